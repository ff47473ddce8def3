"""Multi-rate fixed-step co-simulation master over fmpy's low-level FMI 2.0 or 3.0 API.

The master runs an :class:`~feedaxis.cosim.system.AxisSystem` (the scheme is stated there):
fixed macro step h, each component stepped every ``ratio`` macro steps, components in
dependency order, system outputs as linear combinations of component outputs. Results are
a structured NumPy array addressed by variable name (``result["NpidServo.position_mm"]``,
``result["positioning_error_um"]``).

Speed: every value reference is resolved before the run; all signals live in one
preallocated ctypes array that each FMU's ``fmi2GetReal`` writes straight into. The macro
steps run compiled (:mod:`feedaxis.cosim.compiled_loop`), calling the FMUs' functions
through the pointers fmpy loaded, a chunk of steps per call. Where that loop cannot be
built (no C compiler), :class:`PythonSteps` makes the same calls through fmpy's raw ctypes
functions ``fmi2SetReal``/``fmi2DoStep``/``fmi2GetReal`` and checks their status, with no
per-step dict lookup or allocation (FMI 3.0 FMUs: ``fmi3SetFloat64``/``fmi3DoStep``/
``fmi3GetFloat64`` behind the same signatures,
:meth:`~feedaxis.cosim.fmu_runner.LoadedFmu.stepping_functions`); it gives the same numbers,
its stepping loop about 13 times as long for the full axis (benchmarks/bench_cosim.py).
"""
from __future__ import annotations

import ctypes
import time
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
from numpy.lib import recfunctions

from fmpy.fmi1 import FMICallException

from ..errors import ParameterError
from ..stop import deferred
from .compiled_loop import CompiledSteps, loop_library
from .fmu_runner import LoadedFmu
from .physics_check import check_physics
from .system import check_parameter_values

CHUNK_STEPS = 1000
FMI_WARNING = 1


class PlanEntry(NamedTuple):
    """One component's part of the macro step, everything resolved before the run."""

    ratio: int            # steps every ``ratio`` macro steps
    copies: tuple         # (input buffer index, signal index) per input to copy
    in_buf: object        # the inputs: a ctypes double array, or a pointer into the signals
    set_real: object      # fmi2SetReal, fmi2DoStep, fmi2GetReal (raw ctypes, maybe timed)
    slave: object         # the fmi2Component
    in_vrs: object        # value references of the inputs
    n_in: int
    do_step: object
    step_s: float
    get_real: object
    out_vrs: object       # value references of the outputs
    n_out: int
    out_ptr: object       # where the outputs land in the signal array
    name: str
    native: tuple         # (FMI 3.0?, the raw set, step and get functions) for the C loop


class SimulationInterrupted(KeyboardInterrupt):
    """Ctrl-C during a run: ``partial`` holds the rows recorded up to the stop."""

    def __init__(self, partial):
        super().__init__("interrupted")
        self.partial = partial


class FmuStepError(RuntimeError):
    """An FMU call returned fmi2Discard, fmi2Error or fmi2Fatal (its log says why)."""


@dataclass
class Timing:
    """Times of the last run (s): all of it, the stepping loop, and (when profiled) the
    FMUs' own fmi2SetReal/fmi2DoStep/fmi2GetReal calls within the loop and what the timers
    around those calls cost themselves."""

    wall_s: float
    loop_s: float
    fmu_s: float | None = None
    macro_steps: int = 0
    timer_s: float = 0.0
    loop: str = "compiled"  # or "python (why)"

    @property
    def overhead_fraction(self):
        """Share of the stepping loop spent outside FMU calls, the timers' own cost taken
        out of the loop (None unless profiled)."""
        if self.fmu_s is None:
            return None
        return 1.0 - self.fmu_s / (self.loop_s - self.timer_s)


