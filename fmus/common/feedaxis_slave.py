"""Common pythonfmu adapter for the feedaxis FMUs: variables, checks, errors and state.

Travels inside every FMU next to ``physics`` (a copy of feedaxis.physics).
A slave declares its variables with :meth:`AxisSlave.parameter`, :meth:`AxisSlave.input`
and :meth:`AxisSlave.output`, builds its physics object in :meth:`AxisSlave.build` and
advances it in :meth:`AxisSlave.step`. Nothing raises into pythonfmu (which would turn any
exception into fmi2Fatal and leave its instance holding freed objects): a ValueError (a bad
parameter, a NaN input, a refused step) is logged with category ``logStatusError`` naming
the variable, any other exception (a bug) with ``logStatusFatal`` and its traceback; the
FMU's host layer (fmus/common/feedaxis_fmi_host.c) returns that status for the call.
"""
import math
import traceback

from pythonfmu import Boolean, Fmi2Causality, Fmi2Initial, Fmi2Slave, Fmi2Variability
from pythonfmu import Integer, Real, String
from pythonfmu.enums import Fmi2Status

_TYPES = {bool: Boolean, int: Integer, float: Real, str: String}


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

    def _declare(self, name, value, description, unit, limits, **kind):
        setattr(self, name, value)
        self.register_variable(_TYPES[type(value)](name, description=description, **kind))
        if unit:
            self.units[name] = unit
        if limits:
            self.limits[name] = limits

    def parameter(self, name, value, description, unit=None, limits=None):
        """Declare a fixed parameter with its default ``value`` (bool, int, float or str)."""
        self._declare(name, value, description, unit, limits,
                      causality=Fmi2Causality.parameter, variability=Fmi2Variability.fixed)

    def input(self, name, value, description, unit=None):
        """Declare a Real input with its start ``value``; NaN or infinity is refused."""
        self._input_names.append(name)
        self._declare(name, float(value), description, unit, None, causality=Fmi2Causality.input)

    def output(self, name, description, unit=None):
        """Declare a Real output, calculated at initialisation from parameters and inputs."""
        self._declare(name, 0.0, description, unit, None,
                      causality=Fmi2Causality.output, initial=Fmi2Initial.calculated)

    def build(self):
        """Return the physics object from the parameters (raise ValueError if one is bad)."""
        raise NotImplementedError

    def step(self, step_size_s):
        """Advance ``self.model`` by ``step_size_s`` and update the outputs."""
        raise NotImplementedError

    def model_state(self):
        """Internal state beyond the FMI variables, as JSON-compatible values."""
        return None

    def restore_model_state(self, state):
        """Restore what :meth:`model_state` returned."""

    def exit_initialization_mode(self):
        try:
            self.model = self.build()
            self.step(0.0)
        except Exception as error:  # noqa: BLE001 -- nothing may raise into pythonfmu
            self._report("initialisation", error)

    def do_step(self, current_time, step_size):
        try:
            self._step_checked(step_size)
        except Exception as error:  # noqa: BLE001 -- nothing may raise into pythonfmu
            return self._report(f"at t = {current_time} s", error)
        return True

    def _step_checked(self, step_size):
        if self.model is None:
            raise ValueError("doStep after a failed initialisation")
        if not (step_size > 0 and math.isfinite(step_size)):
            raise ValueError(f"communication step size must be finite and > 0, got {step_size!r}")
        for name in self._input_names:
            if not math.isfinite(getattr(self, name)):
                raise ValueError(f"input {name} must be finite, got {getattr(self, name)!r}")
        self.step(step_size)

    def _report(self, where, error):
        """Log ``error``: a ValueError (bad input) as an error, anything else (a bug) as
        fatal with its traceback. Returns False (the step failed)."""
        if isinstance(error, ValueError):
            self.log(f"{where}: {error}", Fmi2Status.error, "logStatusError")
        else:
            self.log(f"{where}: internal error\n{traceback.format_exc()}", Fmi2Status.fatal,
                     "logStatusFatal")
        return False

    def _get_fmu_state(self):
        state = super()._get_fmu_state()
        state["model_state"] = self.model_state()
        return state

    def _set_fmu_state(self, state):
        state = dict(state)
        model_state = state.pop("model_state", None)
        super()._set_fmu_state(state)
        self.restore_model_state(model_state)
