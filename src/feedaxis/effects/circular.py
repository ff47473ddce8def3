"""Effects on a circular test: each axis's own effects, and the machine's on the pair.

An effect of one axis is named ``EFFECT@AXIS`` (``backlash@X``): the argument of
``fit --add`` and the key of its parameters in a model file. It evaluates the one-axis
catalog effect at that axis's positions and directions of motion on the circle and adds
its error along the axis to the radius (:func:`feedaxis.physics.circle.radial_um`);
backlash crosses the nut's play as the GeometricError FMU does. The machine's effects
(``squareness``, ``servo_mismatch``) have no axis. What the set-up gives (the centring
offset of the instrument's pivot, a slow drift of its length, the radius) is not an
effect: the circular measurement fits it with every model.

Where an axis's ``[servo]`` is given, the effects acting inside its closed loop
(``coulomb_friction@X``, ``servo_plant@X``) set the loop's parameters; the circular
measurement runs that loop along the commanded circle (:class:`InLoop`) and adds its error
beyond the loop's error with every such effect off. Where it is not, friction at a reversal
is a free spike of that axis (``reversal_spike@X``).

A lead error's offset moves the axis as a whole: on the circle a centring offset, so only
its slope (a scale error, an ellipse along the axes) is fitted.
"""
from __future__ import annotations

import numpy as np

from ..case import Case
from ..measurement.positioning import Positioning, PositioningSamples
from ..physics import circle
from .base import Effect, Needs, Parameter
from .catalog import AssemblyEccentricity, LeadError, MotorStepError
from .tracking import CoulombFriction, ServoPlant

LEAD_KEYS = ("lead_mm",)


def axis_index(case, axis):
    return case.axis.circular.axes.index(axis)


def axis_case(case, axis, lag_deg=0.0):
    """The one-axis view of a circular case: axis ``axis`` with its positions on the circle
    as the targets and its direction of motion as the approach direction, ``lag_deg``
    behind the commanded angle."""
    samples, test = case.circular, case.axis.circular
    index = axis_index(case, axis)
    angle_deg = samples.angle_deg - samples.direction * lag_deg
    position_mm = circle.axis_positions_mm(angle_deg, test.radius_mm, test.center_mm, index)
    direction = circle.axis_direction(angle_deg, samples.direction, index)
    samples = PositioningSamples(position_mm, np.zeros(position_mm.size), direction,
                                 has_direction=True)
    return Case(case.folder, case.axis.axes[axis]).with_samples(Positioning.kind, samples)


class CircularEffect(Effect):
    """An effect on a circular test; ``axis`` is None for the machine's, ``effect`` the
    catalog name (the same on every axis)."""

    measurement = "circular"
    axis = None
    effect = ""

    def unavailable(self, case):
        if case.circular is None:
            return "the case has no circular.csv"
        if self.axis is None:
            return None
        axis = case.axis.axes[self.axis]
        missing = (axis.missing("screw", self.needs.screw_keys)
                   + axis.missing("motor", self.needs.motor_keys))
        if missing:
            return "needs " + ", ".join(m.replace("[", f"[axes.{self.axis}.") for m in missing)
        return None

    def component(self, fmu):
        return f"{self.axis}_{fmu}"


LAG = Parameter("lag_deg", "deg", 0.0, 10.0,
                "how far the axis trails the commanded angle (servo lag x angular speed)")


class OnAxis(CircularEffect):
    """A one-axis catalog effect ``inner`` acting on axis ``axis`` of the circle; the
    parameters in ``held`` are held at their values (not fitted). With ``lagged`` (an
    error periodic along the axis, whose phase a servo lag moves) the axis's positions trail
    the commanded angle by a fitted ``lag_deg``."""

    def __init__(self, inner, axis, held=None, needs=Needs(), lagged=False):
        self.inner, self.axis, self.held = inner, axis, dict(held or {})
        self.effect = inner.name
        self.name = f"{inner.name}@{axis}"
        self.meaning = f"axis {axis}: {inner.meaning}"
        self.parameters = tuple(p for p in inner.parameters if p.name not in self.held) + (
            (LAG,) if lagged else ())
        self.linear = tuple(n for n in inner.linear if n not in self.held)
        self.probe = {LAG.name: 0.05} if lagged else {}
        self.needs = Needs(screw_keys=inner.needs.screw_keys + needs.screw_keys,
                           motor_keys=inner.needs.motor_keys)
        self.fmu = inner.fmu

    def prepare(self, case):
        along = circle.unit_vector(case.circular.angle_deg, axis_index(case, self.axis))
        if LAG not in self.parameters:
            evaluate = self.inner.prepare(axis_case(case, self.axis))
            return lambda values: along * evaluate({**self.held, **values})

        last = {}  # the inner effect prepared at the last lag (a fit's split asks thrice)

        def lagged(values):
            lag_deg = values[LAG.name]
            if last.get("lag_deg") != lag_deg:
                last.update(lag_deg=lag_deg,
                            evaluate=self.inner.prepare(axis_case(case, self.axis, lag_deg)))
            return along * last["evaluate"](self.inner_values(values))

        return lagged

    def inner_values(self, values):
        """The inner catalog effect's values: the held ones, without the lag."""
        return {**self.held, **{k: v for k, v in values.items() if k != LAG.name}}

    def wavelength_mm(self, axis):
        return self.inner.wavelength_mm(axis.axes[self.axis])

    def fmu_parameters(self, axis, values):
        return {self.component(fmu): parameters for fmu, parameters in
                self.inner.fmu_parameters(axis.axes[self.axis],
                                          self.inner_values(values)).items()}

    def evidence(self, case, values, contribution_um):
        return f"axis {self.axis}: " + self.inner.evidence(axis_case(case, self.axis),
                                                           self.inner_values(values),
                                                           contribution_um)