class Master:
    """Runs one system many times; the FMUs are extracted once.

    Parameters
    ----------
    system : AxisSystem
    fmu_paths : dict
        FMU name -> path of the .fmu (:func:`feedaxis.cosim.fmu_cache.cached_fmus`).
    compiled_loop : bool
        Step in the compiled loop where it can be built (default); False: in Python.
    """

    def __init__(self, system, fmu_paths, compiled_loop=True):
        self.system = system
        self.library, self.loop_missing = (loop_library() if compiled_loop else
                                           (None, "the Python loop was asked for"))
        self.loaded = {}
        try:
            for component in system.components:
                if component.fmu not in self.loaded:
                    self.loaded[component.fmu] = LoadedFmu(fmu_paths[component.fmu])
        except BaseException:  # a damaged FMU or a stop signal: no extracted folder left
            self.close()
            raise
        self.outputs = {c.name: [v.name for v in self.loaded[c.fmu].variables.values()
                                 if v.causality == "output" and v.type == "Real"]
                        for c in system.components}
        self.signal_names = [v.name for v in system.inputs] + [
            f"{c.name}.{name}" for c in system.components for name in self.outputs[c.name]]
        self.timing = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def close(self):
        """Remove the extracted FMUs."""
        for loaded in self.loaded.values():
            loaded.close()

    @property
    def names(self):
        """Fields of the result array: time, inputs, component outputs, system outputs."""
        return ["time", *self.signal_names, *(o.variable.name for o in self.system.outputs)]

    def run(self, stop_s, inputs=None, parameters=None, output_interval_s=None,
            record_at_s=None, progress=None, profile=False):
        """Simulate from 0 to ``stop_s`` and return the recorded rows.

        Parameters
        ----------
        stop_s : float
            End time (s), a whole number of macro steps.
        inputs : dict, optional
            System input name -> a constant, an array of one value per macro step (value k
            held over [t_k, t_{k+1})) or a function of the time array t_k (s). Inputs not
            given keep their start value.
        parameters : dict, optional
            {component: {parameter: value}} over the system's values for this run only,
            e.g. ``Model.fmu_parameters(axis)`` of a fitted model.
        output_interval_s : float, optional
            Record every this many seconds (a whole number of macro steps); default: every
            macro step unless ``record_at_s`` is given.
        record_at_s : array_like, optional
            Also record at these times (s), rounded to the macro grid.
        progress : callable, optional
            ``progress(done_steps, total_steps)`` after every chunk of macro steps.
        profile : bool
            Time every FMU call; ``self.timing.fmu_s`` then holds their sum (and
            ``self.timing.timer_s`` what the timers cost outside the calls they time).

        Returns
        -------
        numpy structured array
            Row 0 is t = 0 (after initialisation), then one row per recorded macro step.

        Raises
        ------
        SimulationInterrupted
            On Ctrl-C; it carries the rows recorded so far.
        """
        system = self.system.with_parameters(parameters or {})
        h = system.macro_step_s
        n_steps = _whole_steps(stop_s, h, "stop time")
        record_steps = self._record_steps(n_steps, h, output_interval_s, record_at_s)
        input_values = self._input_sources(inputs or {}, n_steps)
        signals = (ctypes.c_double * len(self.signal_names))()
        fmu_time = [0.0, 0]  # seconds in FMU calls, timed calls
        slaves, plan = [], []
        started = time.perf_counter()
        for j, source in input_values:
            signals[j] = float(_values(source, np.zeros(1))[0])
        with _StopFlag() as stop:  # freeing the slaves runs their Python too
            try:
                for component in system.ordered_components():
                    plan.append(self._instantiate(system, component, signals, slaves,
                                                  fmu_time if profile else None))
                fmu_time[:] = [0.0, 0]
                recorded = bytearray(memoryview(signals).cast("B"))  # row 0
                varying = [(j, source) for j, source in input_values if _varies(source)]
                steps = self._steps(plan, signals, [j for j, _ in varying],
                                    record_steps.tolist(), h, recorded, fmu_time, profile)
                loop_started = time.perf_counter()
                _loop(steps, varying, n_steps, h, progress, stop)
                loop_s = time.perf_counter() - loop_started
            finally:
                for slave in slaves:
                    slave.freeInstance()
        self.timing = Timing(time.perf_counter() - started, loop_s, macro_steps=n_steps,
                             loop="compiled" if self.library else
                             f"python ({self.loop_missing})")
        if profile:
            self.timing.fmu_s, calls, timer_cost_s = steps.fmu_time()
            self.timing.timer_s = calls * timer_cost_s
        table = np.frombuffer(recorded, dtype=np.float64).reshape(-1, len(signals))
        rows = len(table)
        result = self._result(table, record_steps[:rows] * h)
        if rows < record_steps.size or stop.requested:  # a stop while the slaves were freed
            raise SimulationInterrupted(result)
        return result

    def _record_steps(self, n_steps, h, output_interval_s, record_at_s):
        """Sorted macro-step indices k + 1 to record after, starting with 0 (initialisation)."""
        steps = [np.array([0])]
        if output_interval_s is not None or record_at_s is None:
            every = _whole_steps(output_interval_s or h, h, "output interval")
            steps.append(np.arange(every, n_steps + 1, every))
        if record_at_s is not None:
            at = np.round(np.asarray(record_at_s, dtype=float) / h).astype(int)
            if at.size and (at.min() < 0 or at.max() > n_steps):
                raise ValueError("record_at_s: times must lie within 0 and the stop time")
            steps.append(at)
        return np.unique(np.concatenate(steps))

    def _input_sources(self, inputs, n_steps):
        """[(signal index, source)] for every system input; unknown names are an error."""
        known = [v.name for v in self.system.inputs]
        unknown = set(inputs) - set(known)
        if unknown:
            raise ValueError(f"no system input {', '.join(sorted(unknown))}; inputs: "
                             f"{', '.join(known)}")
        for name, source in inputs.items():
            if not callable(source) and np.ndim(source) and len(source) < n_steps:
                raise ValueError(f"input {name}: {len(source)} values for {n_steps} macro steps")
        return [(j, inputs.get(v.name, v.start)) for j, v in enumerate(self.system.inputs)]

    def _instantiate(self, system, component, signals, slaves, fmu_time):
        """Instantiate (appending to ``slaves``) and initialise one component with the
        current ``signals``; return its loop plan entry."""
        loaded = self.loaded[component.fmu]
        variables = loaded.variables
        check_parameter_values(component, variables)
        check_physics(component, variables)
        connections = system.inputs_of(component.name)
        for connection in connections:
            if connection.target.split(".", 1)[1] not in variables:
                raise ValueError(f"connection target {connection.target}: no such input")
        in_vrs = _vr_array([variables[c.target.split(".", 1)[1]].valueReference
                            for c in connections])
        sources = [self.signal_names.index(c.source) for c in connections]
        out_vrs = _vr_array([variables[n].valueReference for n in self.outputs[component.name]])
        out_ptr = _signal_pointer(signals, self.signal_names.index(
            f"{component.name}.{self.outputs[component.name][0]}"))
        if sources and sources == list(range(sources[0], sources[0] + len(sources))):
            # inputs side by side in the signal array: the FMU reads them there, no copies
            copies, in_buf = (), _signal_pointer(signals, sources[0])
        else:
            copies = tuple(enumerate(sources))
            in_buf = (ctypes.c_double * max(1, len(copies)))()
        slave = loaded.instantiate(component.name)
        slaves.append(slave)
        loaded.set_values(slave, component.parameters)
        loaded.enter_initialisation(slave)
        functions = loaded.stepping_functions(slave)
        if fmu_time is not None:
            functions = [_timed(f, fmu_time) for f in functions]
        set_real, do_step, get_real = functions
        for i, j in copies:
            in_buf[i] = signals[j]
        _check(set_real(slave.component, in_vrs, len(sources), in_buf), component.name, 0.0)
        try:
            slave.exitInitializationMode()
        except FMICallException:
            raise ParameterError("the FMU refuses these parameter values at initialisation "
                                 "(its log above says why)", component.name) from None
        _check(get_real(slave.component, out_vrs, len(out_vrs), out_ptr), component.name, 0.0)
        return PlanEntry(ratio=system.ratio(component), copies=copies, in_buf=in_buf,
                         set_real=set_real, slave=slave.component, in_vrs=in_vrs,
                         n_in=len(sources), do_step=do_step, step_s=component.step_s,
                         get_real=get_real, out_vrs=out_vrs, n_out=len(out_vrs),
                         out_ptr=out_ptr, name=component.name,
                         native=loaded.native_stepping_functions(slave))

    def _steps(self, plan, signals, varying, records, h, recorded, fmu_time, profile):
        """The run's macro steps: compiled where the loop's library loaded, else in Python
        (:class:`PythonSteps`, its FMU calls timed into ``fmu_time`` when profiled)."""
        if self.library is not None:
            return CompiledSteps(self.library, plan, signals, varying, records, h, recorded,
                                 CHUNK_STEPS, profile)
        return PythonSteps(plan, signals, varying, records, h, recorded, fmu_time)

    def _result(self, table, time_s):
        """The structured result: recorded signals plus the system outputs."""
        columns = {name: table[:, i] for i, name in enumerate(self.signal_names)}
        columns.update(self.system.output_values(columns))
        stacked = np.column_stack([time_s, *columns.values()]) if len(time_s) else \
            np.zeros((0, len(columns) + 1))
        dtype = np.dtype([(name, float) for name in self.names])
        return recfunctions.unstructured_to_structured(stacked, dtype)


