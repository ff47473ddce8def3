"""The master's macro steps compiled: ``master_loop.c`` built once per machine, kept in the
user cache, loaded with ctypes.

The FMUs of the full axis step in compiled code, about 1 µs per macro step in all; the
master's Python loop adds 2-4 µs of its own per macro step (the plan's ratio tests, the
input copies, the status checks, the rows) and about ten ctypes calls, each costing more
than the FMU function it calls: over FMUs that do nothing it still takes about 13 µs per
macro step. The C loop makes the same calls through the function pointers fmpy loaded, on
the same plan, signal array and record grid (:class:`CompiledSteps`), one ctypes call per
chunk of macro steps: its own share of the stepping loop is about 4 % (0.1 µs per macro
step; benchmarks/bench_cosim.py, docs/speed.md).

Where it cannot be built (no C compiler, not Linux, a failed compile, a cache folder that
cannot be written) the master keeps its Python loop (:class:`~feedaxis.cosim.master.
PythonSteps`), which gives the same numbers: :func:`loop_library` says why, the run's
``Master.timing.loop`` too, and the reason is logged at debug level once.
"""
from __future__ import annotations

import ctypes
import functools
import hashlib
import logging
import platform
import subprocess
from pathlib import Path

import numpy as np

from ..output import built_once
from ..toolchain import c_compiler, cache_root, compiler_missing

SOURCE = Path(__file__).resolve().with_name("master_loop.c")
LIBRARY_NAME = "master_loop.so"
TIMER_CALLS = 20_000
LONG = np.dtype(ctypes.c_long)


class LoopUnavailable(RuntimeError):
    """The compiled loop cannot be built or loaded on this machine."""


class Component(ctypes.Structure):
    """master_loop.c's ``Component``: one plan entry, flat."""

    _fields_ = [("fmi3", ctypes.c_int), ("ratio", ctypes.c_long),
                ("set_values", ctypes.c_void_p), ("do_step", ctypes.c_void_p),
                ("get_values", ctypes.c_void_p), ("component", ctypes.c_void_p),
                ("in_vrs", ctypes.c_void_p), ("n_in", ctypes.c_size_t),
                ("in_buf", ctypes.c_void_p), ("copy_from", ctypes.c_void_p),
                ("n_copies", ctypes.c_size_t), ("out_vrs", ctypes.c_void_p),
                ("n_out", ctypes.c_size_t), ("out_ptr", ctypes.c_void_p),
                ("step_s", ctypes.c_double)]


class Run(ctypes.Structure):
    """master_loop.c's ``Run``."""

    _fields_ = [("plan", ctypes.POINTER(Component)), ("n_plan", ctypes.c_size_t),
                ("signals", ctypes.c_void_p), ("n_signals", ctypes.c_size_t),
                ("varying", ctypes.c_void_p), ("n_varying", ctypes.c_size_t),
                ("records", ctypes.c_void_p), ("n_records", ctypes.c_size_t),
                ("h", ctypes.c_double), ("fmu_s", ctypes.POINTER(ctypes.c_double)),
                ("timed_calls", ctypes.POINTER(ctypes.c_long))]


def library_key():
    """SHA-256 (first 12 hex digits) of the source, the compiler and the machine."""
    digest = hashlib.sha256(SOURCE.read_bytes())
    digest.update(f"{c_compiler()}|{platform.machine()}".encode())
    return digest.hexdigest()[:12]


def _compile_into(staging):
    command = [c_compiler(), "-shared", "-fPIC", "-O2", "-Wall", "-o",
               str(staging / LIBRARY_NAME), str(SOURCE)]
    result = subprocess.run(command, capture_output=True, text=True)
    if result.returncode != 0:
        raise LoopUnavailable(f"compiling {SOURCE.name} failed:\n{result.stderr[-2000:]}")