class CircleBacklash(CircularEffect):
    """Backlash B of one axis: a step of B in the radius at its reversals, crossing the
    play over B of travel (:func:`feedaxis.physics.circle.backlash_um`)."""

    effect = "backlash"
    parameters = (Parameter("backlash_um", "um", -1e3, 1e3,
                            "reversal B = error moving in + minus error moving in -"),
                  Parameter("lag_deg", "deg", 0.0, 10.0,
                            "how far the axis trails the commanded angle (servo lag)"))
    probe = {"lag_deg": 0.05}
    fmu = "GeometricError"

    def __init__(self, axis):
        self.axis, self.name = axis, f"backlash@{axis}"
        self.meaning = (f"axis {axis}: lost motion in the nut and bearings, a step in the "
                        "radius where the axis reverses")

    def prepare(self, case):
        samples = case.circular
        radial = circle.backlash_shape(samples.angle_deg, samples.direction,
                                       axis_index(case, self.axis), case.axis.circular.radius_mm)
        return lambda v: radial(v["backlash_um"], v["lag_deg"])

    def guess(self, case, residual_um):
        samples = case.circular
        step = circle.backlash_um(samples.angle_deg, samples.direction,
                                  axis_index(case, self.axis), 1.0)
        value = float(step @ residual_um / max(step @ step, 1e-300))
        return {"backlash_um": float(np.clip(value, -1e3, 1e3)) or 1e-3, "lag_deg": 0.0}

    def fmu_parameters(self, axis, values):
        return {self.component(self.fmu): {"backlash_um": values["backlash_um"]}}

    def evidence(self, case, values, contribution_um):
        points = "0° and 180°" if axis_index(case, self.axis) == 0 else "90° and 270°"
        return (f"axis {self.axis}: the radius steps by B = {values['backlash_um']:+.3f} µm "
                f"where the axis reverses ({points}, {values['lag_deg']:.2f}° late)")


class InLoop(CircularEffect):
    """A tracking effect (``inner``: its parameters are NpidServo's) inside the closed loop
    of axis ``axis``, whose ``[servo]`` is given: the circular measurement simulates that
    loop along the commanded circle (:func:`feedaxis.physics.circle.loop_error_um`), so
    this effect is not additive. With ``screened`` the diagnosis ranks it by one
    linearised step before fitting it (the plant: its lag moves the circle nearly
    linearly); a friction is always fitted (its smoothed sign makes a step from 0 fall
    short: 0.27 µm RMS left where the fit leaves the 0.1 µm noise). Its neutral values are the loop of the machine
    (:data:`feedaxis.physics.circle.MACHINE_PLANT`, no friction)."""

    additive = False
    fmu = "NpidServo"

    def __init__(self, inner, axis, screened=False):
        self.inner, self.axis, self.screened = inner, axis, screened
        self.effect, self.name = inner.name, f"{inner.name}@{axis}"
        self.meaning = f"axis {axis}, through its servo loop: {inner.meaning}"
        self.parameters, self.probe = inner.parameters, inner.probe
        self.neutral = {key: circle.MACHINE_PLANT.get(key, value)
                        for key, value in inner.neutral.items()}

    def unavailable(self, case):
        reason = super().unavailable(case)
        if reason is None and not case.axis.axes[self.axis].servo:
            return (f"needs [axes.{self.axis}.servo] (the controller as set in the drive): "
                    f"without it friction on {self.axis} is a reversal spike")
        return reason

    def guess(self, case, residual_um):
        return dict(self.neutral)

    def fmu_parameters(self, axis, values):
        return {self.component(self.fmu): dict(values)}

    def evidence(self, case, values, contribution_um):
        changed = ", ".join(f"{name} {self.neutral[name]:.4g} -> {values[name]:.4g}"
                            for name in self.parameter_names)
        return (f"axis {self.axis}, its servo loop run along the circle: {changed}; "
                f"{np.ptp(contribution_um) / 2:.3g} µm on the radius")