def _loop(steps, varying, n_steps, h, progress, stop):
    """The macro steps in chunks: between chunks a stop is honoured (the rows recorded so
    far stay) and ``progress`` told; ``steps`` makes a chunk's steps (compiled or
    :class:`PythonSteps`)."""
    for k_start in range(0, n_steps, CHUNK_STEPS):
        if stop.requested:
            break
        k_end = min(n_steps, k_start + CHUNK_STEPS)
        t_chunk = np.arange(k_start, k_end) * h
        failed = steps(k_start, k_end, np.array(
            [_values(source, t_chunk, k_start) for _, source in varying]).reshape(
                len(varying), k_end - k_start))
        if failed is not None:
            name, k1 = failed
            raise FmuStepError(f"{name} failed in the step ending at t = {k1 * h:.6g} s "
                               "(its log above says why)")
        if progress is not None:
            progress(k_end, n_steps)


class PythonSteps:
    """The macro steps of a chunk in Python, as ``master_loop.c`` makes them compiled.

    The fallback where that loop cannot be built (no C compiler, not Linux): the same
    calls on the same plan, so the same numbers, its stepping loop about 13 times as long
    for the full axis (each of fmpy's ctypes calls costs more than the FMU function it
    calls). ``steps(k_start, k_end, values)`` (``values``: one row per
    varying input, one column per step) appends the recorded rows to ``recorded`` and
    returns None, or (name, k + 1) of the component that failed in macro step k.
    A row is recorded as the signal array's bytes appended to one buffer (a twentieth of a
    microsecond, a fifth of a NumPy row assignment).
    """

    def __init__(self, plan, signals, varying, records, h, recorded, fmu_time):
        self.plan, self.signals, self.varying, self.h = plan, signals, varying, h
        self.records, self.row = records, 1
        self.record = recorded.extend
        self.row_bytes = memoryview(signals).cast("B")
        self.timed = fmu_time

    def __call__(self, k_start, k_end, values):
        plan, signals, h, record, row_bytes = (self.plan, self.signals, self.h, self.record,
                                               self.row_bytes)
        records, row, warning = self.records, self.row, FMI_WARNING
        n_records = len(records)
        next_record = records[row] if row < n_records else -1
        chunk = list(zip(self.varying, values.tolist()))
        try:
            for k in range(k_start, k_end):
                kk = k - k_start
                for j, column in chunk:
                    signals[j] = column[kk]
                k1 = k + 1
                # unpacked in PlanEntry's field order: the fastest access in this loop
                for (ratio, copies, in_buf, set_real, slave, in_vrs, n_in, do_step, step_s,
                     get_real, out_vrs, n_out, out_ptr, name, native) in plan:
                    if k1 % ratio:
                        continue
                    for i, j in copies:
                        in_buf[i] = signals[j]
                    if (set_real(slave, in_vrs, n_in, in_buf) > warning
                            or do_step(slave, (k1 - ratio) * h, step_s, 1) > warning
                            or get_real(slave, out_vrs, n_out, out_ptr) > warning):
                        return name, k1
                if k1 == next_record:
                    record(row_bytes)
                    row += 1
                    next_record = records[row] if row < n_records else -1
        finally:
            self.row = row
        return None

    def fmu_time(self):
        """(seconds in the timed FMU calls, their count, what one timer costs outside the
        call it times (s))."""
        return self.timed[0], self.timed[1], _timer_cost_s()