def _built_library():
    """The loaded library, compiled into ``<cache>/master-loop-<key>/`` on first use."""
    missing = compiler_missing("the compiled co-simulation loop")
    if missing:
        raise LoopUnavailable(missing)
    folder = built_once(cache_root() / f"master-loop-{library_key()}", _compile_into,
                        lambda folder: (folder / LIBRARY_NAME).is_file())
    library = ctypes.CDLL(str(folder / LIBRARY_NAME))
    library.feedaxis_master_chunk.restype = ctypes.c_int
    library.feedaxis_master_chunk.argtypes = [
        ctypes.POINTER(Run), ctypes.c_long, ctypes.c_long, ctypes.c_void_p,
        ctypes.POINTER(ctypes.c_long), ctypes.c_void_p, ctypes.POINTER(ctypes.c_long)]
    library.feedaxis_timer_cost_s.restype = ctypes.c_double
    library.feedaxis_timer_cost_s.argtypes = [ctypes.c_long]
    return library


@functools.cache
def loop_library():
    """(the compiled loop's library, None) or (None, why it is not available); built and
    loaded once per process."""
    try:
        return _built_library(), None
    except (LoopUnavailable, OSError) as error:
        reason = str(error)
        logging.getLogger(__name__).debug("the co-simulation master steps in Python: %s",
                                          reason)
        return None, reason


def _address(value):
    """The address a ctypes array, pointer or function points at."""
    return ctypes.cast(value, ctypes.c_void_p).value


def _component(entry, keep):
    """:class:`Component` of a master plan entry; the arrays it points into go to ``keep``."""
    fmi3, set_values, do_step, get_values = entry.native
    copy_from = np.array([j for _, j in entry.copies], dtype=LONG)
    keep.append(copy_from)
    return Component(int(fmi3), entry.ratio, _address(set_values), _address(do_step),
                     _address(get_values), entry.slave, _address(entry.in_vrs), entry.n_in,
                     _address(entry.in_buf), copy_from.ctypes.data, copy_from.size,
                     _address(entry.out_vrs), entry.n_out, _address(entry.out_ptr),
                     entry.step_s)


class CompiledSteps:
    """The master's macro steps, a chunk per call, in ``master_loop.c``.

    Called as :class:`~feedaxis.cosim.master.PythonSteps` is: ``steps(k_start, k_end,
    values)`` appends the recorded rows to ``recorded`` and returns None, or (name, k + 1)
    of the component that failed in macro step k. ``profile``: the FMU calls are timed in C
    (:meth:`fmu_time`).
    """

    def __init__(self, library, plan, signals, varying, records, h, recorded, chunk_steps,
                 profile=False):
        self._library = library
        self._keep = []
        components = (Component * len(plan))(*(_component(e, self._keep) for e in plan))
        self._varying = np.array(varying, dtype=LONG)
        self._records = np.array(records, dtype=LONG)
        self._fmu_s, self._calls = ctypes.c_double(), ctypes.c_long()
        self._run = Run(components, len(plan), _address(signals), len(signals),
                        self._varying.ctypes.data, self._varying.size,
                        self._records.ctypes.data, self._records.size, h,
                        ctypes.pointer(self._fmu_s) if profile else None,
                        ctypes.pointer(self._calls) if profile else None)
        self._keep.append(components)
        self._names = [entry.name for entry in plan]
        self._rows = np.empty((chunk_steps, len(signals)))
        self._row = ctypes.c_long(1)
        self._failed_step = ctypes.c_long()
        self._recorded = recorded

    def __call__(self, k_start, k_end, values):
        values = np.ascontiguousarray(values, dtype=np.float64)
        before = self._row.value
        failed = self._library.feedaxis_master_chunk(
            ctypes.byref(self._run), k_start, k_end, values.ctypes.data,
            ctypes.byref(self._row), self._rows.ctypes.data, ctypes.byref(self._failed_step))
        if failed >= 0:
            return self._names[failed], self._failed_step.value
        self._recorded.extend(self._rows[:self._row.value - before].data)
        return None

    def fmu_time(self):
        """(seconds in FMU calls, timed calls, what one timer costs outside the call it
        times (s): the median of five calibrations)."""
        costs = sorted(self._library.feedaxis_timer_cost_s(TIMER_CALLS) for _ in range(5))
        return self._fmu_s.value, self._calls.value, costs[2]
