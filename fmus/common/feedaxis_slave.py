"""Common pythonfmu adapter for the feedaxis FMUs: variables, checks, errors and state.

Travels inside every FMU next to ``physics`` (a copy of feedaxis.physics).
A slave declares its variables with :meth:`AxisSlave.parameter`, :meth:`AxisSlave.input`
and :meth:`AxisSlave.output`, builds its physics object in :meth:`AxisSlave.build` and
advances it in :meth:`AxisSlave.step`. Nothing raises into pythonfmu (which would turn any
exception into fmi2Fatal and leave its instance holding freed objects): a ValueError (a bad
parameter, a NaN input, a refused step) is logged with category ``logStatusError`` naming
the variable, any other exception (a bug) with ``logStatusFatal`` and its traceback; the
FMU's host layer (fmus/common/host/) returns that status for the call.

While stepping, the host layer keeps the Real inputs and outputs itself and makes one call
per doStep, to the function :func:`claim` returns (:meth:`AxisSlave.exchanger`), instead of
pythonfmu's three (set_real, do_step, get_real, each building Python lists).

Where the FMU's compiled module is there (physics/step_kernel, feedaxis.kernel_build), the
host layer steps the four FMUs of the axis without Python: it calls the C
function :meth:`AxisSlave.native_step` names on a block of numbers the slave fills
(:meth:`AxisSlave.native_block`, packed again after any call that may change the slave)
and hands the outputs and state back (:meth:`AxisSlave.restore_native`) before any other
call reaches the slave. A step the compiled function declines (a bad input) goes through
the exchange function, which says what is wrong.

A saved state is restored only if it is one this FMU could have saved (its variables with
their types, the fixed parameters of an initialised instance unchanged, the model's state
restorable); anything else is refused with an error naming what is wrong, the instance as
it was. The host layer asks :meth:`AxisSlave.state_error` before a buffer reaches pythonfmu.
"""
import array
import json
import math
import sys
import threading
import traceback
import types
import weakref

from pythonfmu import Boolean, Fmi2Causality, Fmi2Initial, Fmi2Slave, Fmi2Variability
from pythonfmu import Integer, Real, String
from pythonfmu.enums import Fmi2Status

_TYPES = {bool: Boolean, int: Integer, float: Real, str: String}
# AxisSlave.exchanger's function for one FMU's inputs and outputs: the fast path takes the
# checks of AxisSlave._advance when they pass, written out; every other case goes through it
EXCHANGE = """
def exchange(current_time, step_size, {values}):
{assignments}    if slave.model is not None and 0.0 < step_size < inf and isfinite({total}):
        try:
            step(step_size)
        except Exception as error:  # noqa: BLE001 -- nothing may raise into pythonfmu
            slave._report(f"at t = {{current_time}} s", error)
            return drained(None)
        if not slave.log_queue and isfinite({outputs_total}):
            return ({outputs})
        return drained(finite(current_time, ({outputs})))
    stepped = advance(current_time, step_size, INPUTS, {values_tuple})
    return drained(({outputs}) if stepped else None)
"""
# the Python values each variable type holds in a serialised state (JSON: bool is not int)
_STATE_VALUES = {Real: (float, int), Integer: (int,), Boolean: (bool,), String: (str,)}
HANDOFF_MODULE = "feedaxis_fmu_handoff"
REFUSED = "feedaxis: refused"  # the key of a buffer that was not a state
STATE_KEYS = {"initialised", "model_state"}  # a state's keys beside the variables


def _handoff():
    """The module all copies of this adapter in a process share with the host layer: the
    slave constructed last on each thread (``constructed``), :func:`claim` and :func:`forget`.

    Every FMU carries its own copy of this file, and a process may hold several builds;
    one shared module makes the hand-over independent of which copy a slave came from.
    """
    module = sys.modules.get(HANDOFF_MODULE)
    if module is None:
        module = types.ModuleType(HANDOFF_MODULE, _handoff.__doc__)
        module.constructed, module.claim, module.forget = {}, claim, forget
        sys.modules[HANDOFF_MODULE] = module
    return module


def forget():
    """Drop this thread's constructed slave; the host layer calls this right before
    pythonfmu's fmi2Instantiate or fmi2Reset, so that :func:`claim` finds only the slave
    that call constructs."""
    _handoff().constructed.pop(threading.get_ident(), None)


