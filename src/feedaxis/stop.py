"""The signals that stop a command: Ctrl-C (SIGINT), SIGTERM (what a job scheduler,
``timeout`` or a service manager sends) and SIGHUP (the terminal closed) all end a command
the same way, as a :class:`KeyboardInterrupt` raised where it runs, so every ``finally``
removes its staging folders and a sweep keeps its finished trials; the exit code is
128 + the signal's number (130, 143, 129). Standard library only, so the console script
installs it before the seconds of start-up imports.
"""
from __future__ import annotations

import os
import signal
import sys
import threading
from contextlib import contextmanager

STOP_SIGNALS = tuple(getattr(signal, name) for name in ("SIGINT", "SIGTERM", "SIGHUP")
                     if hasattr(signal, name))
_received = [signal.SIGINT]  # the last stop signal received (Ctrl-C until another came)
_came = [False]  # whether a stop signal has come (its interrupt may have been swallowed)


def _raise_interrupt(signum, _frame):
    _received[0] = signum
    _came[0] = True
    raise KeyboardInterrupt


def raise_if_swallowed():
    """Raise :class:`KeyboardInterrupt` again if a stop signal has come: called where no
    interrupt can have been seen yet (before a command starts), it catches one that a
    library's import swallowed. xml.etree.ElementTree falls back to Python when its C
    accelerator's start fails, and an interrupt landing there fails it as an ImportError
    it ignores: the command then ran to its end and exited 0 (seen under load)."""
    if _came[0]:
        raise KeyboardInterrupt


def install():
    """Make every stop signal raise :class:`KeyboardInterrupt` (main thread only)."""
    if threading.current_thread() is threading.main_thread():
        for signum in STOP_SIGNALS:
            signal.signal(signum, _raise_interrupt)


def ignore_all():
    """Ignore every stop signal (while the one-line message and the exit are written)."""
    for signum in STOP_SIGNALS:
        signal.signal(signum, signal.SIG_IGN)


def exit_code():
    """128 + the number of the last stop signal received (130 for Ctrl-C)."""
    return 128 + int(_received[0])


def interrupt_behind(error):
    """The stop (:class:`KeyboardInterrupt`) that ``error`` was raised from, or None: a C
    extension's module initialisation turns an interrupt into ``ImportError("initialization
    failed")`` raised from it (pybind11's modules in SciPy and Matplotlib)."""
    seen = set()
    while error is not None and id(error) not in seen:
        if isinstance(error, KeyboardInterrupt):
            return error
        seen.add(id(error))
        error = error.__cause__ or error.__context__
    return None


def leave(code):
    """Exit with ``code``: a stop's code without Python's finalisation. The interrupt may
    have been raised inside code a C extension ran (an import, an FMU's Python), which
    leaves CPython marked to kill itself with SIGINT at exit (exit 130 or -2, never 143);
    every ``finally`` has run by now, so only the streams are flushed."""
    if code in {128 + int(signum) for signum in STOP_SIGNALS}:
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError):
                pass
        os._exit(code)
    sys.exit(code)


def described(message):
    """``message`` with the signal named when it was not Ctrl-C."""
    signum = _received[0]
    return message if signum == signal.SIGINT else \
        f"{message} ({signal.Signals(signum).name})"


@contextmanager
def deferred(request):
    """Within: a stop signal calls ``request()`` instead of raising where the code is (an
    FMU call, Dask's own calls); the signal is recorded for :func:`exit_code`. Outside the
    main thread nothing changes."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def handler(signum, _frame):
        _received[0] = signum
        request()

    previous = {signum: signal.signal(signum, handler) for signum in STOP_SIGNALS}
    try:
        yield
    finally:
        for signum, old in previous.items():
            signal.signal(signum, old)
