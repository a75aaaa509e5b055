"""The errors facedyn reports to its users as one line, without a traceback.

Anything raised as a `FacedynError` is a problem with the user's input or environment, and
its message names what is wrong (which file, which prim, what was expected). Everything
else is a bug in facedyn.
"""


class FacedynError(ValueError):
    """A user-facing error: bad input, a missing file, an unwritable output."""


class UsageError(FacedynError):
    """The command line itself is wrong (exit code 2)."""
