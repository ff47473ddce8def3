"""Each FMU's step on flat numbers, which the FMU's host layer calls compiled, without Python.

The NpidServo, StepperError and GeometricError FMUs step every macro step; entering Python
for that costs more than their physics, and ThermalScrew's NumPy calls on its 80 cells cost
as much again in Python as their arithmetic. feedaxis.kernel_build compiles the step functions
here with numba's ahead-of-time compiler into the FMUs' compiled module (:mod:`.kernel`) as C
functions ``int step(double *block, double step_size_s, const double *inputs, double
*outputs)``: ``block`` holds the parameters and the state (the layout of the FMU's
``*_block`` function below, filled by its slave), ``inputs`` and ``outputs`` the FMU's Real
inputs and outputs in their declared order. They call the same physics functions as the
slaves' Python steps (compiled by numba: the float branches of :mod:`.scalar` and
:mod:`.checks` through :func:`register_float_overloads`).

A step returns 1 when done, 0 when it declines: a step size that is not finite and > 0, an
input that is not finite, an output that would not be finite, more internal steps than
allowed (ThermalScrew: more sub-steps than its Euler loop takes; the Python step takes those
as a matrix power through NumPy's BLAS, which the compiled module does not carry, faster
than plain compiled loops would). A declined step leaves the block as it was, so the slave's
Python step, which says what is wrong or takes the step, takes it from the same state; an
exception inside (none is expected) declines too.
"""
from __future__ import annotations

import math
import types

from . import geometry, motor, mounting, scalar, servo, thermal
from .kernel import shipped_kernel

# the symbols of the C functions in the compiled module, by FMU
STEPS = {"StepperError": "feedaxis_stepper_error_step",
         "GeometricError": "feedaxis_geometric_error_step",
         "NpidServo": "feedaxis_npid_servo_step",
         "ThermalScrew": "feedaxis_thermal_screw_step"}
SIGNATURE = "i4(CPointer(f8), f8, CPointer(f8), CPointer(f8))"


def native_step(name):
    """(FMU ``name``'s compiled step: (library path, C symbol), or None; why the compiled
    module did not load, or None)."""
    module, failure = shipped_kernel()
    return (None if module is None else (module.__file__, STEPS[name])), failure


def stepper_error_block(position_offset_mm, period_mm, cos_um, sin_um):
    """StepperError's block: offset (mm), motor error period (mm), the two harmonics' cosine
    and sine amplitudes (µm)."""
    return [position_offset_mm, period_mm, *cos_um, *sin_um]


def stepper_error_step(block, step_size_s, inputs, outputs):
    """StepperError: ``error_um`` at ``position_mm`` (:func:`.motor.motor_error_um`)."""
    if not (0.0 < step_size_s < math.inf and math.isfinite(inputs[0])):
        return 0
    error_um = motor.motor_error_um(block[0] + inputs[0], block[1], (block[2], block[3]),
                                    (block[4], block[5]))
    if not math.isfinite(error_um):
        return 0
    outputs[0] = error_um
    return 1


GEOMETRY_HEADER = 11  # the block's numbers before the gravity sag table


def geometric_error_block(engagement, position_offset_mm, lead_mm, offset_um, slope_um_per_mm,
                          cos_um, sin_um, backlash_um, sag_enabled, fixed_end_mm, sag_table):
    """GeometricError's block: the engagement in the play (its state, first), the parameters,
    then the gravity sag table (n, x, y, slope of each interval: :class:`.scalar.Table`)."""
    return [engagement, position_offset_mm, lead_mm, offset_um, slope_um_per_mm, cos_um,
            sin_um, backlash_um, float(sag_enabled), fixed_end_mm,
            float(len(sag_table.x_list)), *sag_table.x_list, *sag_table.y_list,
            *sag_table.slope_list]