def claim(input_names, output_names):
    """The exchange function (:meth:`AxisSlave.exchanger`) of the slave constructed on this
    thread since :func:`forget`, or None; the host layer calls this right after."""
    reference = _handoff().constructed.pop(threading.get_ident(), None)
    slave = reference() if reference is not None else None
    return None if slave is None else slave.exchanger(input_names, output_names)


class AxisSlave(Fmi2Slave):
    """Base class: declared variables with units and limits, checked steps, full state."""

    author = "feedaxis"
    license = "MIT"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.units = {}
        self.limits = {}
        self.model = None
        self._input_names = []
        self._output_names = []
        self._block = None  # the compiled step's numbers (_native_pack)
        _handoff().constructed[threading.get_ident()] = weakref.ref(self)

    def _declare(self, name, value, description, unit, limits, **kind):
        setattr(self, name, value)
        self.register_variable(_TYPES[type(value)](name, description=description, **kind))
        if unit:
            self.units[name] = unit
        if limits:
            self.limits[name] = limits

    def parameter(self, name, value, description, unit=None, limits=None, tunable=False):
        """Declare a parameter with its default ``value`` (bool, int, float or str): fixed,
        or ``tunable`` where :meth:`step` reads it at every step (a set between steps holds
        from the next one on; the host layer checks it as it is set)."""
        variability = Fmi2Variability.tunable if tunable else Fmi2Variability.fixed
        self._declare(name, value, description, unit, limits,
                      causality=Fmi2Causality.parameter, variability=variability)

    def position_offset_parameter(self, use):
        """Declare ``position_offset_mm`` (default 0), the machine position that 0 mm on the
        FMU's position connectors stands for; ``use`` says how the FMU applies it. A system
        whose connectors count from the start of a motion (0 there, whatever a host passes
        before its first step) hands the start position here; the physics sees machine
        positions."""
        self.parameter("position_offset_mm", 0.0, "Machine position that 0 mm on the "
                       f"position connectors stands for: {use} (0: the connectors carry "
                       "machine positions)", "mm")

    def input(self, name, value, description, unit=None):
        """Declare a Real input with its start ``value``; NaN or infinity is refused."""
        self._input_names.append(name)
        self._declare(name, float(value), description, unit, None, causality=Fmi2Causality.input)

    def output(self, name, description, unit=None):
        """Declare a Real output, calculated at initialisation from parameters and inputs."""
        self._output_names.append(name)
        self._declare(name, 0.0, description, unit, None,
                      causality=Fmi2Causality.output, initial=Fmi2Initial.calculated)

    def build(self):
        """Return the physics object from the parameters (raise ValueError if one is bad)."""
        raise NotImplementedError

    def step(self, step_size_s):
        """Advance ``self.model`` by ``step_size_s`` and update the outputs."""
        raise NotImplementedError

    def native_step(self):
        """(this FMU's compiled step: (library path, C symbol) or None; why the compiled
        module did not load, or None): physics.fmu_steps.native_step. None, None here."""
        return None, None

    def native_block(self):
        """The numbers the compiled step reads and updates (physics.fmu_steps'
        ``*_block``), from the parameters and the model's state."""
        raise NotImplementedError

    def restore_native(self, block):
        """Take the model's state back from ``block`` after compiled steps."""

    def model_state(self):
        """Internal state beyond the FMI variables, as JSON-compatible values (called once
        the model is built)."""
        return None

    def restore_model_state(self, state):
        """Restore what :meth:`model_state` returned; raise ValueError if it is not one."""

    def exit_initialization_mode(self):
        try:
            self._check_parameters()
            self.model = self.build()
            self.step(0.0)
            self._check_outputs()
            failure = self.native_step()[1]
            if failure:
                self.log(f"the compiled step does not load ({failure}): stepping in Python, "
                         f"same results, slower", Fmi2Status.warning, "logStatusWarning")
        except Exception as error:  # noqa: BLE001 -- nothing may raise into pythonfmu
            self.model = None
            self._report("initialisation", error)

    def _check_parameters(self):
        """Raise ValueError naming the first number parameter that is not finite or lies
        outside its declared limits (the host layer refuses these where they are set; a
        build without it, or a value set before the layer saw it, is caught here)."""
        for variable in self.vars.values():
            value = getattr(self, variable.name)
            if variable.causality != Fmi2Causality.parameter or isinstance(value, (bool, str)):
                continue
            if not math.isfinite(value):
                raise ValueError(f"{variable.name}: must be finite, got {value!r}")
            lower, upper = self.limits.get(variable.name, (None, None))
            if (lower is not None and value < lower) or (upper is not None and value > upper):
                raise ValueError(f"{variable.name} = {value!r} is outside its limits "
                                 f"[{lower}, {upper}]")

    def _check_outputs(self):
        """Raise ValueError naming the first output that is not finite: the parameters and
        inputs, each valid, took the model beyond a float's range (never reported as OK)."""
        for name in self._output_names:
            value = getattr(self, name)
            if not math.isfinite(value):
                raise ValueError(f"output {name} = {value!r}: the parameters and inputs take "
                                 "the model beyond a float's range")

    def _finite_outputs(self, current_time, values):
        """``values`` (the outputs after a step) if all are finite, else None with the error
        logged (the exchange's check when their sum is not finite)."""
        try:
            self._check_outputs()
        except ValueError as error:
            self._report(f"at t = {current_time} s", error)
            return None
        return values

    def do_step(self, current_time, step_size):
        names = self._input_names
        return self._advance(current_time, step_size, names, [getattr(self, n) for n in names])

    def exchanger(self, input_names, output_names):
        """``exchange(current_time, step_size, *inputs)``: set the inputs (in the order of
        ``input_names``), do the step as :meth:`do_step`, and return the outputs (in the
        order of ``output_names``) as a tuple; when the step failed or logged, return
        ``[outputs or None, [(status, category, message), ...]]`` and empty the log queue.

        It runs at every doStep, so it is written out for these variables (see
        :data:`EXCHANGE`): when the inputs are finite, the step size valid and the model
        built, it steps at once; anything else goes through :meth:`_advance`, which says what
        is wrong. A loop over the names and the checks cost a quarter of an FMU's Python work
        per step (5,800 of 21,800 instructions for StepperError, callgrind).
        """
        inputs, outputs = tuple(input_names), tuple(output_names)
        self._exchange_outputs = outputs
        declared = {variable.name for variable in self.vars.values()}
        for name in (*inputs, *outputs):
            if not (name.isidentifier() and name in declared):
                raise ValueError(f"{name!r} is not a variable of {type(self).__name__}")
        values = ", ".join(inputs)
        source = EXCHANGE.format(
            values=values, values_tuple=f"({values},)" if inputs else "()",
            assignments="".join(f"    slave.{name} = {name}\n" for name in inputs),
            total=" + ".join(inputs) or "0.0",
            outputs_total=" + ".join(f"slave.{name}" for name in outputs) or "0.0",
            outputs=", ".join(f"slave.{name}" for name in outputs) + ",")
        namespace = {"slave": self, "step": self.step, "advance": self._advance,
                     "drained": self._drained, "finite": self._finite_outputs,
                     "INPUTS": inputs, "inf": math.inf,
                     "isfinite": math.isfinite}
        exec(compile(source, f"<{type(self).__name__} exchange>", "exec"), namespace)
        exchange = namespace["exchange"]
        exchange.state_error = self.state_error  # the host layer's check of a state buffer
        exchange.initialised = self.initialised  # which FMI state a restored state is in
        if self.native_step()[0] is not None:  # the compiled step, for the host layer
            exchange.native_pack, exchange.native_unpack = self._native_pack, self._native_unpack
        return exchange

    def _native_pack(self):
        """(library path, C symbol, block address) of the compiled step over a block filled
        now (:meth:`native_block`), or None before the model is built."""
        if self.model is None:
            return None
        values = self.native_block()
        if self._block is None or len(self._block) != len(values):
            self._block = array.array("d", values)  # its address stays while its size does
        else:
            self._block[:] = array.array("d", values)
        return (*self.native_step()[0], self._block.buffer_info()[0])

    def _native_unpack(self, *outputs):
        """After compiled steps: set the outputs (in the exchange's order) and take the
        model's state back from the block."""
        for name, value in zip(self._exchange_outputs, outputs):
            setattr(self, name, value)
        self.restore_native(self._block)

    def _drained(self, outputs):
        """``[outputs, [(status, category, message), ...]]`` of the log queue, emptied."""
        messages = [(int(m.status), m.category, m.msg) for m in self.log_queue]
        self.log_queue.clear()
        return [outputs, messages]

    def _advance(self, current_time, step_size, input_names, values):
        """The checked step, the inputs ``input_names`` holding ``values``: True, or False
        with the error logged (nothing may raise into pythonfmu)."""
        try:
            if self.model is None:
                raise ValueError("doStep after a failed initialisation")
            if not 0.0 < step_size < math.inf:
                raise ValueError(f"communication step size must be finite and > 0, "
                                 f"got {step_size!r}")
            if not math.isfinite(sum(values)):  # one check for all; the loop names the input
                for name, value in zip(input_names, values):
                    if not math.isfinite(value):
                        raise ValueError(f"input {name} must be finite, got {value!r}")
            self.step(step_size)
            self._check_outputs()
        except Exception as error:  # noqa: BLE001 -- nothing may raise into pythonfmu
            return self._report(f"at t = {current_time} s", error)
        return True

    def _report(self, where, error):
        """Log ``error``: a ValueError (bad input) as an error, anything else (a bug) as
        fatal with its traceback. Returns False (the step failed). A ValueError that is not
        about one parameter (which the physics names first: ``diameter_m: must be > 0``) nor
        names an input gets the inputs' values, which brought the model there
        (``math domain error``, a non-finite output)."""
        if isinstance(error, ValueError):
            text = str(error)
            about_one = any(text.startswith(variable.name) for variable in self.vars.values())
            if not about_one and not any(name in text for name in self._input_names):
                values = ", ".join(f"{n} = {getattr(self, n)!r}" for n in self._input_names)
                text = f"{text} (the inputs: {values})"
            self.log(f"{where}: {text}", Fmi2Status.error, "logStatusError")
        else:
            self.log(f"{where}: internal error\n{traceback.format_exc()}", Fmi2Status.fatal,
                     "logStatusFatal")
        return False

    def _get_fmu_state(self):
        state = super()._get_fmu_state()
        state["initialised"] = self.model is not None
        state["model_state"] = self.model_state() if state["initialised"] else None
        return state

    def _set_fmu_state(self, state):
        problem = self._state_error(state)
        if problem is None:
            saved = self._get_fmu_state()
            try:
                self._restore(state)
            except Exception as error:  # noqa: BLE001 -- nothing may raise into pythonfmu
                self._restore(saved)
                problem = f"its model state does not restore ({type(error).__name__}: {error})"
        if problem is not None:
            self.log(f"fmi2SetFMUstate refused, the instance is unchanged: {problem}",
                     Fmi2Status.error, "logStatusError")

    def _restore(self, state):
        state = dict(state)
        initialised, model_state = state.pop("initialised"), state.pop("model_state")
        super()._set_fmu_state(state)
        if initialised:
            self.restore_model_state(model_state)

    def initialised(self):
        """Whether the model is built (initialisation succeeded, or a state saved after it
        was restored)."""
        return self.model is not None

    def state_error(self, data):
        """Why the serialised ``data`` (bytes) is not a state of this FMU, or None."""
        return self._state_error(self._fmu_state_from_bytes(data))

    def _state_error(self, state):
        """Why ``state`` (a deserialised state) is not one this FMU saved, or None."""
        if not isinstance(state, dict):
            return f"not a state: {type(state).__name__}"
        if REFUSED in state:
            return state[REFUSED]
        variables = {variable.name: variable for variable in self.vars.values()}
        unknown = sorted(set(state) - set(variables) - STATE_KEYS)
        missing = sorted((set(variables) | STATE_KEYS) - set(state))
        if unknown or missing:
            return (f"not a state of this FMU (unknown: {', '.join(unknown) or 'none'}; "
                    f"missing: {', '.join(missing) or 'none'})")
        for name, variable in variables.items():
            value = state[name]
            allowed = _STATE_VALUES[type(variable)]
            if not isinstance(value, allowed) or (bool not in allowed and isinstance(value, bool)):
                return f"{name} holds {value!r}, not a {type(variable).__name__}"
            fixed = variable.variability == Fmi2Variability.fixed
            if fixed and self.model is not None and value != getattr(self, name):
                return (f"fixed parameter {name} is {value!r} in the state, "
                        f"{getattr(self, name)!r} in this initialised instance")
        if state["initialised"] is not (self.model is not None):
            return ("a state saved before initialisation restores only before it, and one "
                    "saved after only after")
        return None

    @staticmethod
    def _fmu_state_from_bytes(state):
        """pythonfmu's parse of a serialised state, never raising (pythonfmu makes any
        exception fmi2Fatal): a buffer that is no JSON object gives a :data:`REFUSED` entry."""
        try:
            parsed = json.loads(bytes(state).decode("utf-8"))
        except (UnicodeDecodeError, ValueError, RecursionError) as error:
            return {REFUSED: f"not a serialised state ({type(error).__name__}: {error})"}
        if not isinstance(parsed, dict):
            return {REFUSED: f"not a serialised state (a JSON {type(parsed).__name__})"}
        return parsed
