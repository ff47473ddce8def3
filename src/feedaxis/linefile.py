"""Line-oriented text files of other tools (laser exports, controller tables): the one error
naming file, line and field, and reading a number with that error."""
from __future__ import annotations

from .errors import InputError, finite_float


class LineError(InputError):
    """A file that does not parse: the message names the file, line and field."""

    def __init__(self, path, message, line=None, field=None):
        super().__init__(message, path=path, row=line, column=field)
        where = [str(path)] + ([f"line {line}"] if line is not None else []) + \
            ([f"field '{field}'"] if field is not None else [])
        self.args = (f"{', '.join(where)}: {message}",)


def number(text, path, line, field, limits=None):
    """``text`` as a finite float, else :class:`LineError` naming line and field; with
    ``limits`` (low, high) a value outside them is refused too."""
    try:
        value = finite_float(text)
    except ValueError as problem:
        raise LineError(path, str(problem), line, field) from None
    if limits is not None and not limits[0] <= value <= limits[1]:
        raise LineError(path, f"{value:g} is beyond any physical axis: expected "
                              f"{limits[0]:g} to {limits[1]:g}", line, field)
    return value
