"""The one error type for unreadable input files, so callers can tell bad data from bugs."""
from __future__ import annotations

from os import PathLike

from facedyn.errors import FacedynError


class InputError(FacedynError):
    """A file is missing or malformed; the one-line message names the file (and line)."""

    def __init__(self, path: str | PathLike, message: str, line: int | None = None) -> None:
        self.path = str(path)
        self.reason = message
        self.line = line
        where = self.path if line is None else f"{self.path}, line {line}"
        super().__init__(f"{where}: {message}")

    def __reduce__(self):
        # Rebuild from the parts (not the formatted text) so the error survives pickling,
        # e.g. across a process pool.
        return type(self), (self.path, self.reason, self.line)


def quoted(text: str, limit: int = 40) -> str:
    """repr(text) cut to `limit` characters, for quoting a file's words in a one-line error."""
    return repr(text) if len(text) <= limit else repr(text[:limit]) + "..."
