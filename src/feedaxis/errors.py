"""Typed errors: :class:`InputError` is the user's input (exit 2); anything else is a bug (exit 1).

Every module that refuses input raises an :class:`InputError` (or a subclass) that names where
the problem is: the file with row and column, or the command-line option, or the parameter.
"""
from __future__ import annotations

from pathlib import Path


class InputError(Exception):
    """Bad input: the message names the file (row, column) or the option or parameter.

    Parameters
    ----------
    message : str
        What is wrong and, where useful, what is expected.
    path : str or Path, optional
        The file or folder at fault.
    row : int or str, optional
        1-based row (header = row 1) or line label.
    column : str, optional
        Column, key or field name.
    parameter : str, optional
        The option or parameter at fault when no file is (``--set``, ``k1_W_m2K``).
    """

    def __init__(self, message, path=None, row=None, column=None, parameter=None):
        where = [str(path)] if path is not None else []
        if row is not None:
            where.append(f"row {row}")
        if column is not None:
            where.append(f"column '{column}'")
        if parameter is not None and path is None:
            where.append(str(parameter))
        super().__init__(f"{', '.join(where)}: {message}" if where else message)
        self.message = message
        self.path = Path(path) if path is not None else None
        self.row, self.column, self.parameter = row, column, parameter

    def as_json(self):
        """The error as the strict-JSON object ``--json`` prints."""
        return {"error": str(self), "file": None if self.path is None else str(self.path),
                "row": self.row, "column": self.column, "parameter": self.parameter}