def _whole_steps(duration_s, h, what):
    steps = duration_s / h
    if not (np.isfinite(steps) and steps >= 0 and abs(steps - round(steps)) < 1e-6):
        raise ValueError(f"{what} {duration_s!r} s must be a whole number of macro steps "
                         f"of {h:g} s")
    return int(round(steps))


def _values(source, t_s, first_step=0):
    """Values of an input source at the times ``t_s`` (macro steps from ``first_step``)."""
    if callable(source):
        return np.broadcast_to(np.asarray(source(t_s), dtype=float), t_s.shape)
    array = np.asarray(source, dtype=float)
    if array.ndim == 0:
        return np.full(t_s.shape, float(array))
    return array[first_step:first_step + t_s.size]


def _varies(source):
    """Whether an input source changes over the run (a function or an array of values);
    a constant is written once, before the first step."""
    return callable(source) or np.ndim(source) > 0


def _signal_pointer(signals, index):
    """A double pointer to ``signals[index]`` (a ctypes double array)."""
    return ctypes.cast(ctypes.addressof(signals) + index * ctypes.sizeof(ctypes.c_double),
                       ctypes.POINTER(ctypes.c_double))


def _vr_array(references):
    return (ctypes.c_uint * len(references))(*references)


def _check(status, name, time_s):
    if status > FMI_WARNING:
        raise FmuStepError(f"{name} failed at t = {time_s:g} s (its log above says why)")


