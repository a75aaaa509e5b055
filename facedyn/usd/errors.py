"""Errors raised at the USD boundary."""
from facedyn.errors import FacedynError


class TakeError(FacedynError):
    """An input USD file that is not what facedyn expects; the message names the file and the prim."""
