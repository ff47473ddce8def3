"""Typed errors: :class:`InputError` is the user's input (exit 2); anything else is a bug (exit 1).

Every module that refuses input raises an :class:`InputError` (or a subclass) that names where
the problem is: the file with row and column, or the command-line option, or the parameter.
The input layer's shared helpers live here too: reading a text file whatever the user saved
it as (:func:`read_text`), checking where a result may be written, and strict-JSON values.
"""
from __future__ import annotations

import math
import os
import re
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


class ParameterError(InputError, ValueError):
    """A parameter value is refused (also a ``ValueError`` for code that checks physics)."""

    def __init__(self, message, parameter=None):
        super().__init__(message, parameter=parameter)


def json_safe(value):
    """``value`` with every non-finite float turned into ``None`` (strict JSON has no NaN).

    Mappings, lists, tuples and NumPy scalars and arrays are walked; other values pass.
    """
    if isinstance(value, dict):
        return {key: json_safe(item) for key, item in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(item) for item in value]
    if hasattr(value, "tolist"):
        return json_safe(value.tolist())
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def read_text(path, what="file"):
    """The text of ``path``: UTF-8 with or without a byte-order mark, or UTF-16 with one.

    Raises
    ------
    InputError
        Naming the path when it is missing, a folder, unreadable or in another encoding
        (with the line of the first byte that is not UTF-8).
    """
    path = Path(path)
    if path.is_dir():
        raise InputError(f"is a folder; expected the {what}", path=path)
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        raise InputError(f"{what} not found", path=path) from None
    except OSError as error:
        raise InputError(f"cannot read the {what}: {error.strerror or error}", path=path) \
            from None
    if data.startswith((b"\xff\xfe", b"\xfe\xff")):
        try:
            return data.decode("utf-16")
        except UnicodeDecodeError:
            raise InputError("starts with a UTF-16 byte-order mark but is not UTF-16 text",
                             path=path) from None
    try:
        text = data.decode("utf-8-sig")
    except UnicodeDecodeError as error:
        line = data.count(b"\n", 0, error.start) + 1
        raise InputError(f"not UTF-8 text: byte 0x{data[error.start]:02x} cannot be decoded; "
                         "save the file as UTF-8", path=path, row=line) from None
    if "\x00" in text:
        raise InputError("holds NUL characters: a binary file, not text", path=path,
                         row=text.count("\n", 0, text.index("\x00")) + 1)
    return text


def check_writable_target(path, kind="file"):
    """Raise :class:`InputError` when ``path`` cannot be written as a ``kind`` ("file" or
    "folder"): a folder where a file is expected or the reverse, or a parent that is a file."""
    path = Path(path)
    if kind == "file" and path.is_dir():
        raise InputError("is a folder; give a file name to write", path=path)
    if kind == "folder" and path.exists() and not path.is_dir():
        raise InputError("is a file; give a folder to write into", path=path)
    for parent in path.parents:
        if parent.exists():
            if not parent.is_dir():
                raise InputError(f"{parent} is a file, not a folder", path=path)
            if not os.access(parent, os.W_OK):
                raise InputError(f"cannot write into {parent}: permission denied", path=path)
            break


def finite_float(text):
    """``text`` as a finite float; ValueError with the reason (for the caller to locate)."""
    try:
        value = float(text)
    except ValueError:
        raise ValueError(f"not a number: {text!r}") from None
    if not math.isfinite(value):
        raise ValueError(f"must be finite, got {text!r}")
    return value


def toml_key_line(text, key, table=None):
    """1-based line of ``key = ...`` (inside ``[table]`` when given), or of ``[key]``."""
    current = None
    for number, line in enumerate(text.splitlines(), start=1):
        stripped = line.strip()
        header = re.match(r"\[\s*([A-Za-z0-9_.-]+)\s*\]", stripped)
        if header:
            current = header.group(1)
            if table is None and current == key:
                return number
        elif current == table and re.match(rf"{re.escape(key)}\s*=", stripped):
            return number
        elif table and re.match(rf"{re.escape(table)}\.{re.escape(key)}\s*=", stripped):
            return number
    return None