def _timed(function, total):
    """``function`` with its wall time added to ``total[0]`` and its calls counted in
    ``total[1]``."""
    clock = time.perf_counter

    def call(*args):
        started = clock()
        status = function(*args)
        total[0] += clock() - started
        total[1] += 1
        return status

    return call


def _timer_cost_s(calls=20_000):
    """Wall seconds one :func:`_timed` call spends outside the interval it measures (its own
    call, the clock's return, the sums): the median of five runs of ``calls`` timed calls
    of a function doing nothing, less what the timer measured inside and the bare loop."""
    def nothing(component, references, count, values):
        return 0

    costs = []
    for _ in range(5):
        inside = [0.0, 0]
        timed = _timed(nothing, inside)
        started = time.perf_counter()
        for _ in range(calls):
            pass
        bare = time.perf_counter() - started
        started = time.perf_counter()
        for _ in range(calls):
            timed(None, None, 0, None)
        costs.append((time.perf_counter() - started - inside[0] - bare) / calls)
    return sorted(costs)[2]


class _StopFlag:
    """Within ``with``: a stop signal (Ctrl-C, SIGTERM, SIGHUP: :mod:`feedaxis.stop`) sets
    ``requested`` instead of raising inside an FMU call.

    A KeyboardInterrupt raised in the Python code of a pythonfmu slave would surface as
    fmi2Fatal; the master instead finishes the current chunk and stops cleanly.
    """

    def __init__(self):
        self.requested = False
        self._deferred = deferred(self._request)

    def __enter__(self):
        self._deferred.__enter__()
        return self

    def __exit__(self, *exc):
        return self._deferred.__exit__(*exc)

    def _request(self):
        self.requested = True
