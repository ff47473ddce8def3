"""Typed errors: :class:`InputError` is the user's input (exit 2); anything else is a bug (exit 1).

Every module that refuses input raises an :class:`InputError` (or a subclass) that names where
the problem is: the file with row and column, or the command-line option, or the parameter.
The input layer's shared helpers live here too: reading a text file whatever the user saved
it as (:func:`read_text`), checking where a result may be written, and strict-JSON values.
"""
from __future__ import annotations

import errno
import math
import os
import re
import sys
from pathlib import Path

if sys.version_info >= (3, 11):
    import tomllib
else:
    import tomli as tomllib

# Lines end at LF, CRLF or CR only (as Python's universal newlines): str.splitlines() would
# also split at a form feed, U+2028 and others, which a comment may hold.
LINE_BREAK = re.compile(r"\r\n|\r|\n")
# Arrays or inline tables nested deeper than this are refused before tomllib recurses.
MAX_TOML_DEPTH = 64
# Python (3.11+ by default) refuses to turn a longer digit string into an int.
MAX_INT_DIGITS = 4300
TOML_TOKENS = re.compile(  # strings and comments (to skip) and brackets
    r'''"""[\s\S]*?"""|'{3}[\s\S]*?'{3}|"(?:\\.|[^"\\\n])*"''' r"|'[^'\n]*'|#[^\n]*|[\[\]{}]")
LONG_INTEGER = re.compile(rf"\d(?:_?\d){{{MAX_INT_DIGITS},}}")


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