def geometric_error_step(block, step_size_s, inputs, outputs):
    """GeometricError: the transmission error (:func:`.geometry.transmission_error_um`) with
    the play's engagement advanced (:func:`.geometry.play_engagement`) and the gravity sag
    at the nut (:func:`.mounting.screw_coordinate_m`, :func:`.scalar.interp_float`)."""
    position_mm, velocity_mm_s = inputs[0], inputs[1]
    if not (0.0 < step_size_s < math.inf and math.isfinite(position_mm + velocity_mm_s)):
        return 0
    backlash_um = block[7]
    engagement = geometry.play_engagement(block[0], velocity_mm_s * step_size_s, backlash_um)
    position_mm = block[1] + position_mm
    sag_um = 0.0
    if block[8] != 0.0:
        n = int(block[10])
        table = numbers(block, GEOMETRY_HEADER + 3 * n - 1)
        x = table[GEOMETRY_HEADER:GEOMETRY_HEADER + n]
        y = table[GEOMETRY_HEADER + n:GEOMETRY_HEADER + 2 * n]
        slope = table[GEOMETRY_HEADER + 2 * n:GEOMETRY_HEADER + 3 * n - 1]
        sag_um = scalar.interp_float(mounting.screw_coordinate_m(position_mm, block[9]), x, y,
                                     slope)
    error_um = geometry.transmission_error_um(position_mm, engagement, block[2], block[3],
                                              block[4], block[5], block[6], backlash_um, sag_um)
    if not math.isfinite(error_um):
        return 0
    block[0] = engagement
    outputs[0] = error_um
    return 1


SERVO_HEADER = 8  # the block's numbers before the loop's coefficients
N_COEFFICIENTS = 27  # servo.loop_coefficients


def npid_servo_block(position_offset_mm, params, max_internal_steps, coefficients, state):
    """NpidServo's block: offset (mm), force_N, force constant (N/V), time step (s), the
    carried time (s, state), the most internal steps a step may take, the delay line's
    length, the coefficients (:func:`.servo.loop_coefficients`), then the loop state
    (:meth:`.servo.Servo.state`: run_loop's six values, the delay line) and room for a copy
    of it and run_loop's one-sample arguments."""
    loop, commands_V = state["loop"], state["commands_V"]
    return [position_offset_mm, params.force_N, params.force_constant_N_per_V,
            params.time_step_s, state["pending_s"], float(max_internal_steps),
            float(len(commands_V)), 0.0, *coefficients, *loop, *commands_V,
            *([0.0] * (servo.STATE_SIZE + len(commands_V) + 5))]


def npid_servo_state(block):
    """The loop state (:meth:`.servo.Servo.state`) in NpidServo's block."""
    size = int(block[6])
    start = SERVO_HEADER + N_COEFFICIENTS
    end = start + servo.STATE_SIZE
    return {"loop": list(block[start:end]), "commands_V": list(block[end:end + size]),
            "pending_s": block[4]}


def npid_servo_step(block, step_size_s, inputs, outputs):
    """NpidServo: the closed loop over one communication step (:func:`.servo.whole_steps`,
    :func:`.servo.run_loop`), outputs as :meth:`.servo.Servo.outputs`, the position less
    the offset."""
    reference_mm, disturbance_N = inputs[0], inputs[1]
    if not (0.0 < step_size_s < math.inf and math.isfinite(reference_mm + disturbance_N)
            and step_size_s / block[3] <= block[5]):
        return 0
    size = int(block[6])
    state_at = SERVO_HEADER + N_COEFFICIENTS
    saved_at = state_at + servo.STATE_SIZE + size
    samples_at = saved_at + servo.STATE_SIZE + size
    values = numbers(block, samples_at + 5)
    loop = values[state_at:saved_at]
    saved = values[saved_at:samples_at]
    saved[:] = loop
    n_steps, pending_s = servo.whole_steps(block[4], step_size_s, block[3])
    reference_mm = block[0] + reference_mm
    if n_steps > 0:
        steps = values[samples_at:samples_at + 1].view(INT64)
        steps[0] = n_steps
        values[samples_at + 1] = reference_mm
        values[samples_at + 2] = servo.force_command_V(disturbance_N, block[1], block[2])
        servo.run_loop(values[SERVO_HEADER:state_at], steps,
                       values[samples_at + 1:samples_at + 2],
                       values[samples_at + 2:samples_at + 3], loop[:servo.STATE_SIZE],
                       loop[servo.STATE_SIZE:], values[samples_at + 3:samples_at + 4],
                       values[samples_at + 4:samples_at + 5])
    position_mm, velocity_mm_s = loop[0], loop[1]
    tracking_error_mm = position_mm - loop[4]
    control_V = servo.newest_command_V(loop[servo.STATE_SIZE:], loop[5])
    if not math.isfinite(position_mm + velocity_mm_s + tracking_error_mm + control_V):
        loop[:] = saved
        return 0
    block[4] = pending_s
    outputs[0] = position_mm - block[0]
    outputs[1] = velocity_mm_s
    outputs[2] = tracking_error_mm
    outputs[3] = control_V
    return 1