class ReversalSpike(CircularEffect):
    """Friction at a reversal of one axis whose servo loop is not given: the axis sticks
    and trails its new motion by h·exp(−φ/φ0) (:func:`feedaxis.physics.circle.reversal_spike_um`)."""

    effect = "reversal_spike"
    parameters = (Parameter("height_um", "um", -1e3, 1e3, "spike height h at the reversal"),
                  Parameter("decay_deg", "deg", 0.05, 45.0,
                            "angle φ0 over which the spike decays by 1/e"))
    linear = ("height_um",)
    probe = {"decay_deg": 0.5}

    def __init__(self, axis):
        self.axis, self.name = axis, f"reversal_spike@{axis}"
        self.meaning = (f"axis {axis}: friction holds the axis at its reversal, a spike "
                        "outwards that decays as the axis gets going (quadrant spikes)")

    def unavailable(self, case):
        reason = super().unavailable(case)
        if reason is None and case.axis.axes[self.axis].servo:
            return (f"[axes.{self.axis}.servo] is given: friction acts through its servo "
                    "loop, not as a free spike")
        return reason

    def prepare(self, case):
        samples = case.circular
        radial = circle.reversal_spike_shape(samples.angle_deg, samples.direction,
                                             axis_index(case, self.axis))
        return lambda v: radial(v["height_um"], v["decay_deg"])

    def guess(self, case, residual_um):
        return {"height_um": 0.0, "decay_deg": 2.0}

    def evidence(self, case, values, contribution_um):
        return (f"axis {self.axis}: a spike of {values['height_um']:+.3f} µm at its reversals "
                f"decaying over {values['decay_deg']:.2f}°")


class Squareness(CircularEffect):
    """The second axis out of square with the first: α·R/2·sin 2θ in both directions."""

    name = effect = "squareness"
    meaning = ("the two axes are not at right angles: an ellipse at 45° that stays when the "
               "direction changes")
    parameters = (Parameter("squareness_urad", "urad", -1e5, 1e5,
                            "α: the table moves α·y along the first axis as the second "
                            "travels y (µm/m)"),)
    linear = ("squareness_urad",)

    def prepare(self, case):
        angle, radius_mm = case.circular.angle_deg, case.axis.circular.radius_mm
        return lambda v: circle.squareness_um(angle, radius_mm, v["squareness_urad"])

    def evidence(self, case, values, contribution_um):
        first, second = case.axis.circular.axes
        return (f"an ellipse at 45°, {np.ptp(contribution_um) / 2:.3f} µm, the same both ways: "
                f"{second} out of square with {first} by {values['squareness_urad']:+.2f} µrad")


class ServoMismatch(CircularEffect):
    """The two axes' servo loops lag their commands by different times T_1, T_2:
    F·(T_1 − T_2)/2·sin 2θ, changing sign with the direction. The plants are never in
    axis.toml (a ``[servo]`` holds the controller), so the lag difference is fitted."""

    name = effect = "servo_mismatch"
    meaning = ("the two axes' position loops lag by different times (unequal gains): an "
               "ellipse at 45° that flips with the direction")
    parameters = (Parameter("lag_difference_ms", "ms", -1e3, 1e3,
                            "T_1 − T_2: lag of the first axis less that of the second"),)
    linear = ("lag_difference_ms",)

    def prepare(self, case):
        samples, test = case.circular, case.axis.circular
        feed_mm_s = test.feed_mm_min / 60.0
        return lambda v: circle.lag_mismatch_um(samples.angle_deg, samples.direction,
                                                feed_mm_s, v["lag_difference_ms"] * 1e-3, 0.0)

    def evidence(self, case, values, contribution_um):
        first, second = case.axis.circular.axes
        return (f"an ellipse at 45°, {np.ptp(contribution_um) / 2:.3f} µm, flipping with the "
                f"direction: {first} lags {values['lag_difference_ms']:+.3f} ms more than "
                f"{second}")


def circular_effects(machine):
    """{add name: effect} of a circular case's machine (:class:`feedaxis.circular_case.Machine`):
    each axis's effects, then the machine's."""
    effects = []
    for axis in machine.circular.axes:
        effects += [OnAxis(LeadError(), axis, held={"offset_um": 0.0}),
                    OnAxis(AssemblyEccentricity(), axis, needs=Needs(screw_keys=LEAD_KEYS),
                           lagged=True),
                    OnAxis(MotorStepError(), axis, needs=Needs(screw_keys=LEAD_KEYS),
                           lagged=True),
                    CircleBacklash(axis), ReversalSpike(axis),
                    InLoop(CoulombFriction(), axis), InLoop(ServoPlant(), axis, screened=True)]
    effects += [Squareness(), ServoMismatch()]
    return {effect.name: effect for effect in effects}


def case_effects(case):
    """The effects of a circular case (:func:`circular_effects` of its machine)."""
    return circular_effects(case.axis)