def read_text(path, what="file", legacy_encoding=None):
    """The text of ``path``: UTF-8 with or without a byte-order mark, or UTF-16 with one;
    with ``legacy_encoding`` (a code page such as cp1252) a file that is not UTF-8 is read
    in it, undecodable bytes replaced.

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
        if legacy_encoding:
            return _without_nul(path, data.decode(legacy_encoding, errors="replace"))
        line = data.count(b"\n", 0, error.start) + 1
        raise InputError(f"not UTF-8 text: byte 0x{data[error.start]:02x} cannot be decoded; "
                         "save the file as UTF-8", path=path, row=line) from None
    return _without_nul(path, text)


def _without_nul(path, text):
    """``text``, refused when it holds a NUL character (a binary file)."""
    if "\x00" in text:
        raise InputError("holds NUL characters: a binary file, not text", path=path,
                         row=line_of(text, text.index("\x00")))
    return text


def text_lines(text):
    """``text`` split into lines at LF, CRLF or CR (never at a form feed or U+2028)."""
    lines = LINE_BREAK.split(text)
    return lines[:-1] if lines and lines[-1] == "" else lines


def line_of(text, position):
    """1-based line of character ``position`` in ``text`` (lines as :func:`text_lines`)."""
    return len(LINE_BREAK.findall(text, 0, position)) + 1


def read_toml(path, what="file"):
    """(text, data) of the TOML file ``path``, read with :func:`read_text`.

    Raises
    ------
    InputError
        Naming the path and line: not TOML, values nested more than ``MAX_TOML_DEPTH``
        deep, or an integer of more than ``MAX_INT_DIGITS`` digits.
    """
    text = read_text(path, what)
    _check_toml_depth(path, text)
    long_integer = LONG_INTEGER.search(text)
    try:
        return text, tomllib.loads(text)
    except tomllib.TOMLDecodeError as error:
        line = re.search(r"line (\d+)", str(error))
        raise InputError(f"not valid TOML: {error}", path=path,
                         row=int(line.group(1)) if line else None) from None
    except ValueError:  # tomllib's int() of a digit string over Python's limit
        if long_integer is None:
            raise
        raise InputError(f"an integer of more than {MAX_INT_DIGITS} digits: no value needs "
                         "that many", path=path, row=line_of(text, long_integer.start())) \
            from None


def _check_toml_depth(path, text):
    """Raise naming the line where arrays or inline tables nest beyond ``MAX_TOML_DEPTH``."""
    depth = 0
    for token in TOML_TOKENS.finditer(text):
        bracket = token.group()
        if bracket in "[{":
            depth += 1
            if depth > MAX_TOML_DEPTH:
                raise InputError(f"values nested more than {MAX_TOML_DEPTH} deep (arrays or "
                                 "inline tables inside each other)", path=path,
                                 row=line_of(text, token.start()))
        elif bracket in "]}":
            depth = max(depth - 1, 0)


def finite_value(value):
    """A TOML or JSON number as a finite float; ValueError with the reason otherwise.

    Booleans and strings are not numbers; an integer beyond the float range is refused
    rather than overflowing.
    """
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError("must be a number")
    try:
        number = float(value)
    except OverflowError:
        raise ValueError("is beyond the range of a number (about 1.8e308)") from None
    if not math.isfinite(number):
        raise ValueError("must be finite")
    return number


def shown_value(value):
    """``value`` for a message: its repr, or its length when it is a very long integer."""
    if isinstance(value, int) and not isinstance(value, bool) and abs(value) > 10**20:
        return f"an integer of {len(str(abs(value)))} digits"
    return repr(value)


def check_writable_target(path, kind="file"):
    """Raise :class:`InputError` when ``path`` cannot be written as a ``kind`` ("file" or
    "folder"): a folder where a file is expected or the reverse, or a parent that is a file."""
    path = Path(path)
    if path.is_symlink() and not path.exists():
        raise InputError(f"is a symbolic link to {os.readlink(path)}, which does not exist; "
                         "give another name or remove the link", path=path)
    if kind == "file" and path.is_dir():
        raise InputError("is a folder; give a file name to write", path=path)
    if kind == "folder" and path.exists() and not path.is_dir():
        raise InputError("is a file; give a folder to write into", path=path)
    for parent in path.parents:
        if parent.exists():
            if not parent.is_dir():
                raise InputError(f"{parent} is a file, not a folder", path=path)
            if not os.access(parent, os.W_OK):
                reason = "read-only file system" if _read_only(parent) else "permission denied"
                raise InputError(f"cannot write into {parent}: {reason}", path=path)
            break


def _read_only(folder):
    """Whether ``folder`` lies on a file system mounted read-only."""
    return bool(os.statvfs(folder).f_flag & os.ST_RDONLY)


# The OSErrors of writing that are the machine's state, not a bug: named, exit 2.
WRITE_ERRORS = {errno.ENOSPC: "no space left on the device",
                errno.EDQUOT: "the disk quota is exceeded",
                errno.EROFS: "read-only file system",
                errno.EACCES: "permission denied", errno.EPERM: "permission denied"}


# Of those, the ones any write may meet (a command's own output is checked beforehand for
# permission): reported as the disk's state wherever they arise.
DISK_STATE_ERRORS = (errno.ENOSPC, errno.EDQUOT, errno.EROFS)


def write_error(error, path=None):
    """The :class:`InputError` for an OSError raised while writing ``path`` (or the error's
    own file name), or None when the error is not one of ``WRITE_ERRORS``."""
    reason = WRITE_ERRORS.get(error.errno)
    if reason is None:
        return None
    return InputError(f"cannot write: {reason}", path=path or error.filename)


def finite_float(text):
    """``text`` as a finite float; ValueError with the reason (for the caller to locate).

    A number is ASCII as C and NumPy read it (``1.5``, ``-3e2``, ``.5``), surrounding white
    space ignored; Python's own extras (``1_000``, digits of other scripts) are not numbers.
    """
    stripped = text.strip()
    try:
        if not stripped.isascii() or "_" in stripped:
            raise ValueError
        value = float(stripped)
    except ValueError:
        raise ValueError(f"not a number: {text!r}") from None
    if not math.isfinite(value):
        raise ValueError(f"must be finite, got {text!r}")
    return value


def number_list(text, option):
    """The comma-separated numbers of option ``option`` (``10,100,190``) as floats."""
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise InputError("expected comma-separated numbers, e.g. 10,100,190",
                         parameter=f"{option} {text}") from None
    return values


def toml_key_line(text, key, table=None):
    """1-based line of ``key = ...`` (inside ``[table]`` when given), or of ``[key]``."""
    current = None
    for number, line in enumerate(text_lines(text), start=1):
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