THERMAL_HEADER = 3  # the block's numbers before the cell terms
THERMAL_ARRAYS = 6  # thermal.CellTerms: its per-cell arrays first, then its floats
THERMAL_FLOATS = len(thermal.CellTerms._fields) - THERMAL_ARRAYS


def thermal_screw_block(position_offset_mm, reference_ambient_C, cells, rise_K):
    """ThermalScrew's block: the number of cells, offset (mm), the ambient at which TE_a = 0
    (°C), the floats of the cell terms (:class:`.thermal.CellTerms`), its per-cell arrays,
    then the temperature rise per cell (K, its state)."""
    return [float(rise_K.size), position_offset_mm, reference_ambient_C,
            *cells[THERMAL_ARRAYS:], *(x for array in cells[:THERMAL_ARRAYS] for x in array),
            *rise_K]


def thermal_screw_cells(values, n):
    """The :class:`.thermal.CellTerms` in ThermalScrew's block (``values``: its numbers as an
    array, ``n`` cells), and the rise per cell (K), as views of the block."""
    floats = values[THERMAL_HEADER:THERMAL_HEADER + THERMAL_FLOATS]
    start = THERMAL_HEADER + THERMAL_FLOATS
    cell = values[start:start + (THERMAL_ARRAYS + 1) * n]
    return (thermal.CellTerms(cell[:n], cell[n:2 * n], cell[2 * n:3 * n], cell[3 * n:4 * n],
                              cell[4 * n:5 * n], cell[5 * n:6 * n], floats[0], floats[1],
                              floats[2], floats[3], floats[4], floats[5], floats[6], floats[7],
                              floats[8], floats[9], floats[10], floats[11], floats[12],
                              floats[13]),
            cell[6 * n:])


def thermal_screw_rise_K(block):
    """The temperature rise per cell (K) in ThermalScrew's block."""
    n = int(block[0])
    return list(block[len(block) - n:])


def thermal_screw_step(block, step_size_s, inputs, outputs):
    """ThermalScrew: the field advanced as :func:`.thermal.advance` does in at most
    :data:`.thermal.EULER_LOOP_LIMIT` sub-steps (:func:`.thermal.held_nut_terms`,
    :func:`.thermal.sub_steps`, :func:`.thermal.euler_steps`), outputs as the slave's: the
    error at the nut (:func:`.thermal.positioning_error_um` of
    :func:`.thermal.elongation_at_um`), the free end's elongation, the peak rise."""
    position_mm = block[1] + inputs[0]
    feed_mm_min = inputs[1] * 60.0
    ambient_delta_K = inputs[2] - block[2]
    if not (0.0 < step_size_s < math.inf
            and math.isfinite(position_mm + feed_mm_min + ambient_delta_K)):
        return 0
    n = int(block[0])
    cells, rise_K = thermal_screw_cells(
        numbers(block, THERMAL_HEADER + THERMAL_FLOATS + (THERMAL_ARRAYS + 1) * n), n)
    _, loss_W_K, sources_K_s, sub_step_s = thermal.held_nut_terms(cells, position_mm,
                                                                  feed_mm_min)
    n_sub = thermal.sub_steps(step_size_s, sub_step_s)
    if not 0 < n_sub <= thermal.EULER_LOOP_LIMIT:
        return 0
    advanced_K = thermal.euler_steps(cells, rise_K, loss_W_K, sources_K_s, step_size_s / n_sub,
                                     n_sub)
    screw_m = mounting.screw_coordinate_m(position_mm, cells.fixed_end_mm)
    error_um = thermal.positioning_error_um(
        cells, thermal.elongation_at_um(cells, advanced_K, screw_m), position_mm,
        ambient_delta_K)
    elongation_um = thermal.elongation_at_um(cells, advanced_K, cells.length_m)
    peak_rise_K = advanced_K.max()
    if not math.isfinite(error_um + elongation_um + peak_rise_K):
        return 0
    rise_K[:] = advanced_K
    outputs[0] = error_um
    outputs[1] = elongation_um
    outputs[2] = peak_rise_K
    return 1


def numbers(block, size):
    """The first ``size`` numbers of ``block`` as an array (numba.carray where compiled;
    bound by :func:`compiled_steps`)."""
    raise NotImplementedError("numbers() exists compiled only (fmu_steps.compiled_steps)")


INT64 = None  # numpy.int64 where compiled (compiled_steps)


