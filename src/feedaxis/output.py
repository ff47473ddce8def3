"""Writing results: whole files or nothing, so a failure never leaves a half-written file.

The temporary files and folders staged for that are private (mode 0600/0700); what is
published gets the mode a plain ``open``/``mkdir`` would give under the user's umask. Their
names, ``.NAME-PID-xxxxxxxx``, carry the process that writes them: one a killed run left
(SIGKILL, a power cut) is removed by the next run writing NAME once that process is gone.
"""
from __future__ import annotations

import os
import re
import shutil
import tempfile
import warnings
from contextlib import contextmanager
from pathlib import Path

from .errors import InputError, check_writable_target, write_error


@contextmanager
def writing(path):
    """Turn an OSError of a full, read-only or forbidden disk while writing ``path`` into an
    :class:`~feedaxis.errors.InputError` naming ``path`` (any other OSError passes)."""
    try:
        yield
    except OSError as error:
        refused = write_error(error, path)
        if refused is None:
            raise
        raise refused from None


def write_atomically(path, content):
    """Write text or bytes to ``path`` through a temporary file in the same folder.

    Two writers of one path each publish a whole file; the last rename wins. Raises
    :class:`~feedaxis.errors.InputError` when ``path`` is a folder or lies under a file, or
    the disk is full or read-only.
    """
    path = Path(path)
    check_writable_target(path)
    with writing(path):
        path.parent.mkdir(parents=True, exist_ok=True)
        handle, staging = tempfile.mkstemp(prefix=staging_prefix(path), dir=path.parent)
        try:
            with os.fdopen(handle, "wb") as stream:
                stream.write(content.encode("utf-8") if isinstance(content, str) else content)
            os.chmod(staging, umask_mode(0o666))
            os.replace(staging, path)
        except BaseException:
            Path(staging).unlink(missing_ok=True)
            raise
    return path


@contextmanager
def staged_folder(folder):
    """Yield a private folder beside ``folder`` to write into; when the block ends without
    an error its files are moved into ``folder`` (created if need be), each replacing its
    namesake at once, so ``folder`` never holds half of a result; on an error or Ctrl-C
    the staged files are removed and ``folder`` is left as it was."""
    folder = Path(folder)
    check_writable_target(folder, "folder")
    with writing(folder):
        folder.parent.mkdir(parents=True, exist_ok=True)
        staging = Path(tempfile.mkdtemp(prefix=staging_prefix(folder), dir=folder.parent))
        try:
            try:
                yield staging
            except InputError as error:  # name the user's folder, not the staging one
                if error.path is None or staging not in error.path.parents:
                    raise
                raise InputError(error.message, folder / error.path.relative_to(staging),
                                 error.row, error.column, error.parameter) from None
            os.chmod(staging, umask_mode(0o777))
            if not folder.exists():
                os.replace(staging, folder)
            else:
                _merge(staging, folder)
        finally:
            shutil.rmtree(staging, ignore_errors=True)


def built_once(folder, build, complete):
    """``folder`` as ``build(staging)`` makes it in a private folder beside it, renamed into
    place, unless ``complete(folder)`` holds already (a cache). A crash or Ctrl-C leaves no
    half folder; of builds racing for one folder, the first rename wins and the others use
    its folder (a rename never replaces a folder holding files); an incomplete one left
    from before is replaced."""
    folder = Path(folder)
    if complete(folder):
        return folder
    with writing(folder):
        folder.parent.mkdir(parents=True, exist_ok=True)
        staging = Path(tempfile.mkdtemp(prefix=staging_prefix(folder), dir=folder.parent))
        try:
            build(staging)
            if folder.exists() and not complete(folder):
                shutil.rmtree(folder, ignore_errors=True)
            try:
                os.replace(staging, folder)
            except OSError:
                if not complete(folder):
                    raise
        finally:
            shutil.rmtree(staging, ignore_errors=True)
    return folder


def refuse_overwriting_inputs(outputs, inputs):
    """Raise :class:`~feedaxis.errors.InputError` when one of ``outputs`` ({path: option})
    is, after symbolic links (or as a hard link), one of ``inputs`` (paths) or a folder
    holding one: the command would destroy what it reads."""
    for output, option in outputs.items():
        target = Path(output).resolve()
        for source in inputs:
            read = Path(source).resolve()
            if target == read or target in read.parents or _same_file(target, read):
                raise InputError(f"{option} is {source}, an input of this command (after "
                                 "links): writing there would destroy it; give another path",
                                 path=output, parameter=option)


def _same_file(first, second):
    try:
        return os.path.samefile(first, second)
    except OSError:
        return False


def staging_prefix(path):
    """The prefix of the private staging name beside ``path``: ``.NAME-PID-``; stale ones
    of killed runs beside it are removed first (:func:`remove_stale_staging`)."""
    remove_stale_staging(Path(path))
    return f".{Path(path).name}-{os.getpid()}-"


def remove_stale_staging(path):
    """Remove the staging files and folders of ``path`` (``.NAME-PID-xxxxxxxx``) whose
    process is gone: a run killed by SIGKILL or a power cut; warn, naming them, about
    older-style ones (``.NAME-xxxxxxxx``, without the process) left by an earlier version."""
    pattern = re.compile(rf"\.{re.escape(path.name)}-(?:(\d+)-)?[a-z0-9_]{{8}}")
    try:
        entries = list(path.parent.iterdir())
    except OSError:
        return
    for entry in entries:
        match = pattern.fullmatch(entry.name)
        if match is None or (match.group(1) and _running(int(match.group(1)))):
            continue
        if match.group(1) is None:
            warnings.warn(f"{entry}: a staging {'folder' if entry.is_dir() else 'file'} of "
                          "an earlier run that was killed; remove it if no other run is "
                          "writing there")
        elif entry.is_dir():
            shutil.rmtree(entry, ignore_errors=True)
        else:
            entry.unlink(missing_ok=True)


def _running(pid):
    """Whether process ``pid`` exists (on this machine)."""
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except OSError:
        return True
    return True


def _merge(staging, folder):
    """Move each entry of ``staging`` into ``folder``: files by one rename, a folder by
    moving the old one aside first."""
    for entry in staging.iterdir():
        target = folder / entry.name
        if entry.is_dir() and target.is_dir():
            old = Path(tempfile.mkdtemp(prefix=f".{entry.name}-old-", dir=folder))
            os.replace(target, old / entry.name)
            os.replace(entry, target)
            shutil.rmtree(old, ignore_errors=True)
        else:
            os.replace(entry, target)


def umask_mode(mode):
    """``mode`` (0o666 for a file, 0o777 for a folder) with the process umask applied."""
    mask = os.umask(0o022)  # reading the umask means setting it; restored at once
    os.umask(mask)
    return mode & ~mask