def register_float_overloads(numba):
    """Let numba compile the physics for one float: the float branches of
    :func:`.scalar.values`, :func:`.scalar.values_and_module`, :func:`.scalar.clip`,
    :func:`.scalar.trailing_axis`,
    :func:`.checks.require_positive`, and ``bisect.bisect_right`` over an array (what
    :func:`.scalar.interp_float` takes)."""
    import bisect

    import numpy as np
    from numba.extending import overload

    from . import checks

    float_types = (numba.types.Float, numba.types.Integer)
    clip_float = numba.njit(scalar.clip_float)

    @overload(scalar.values)
    def _values(value):
        if isinstance(value, float_types):
            return lambda value: float(value)

    @overload(scalar.values_and_module)
    def _values_and_module(value):
        if isinstance(value, float_types):
            return lambda value: (float(value), math)

    @overload(scalar.clip)
    def _clip(value, lower, upper):
        if isinstance(value, float_types):
            return lambda value, lower, upper: clip_float(value, lower, upper)

    @overload(scalar.trailing_axis)
    def _trailing_axis(value):
        if isinstance(value, float_types):
            return lambda value: value

    @overload(checks.require_positive)
    def _require_positive(name, value):
        if isinstance(value, float_types):
            def check(name, value):
                if not 0.0 < value < math.inf:
                    raise ValueError("must be finite and > 0")
            return check

    @overload(bisect.bisect_right)
    def _bisect_right(x, value):
        if isinstance(x, numba.types.Array):
            return lambda x, value: np.searchsorted(x, value, side="right")


def compiled_steps(numba):
    """{symbol: the FMU's step function, its physics calls bound to numba-compiled copies}
    (:data:`STEPS`): what feedaxis.kernel_build exports as C functions."""
    import numpy as np

    register_float_overloads(numba)
    compiled = {}
    extra = {"numbers": numba.njit(lambda block, size: numba.carray(block, size)),
             "INT64": np.int64}
    return {symbol: rebound(numba, globals()[f"{_snake(name)}_step"], compiled, extra)
            for name, symbol in STEPS.items()}


def _snake(name):
    """``StepperError`` -> ``stepper_error``."""
    return "".join(f"_{c.lower()}" if c.isupper() else c for c in name).lstrip("_")


def _overloaded():
    """The physics functions numba compiles through :func:`register_float_overloads`."""
    from . import checks

    return {scalar.values, scalar.values_and_module, scalar.clip, scalar.trailing_axis,
            checks.require_positive}


def bound(numba, function, compiled):
    """``function`` compiled by numba (lazily), with the physics functions and modules it
    names bound to compiled copies in turn (``compiled``: those made so far)."""
    if function not in compiled:
        namespace = dict(function.__globals__)
        compiled[function] = numba.njit(_with_globals(function, namespace))
        _bind_names(numba, function, namespace, compiled)
    return compiled[function]


def rebound(numba, function, compiled, extra):
    """``function`` (Python) with the physics functions and modules it names bound to
    compiled copies (:func:`bound`), and the names in ``extra``."""
    namespace = {**function.__globals__, **extra}
    _bind_names(numba, function, namespace, compiled)
    return _with_globals(function, namespace)


def _with_globals(function, namespace):
    return types.FunctionType(function.__code__, namespace, function.__name__,
                              function.__defaults__, function.__closure__)


def _bind_names(numba, function, namespace, compiled):
    """Bind the physics functions and modules ``function`` names in ``namespace``."""
    for name in function.__code__.co_names:
        value = namespace.get(name)
        if isinstance(value, types.ModuleType) and _physics(value.__name__):
            namespace[name] = _bound_module(numba, value, compiled)
        elif (isinstance(value, types.FunctionType) and _physics(value.__module__)
              and value not in _overloaded()):
            namespace[name] = bound(numba, value, compiled)


def _bound_module(numba, module, compiled):
    """A copy of the physics ``module`` whose functions are :func:`bound`."""
    if module in compiled:
        return compiled[module]
    copy = types.ModuleType(module.__name__)
    compiled[module] = copy
    for name, value in vars(module).items():
        if (isinstance(value, types.FunctionType) and _physics(value.__module__)
                and value not in _overloaded()):
            value = bound(numba, value, compiled)
        setattr(copy, name, value)
    return copy


def _physics(module_name):
    """Whether ``module_name`` is one of this physics package's modules."""
    return module_name is not None and module_name.startswith(f"{__package__}.")
