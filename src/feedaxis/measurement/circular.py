"""A circular test of two axes (circular.csv, ISO 230-4, ballbar style).

The samples are radial deviations at nominal angles, counter-clockwise and clockwise.
The effects act on one axis (``backlash@X``) or on the machine (``squareness``) and add
to the radius (:mod:`feedaxis.effects.circular`).

The set-up is fitted with every model and never named as the machine's: the centring
offset of the instrument's pivot (cos θ, sin θ, the same both ways), the radius (the
programmed radius against the instrument's length, and the radius change of equal axis
lags) and a slow drift of the instrument's length along the test's clock. They are
projected out of the measurement and of every prediction (the model's least squares with
them fitted jointly, by the Frisch-Waugh-Lovell theorem), and reported as the set-up's
(:meth:`Circular.setup`).

What one direction cannot separate is said: squareness and a servo mismatch are both an
ellipse at 45° (sin 2θ); only the change of sign with the direction tells them apart. In
one direction both are passed over, and a 45° ellipse left in the residual makes the
verdict ``undetermined`` with that reason. A periodic effect of an axis whose wavelength
the samples step over along that axis is passed over with the reason.
"""
from __future__ import annotations

from dataclasses import replace
from functools import cached_property
from pathlib import Path

import numpy as np

from .. import kinds
from ..case import AXIS_FILE, CaseError
from ..circular_case import CIRCULAR_FILE, Machine, read_circular, read_machine
from ..iso230_4 import figures_um
from ..fmu_map import servo_to_fmu
from ..physics import circle
from ..physics.servo import check_runs
from ..stats import judge
from ..stats.noise import ResidualMeanSquare, Serial
from .base import Measurement, Shape, Trial, figure_table

MAX_HARMONIC = 90  # structure searched up to 90 cycles per turn (4° on the circle)
ONE_DIRECTION = ("squareness", "servo_mismatch")
SETUP = ("radius_um", "center_first_um", "center_second_um", "drift_um_per_s")
LSC_BOTH = "least squares, both paths"
LSC_OWN = "least squares, its own path"
MZC_BOTH = "minimum zone, both paths"
MZC_OWN = "minimum zone, its own path"
FIGURE_NAMES = {  # key: (name, the centre it is taken about)
    "G_um": ("circular deviation G (both directions)", LSC_BOTH),
    "G_ccw_um": ("circular deviation G, counter-clockwise", LSC_OWN),
    "G_cw_um": ("circular deviation G, clockwise", LSC_OWN),
    "H_um": ("circular hysteresis H", LSC_BOTH),
    "F_max_um": ("radial deviation F max", LSC_BOTH),
    "F_min_um": ("radial deviation F min", LSC_BOTH),
    "G_mz_um": ("circular deviation G (both directions)", MZC_BOTH),
    "G_ccw_mz_um": ("circular deviation G, counter-clockwise", MZC_OWN),
    "G_cw_mz_um": ("circular deviation G, clockwise", MZC_OWN)}
EXPLAINED = ("G_um", "G_ccw_um", "G_cw_um", "H_um", "G_mz_um", "G_ccw_mz_um", "G_cw_mz_um")


@kinds.register
class Circular(Measurement):
    """The circular samples of a case; the case's axis is the :class:`Machine` of two axes
    (this kind reads axis.toml's ``axis_tables``)."""

    kind = "circular"
    file = CIRCULAR_FILE
    location_key = "harmonic_per_turn"
    location_unit = "cycles per turn"
    coordinate_label = "angle (deg)"
    reference_label = "measured"
    stages = ("effects", "structures")
    measured_column = ("deviation_um", 1.0)
    capabilities = ("resolution", "shapes", "correlated", "setup", "core")
    axis_tables = ("circular", "axes")
    text = "feedaxis.measurement.circular:comparison_lines"
    views = "feedaxis.report.circular:VIEWS"
    scenarios = "feedaxis.cosim.circular:SCENARIOS"
    case_effects = "feedaxis.effects.circular:case_effects"
    comp_table = "feedaxis.comptable.circle:circle_comp_table"

    @classmethod
    def read(cls, folder, axis, duty):
        path = Path(folder) / cls.file
        if not path.exists():
            return None
        if not isinstance(axis, Machine):
            raise CaseError(Path(folder) / AXIS_FILE, f"{cls.file} is a circular test of two "
                                                      "axes: axis.toml needs [circular] and "
                                                      "[axes.NAME]", column="circular")
        return read_circular(path)

    @classmethod
    def read_axis(cls, path):
        """The machine of axis.toml (``[circular]``, ``[axes.NAME]``)."""
        return read_machine(path)

    def __init__(self, case):
        super().__init__(case)
        self.samples = self.samples_of(case)
        self.test = case.axis.circular
        self.angle_deg = self.coordinate = self.samples.angle_deg
        self.direction = self.samples.direction
        self.raw_um = np.asarray(self.samples.deviation_um, dtype=float)
        self.measured_um = self.project(self.raw_um)

    def describe(self):
        ways = "both directions" if self.samples.bidirectional else (
            "counter-clockwise" if self.direction[0] > 0 else "clockwise")
        return (f"{self.size} samples on R {self.test.radius_mm:g} mm, {ways} "
                f"(axes {', '.join(self.test.axes)})")

    # -- the set-up -----------------------------------------------------------------------

    @cached_property
    def clock(self):
        """The test's clock: ``time_s``, else the sample's place in the file (the order taken)."""
        return (self.samples.time_s if self.samples.time_s is not None
                else np.arange(self.angle_deg.size, dtype=float))

    @cached_property
    def setup_basis(self):
        """Columns: radius, centring offset along each axis, drift along the clock."""
        theta = np.radians(self.angle_deg)
        clock = self.clock - self.clock.mean()
        return np.column_stack((np.ones_like(theta), np.cos(theta), np.sin(theta), clock))

    @cached_property
    def orthonormal(self):
        return np.linalg.qr(self.setup_basis)[0]

    def project(self, values):
        """``values`` (samples, or samples x k) with the set-up's least squares taken out."""
        q = self.orthonormal
        return values - q @ (q.T @ values)

    def setup(self, residual_um):
        """The set-up's values fitted beside the model: {radius_um, center_first_um,
        center_second_um, drift_um_per_s (per sample where there is no time_s)} from the
        deviation the model leaves (``raw_um`` - prediction)."""
        values = np.linalg.lstsq(self.setup_basis, residual_um, rcond=None)[0]
        return dict(zip(SETUP, map(float, values)))

    def artefacts(self, result):
        """The set-up fitted beside the model (:meth:`setup`)."""
        return {"setup": self.setup(self.raw_um - self.model_um(result))}

    def separable(self, model):
        separate = super().separable(model)

        def projected(values):
            base_um, columns_um = separate(values)
            return self.project(base_um), self.project(columns_um)

        return projected

    def predictor(self, model):
        predict = super().predictor(model)
        return lambda values: self.project(predict(values))

    # -- the servo loops along the circle -------------------------------------------------

    def loop_params(self, axis, values):
        """:class:`~feedaxis.physics.servo.ServoParams` of ``axis``'s loop: its ``[servo]``
        on the machine's plant with ``values`` (NpidServo parameters)."""
        return circle.servo_params(servo_to_fmu(self.case.axis.axes[axis].servo), values)

    def loop_error_um(self, axis, values):
        """The error (µm) of ``axis``'s closed loop (:meth:`loop_params`) along the commanded
        circle."""
        samples, test = self.samples, self.test
        return circle.loop_error_um(self.loop_params(axis, values), samples.angle_deg,
                                    samples.direction, test.radius_mm, test.feed_mm_min,
                                    test.center_mm, test.axes.index(axis))

    @cached_property
    def given_loop_um(self):
        """{axis: the error (µm) of its loop as given} of each axis with a ``[servo]``."""
        return {axis: self.loop_error_um(axis, {}) for axis in self.test.axes
                if self.case.axis.axes[axis].servo}

    def loop_values(self, model, values):
        """{axis: NpidServo values} of each axis whose ``[servo]`` is given: the values of
        the model's effects inside its loop (none: the loop as given)."""
        merged = {axis: {} for axis in self.test.axes if self.case.axis.axes[axis].servo}
        for effect in model.effects:
            if not effect.additive:
                merged[effect.axis].update({**effect.neutral, **values[effect.name]})
        return merged

    def core(self, model):
        """The radial deviation of each axis's closed loop where its ``[servo]`` is given:
        the loop run along the commanded circle with the values of the model's effects
        inside it (:class:`feedaxis.effects.circular.InLoop`); the radius of the point
        both axes' errors move the commanded point to, exactly (a lag of 40 µm along the
        path changes a 20 mm radius by 0.04 µm, which the first-order projection misses).
        Equal loops lag both axes alike (a shift along the path, a radius change the
        set-up takes); unequal controllers give the ellipse of a servo mismatch."""
        if not self.loop_values(model, model.values):
            return None

        def predict(values):
            error_um = [np.zeros(self.size), np.zeros(self.size)]
            for axis, merged in self.loop_values(model, values).items():
                error_um[self.test.axes.index(axis)] = (
                    self.loop_error_um(axis, merged) if merged else self.given_loop_um[axis])
            return circle.radius_change_um(self.angle_deg, self.test.radius_mm, *error_um)

        return predict

    def check_start(self, model, values):
        """Each axis's loop must not run away with ``values``
        (:class:`~feedaxis.physics.servo.LoopRunsAway`)."""
        for axis, merged in self.loop_values(model, values).items():
            check_runs(self.loop_params(axis, merged), self.loop_error_um(axis, merged) * 1e-3)

    # -- what the samples resolve ---------------------------------------------------------

    def unresolvable(self, effect):
        """Squareness and a servo mismatch in one direction; a periodic effect of an axis
        whose wavelength the samples step over along that axis (steps of half a wavelength
        or more between neighbours in the order taken)."""
        if effect.name in ONE_DIRECTION and not self.samples.bidirectional:
            return ("one direction cannot separate squareness from a servo mismatch: both "
                    "are an ellipse at 45° (sin 2θ), which only the change of sign with the "
                    "direction tells apart; measure both directions")
        axis = getattr(effect, "axis", None)
        if axis is None:
            return None
        try:
            wavelength_mm = effect.wavelength_mm(self.case.axis)
        except KeyError:
            return None
        if not wavelength_mm:
            return None
        step_mm = self.largest_step_mm(axis)
        if step_mm >= wavelength_mm / 2:
            return (f"the samples step up to {step_mm:.4g} mm along {axis}, which does not "
                    f"resolve its {wavelength_mm:.4g} mm wavelength (steps below half of it "
                    "are needed: more samples per turn)")
        return None

    def largest_step_mm(self, axis):
        """The largest step (mm) along ``axis`` between neighbouring samples of a pass."""
        index = self.test.axes.index(axis)
        position = circle.axis_positions_mm(self.angle_deg, self.test.radius_mm,
                                            self.test.center_mm, index)
        same_pass = np.diff(self.direction) == 0
        steps = np.abs(np.diff(position))[same_pass]
        return float(steps.max()) if steps.size else np.inf

    # -- noise, structure, verdict --------------------------------------------------------

    @cached_property
    def noise(self):
        order = np.argsort(self.clock, kind="stable")
        return Serial(order, ResidualMeanSquare(order))

    def noise_gram(self, jacobian, residual_um, variance):
        return self.noise.gram(jacobian, residual_um, variance)

    def subset(self, keep):
        kept = {name: None if getattr(self.samples, name) is None else
                getattr(self.samples, name)[keep]
                for name in ("angle_deg", "deviation_um", "direction", "run", "time_s")}
        return Circular(self.case.with_samples(self.kind, replace(self.samples, **kept)))

    def shapes(self, effects):
        """Harmonics of the angle the same both ways and, in both directions, flipping with
        the direction; in one direction from 3 cycles per turn (2 is the 45° ellipse one
        direction cannot attribute, :meth:`undetermined`, or a scale mismatch, an effect)."""
        if not self.samples.bidirectional:
            return (Harmonic(flips=False, lowest=3),)
        return (Harmonic(flips=False), Harmonic(flips=True))

    def ellipse_45_test(self, residual_um, n_free):
        """The F test of a sin 2θ term (apart from the set-up) on ``residual_um`` (the noise
        model's shape test); (its amplitude (µm), its fit, the test)."""
        column = self.project(np.sin(2 * np.radians(self.angle_deg)))
        amplitude_um = float(column @ residual_um / (column @ column))
        fitted = amplitude_um * column
        return abs(amplitude_um), fitted, self.noise.shape_test(residual_um, residual_um - fitted,
                                                                1, n_free + 1)

    def undetermined(self, current, stages):
        """In one direction, a 45° ellipse left in the residual: squareness or a servo
        mismatch, which the data cannot tell apart."""
        if self.samples.bidirectional:
            return None
        amplitude_um, _, test = self.ellipse_45_test(current.residual_um,
                                                     current.statistics.n_free)
        if not judge.accepts(test.p_value, 1, stages) or amplitude_um < 1e-3:
            return None
        return (f"an ellipse at 45° of {amplitude_um:.3f} µm is left ({test.describe()}): "
                "squareness of the axes or a mismatch of their servo lags, which one "
                "direction cannot tell apart (only a servo mismatch changes sign with the "
                "direction); measure both directions")

    def rival(self, effect, left, result):
        """In one direction: why an effect of an axis is not what the data show when a 45°
        ellipse (one parameter) explains the residual at least as well (it would stand in
        for squareness or a servo mismatch, which one direction cannot name)."""
        if self.samples.bidirectional or effect.name in ONE_DIRECTION:
            return None
        _, fitted, _ = self.ellipse_45_test(left.residual_um, left.statistics.n_free)
        if np.sum((left.residual_um - fitted) ** 2) > np.sum(result.residual_um ** 2):
            return None
        return ("a 45° ellipse explains the residual at least as well: the effect would only "
                "stand in for squareness or a servo mismatch, which one direction cannot "
                "tell apart")

    # -- figures --------------------------------------------------------------------------

    def figures(self, result):
        """ISO 230-4 figures of the measurement and of what the model leaves, side by side;
        ``explained`` = 1 - residual / measured; ``center`` the centre a figure is taken
        about (G also about the minimum-zone centre, the one figure whose definition allows
        it)."""
        left_um = self.raw_um - self.model_um(result)
        measured, residual = (figures_um(self.angle_deg, values, self.direction)
                              for values in (self.raw_um, left_um))
        figures = {}
        for key, (name, centre) in FIGURE_NAMES.items():
            if measured[key] is None:
                continue
            explained = (1 - residual[key] / measured[key]
                         if key in EXPLAINED and measured[key] else None)
            figures[key] = {"name": name, "measured_um": measured[key],
                            "residual_um": residual[key], "explained": explained,
                            "center": centre}
        return {"case": str(self.case.folder), "kind": self.kind,
                "effects": list(result.model.names), "axes": list(self.test.axes),
                "radius_mm": self.test.radius_mm, "feed_mm_min": self.test.feed_mm_min,
                "bidirectional": self.samples.bidirectional,
                "setup": self.setup(left_um),
                "rms_measured_um": result.statistics.rms_before_um,
                "rms_residual_um": result.statistics.rms_um, "figures": figures}

    def model_um(self, result):
        """The model's own prediction at the samples (µm), before the set-up's projection."""
        return Measurement.predictor(self, result.model)(result.model.values)


class Harmonic(Shape):
    """A harmonic of the angle, n = ``lowest`` to ``MAX_HARMONIC`` cycles per turn, the same in both
    directions or (``flips``) changing sign with the direction, apart from the set-up; the
    n whose cosine and sine explain most of the residual."""

    extra = 2

    def __init__(self, flips, lowest=2):
        self.flips, self.lowest = flips, lowest
        self.kind = "harmonic_flipping" if flips else "harmonic"

    def trials(self, measurement):
        return MAX_HARMONIC - self.lowest + 1

    def columns(self, measurement, n):
        """cos nθ, sin nθ (times the direction when ``flips``), before the projection."""
        theta = np.radians(measurement.angle_deg)
        columns = np.column_stack((np.cos(n * theta), np.sin(n * theta)))
        return columns * measurement.direction[:, None] if self.flips else columns

    def trial(self, measurement, current):
        """The harmonic explaining most of the residual r, apart from the set-up (Q its
        orthonormal basis): with C its columns, the projected C'C is C'C − (Q'C)'(Q'C) and
        the projected C'r is C'r (r is orthogonal to Q), a 2 x 2 solve per harmonic."""
        residual, q = current.residual_um, measurement.orthonormal
        best, best_ss = None, -1.0
        for n in range(self.lowest, MAX_HARMONIC + 1):
            columns = self.columns(measurement, n)
            along = q.T @ columns
            gram = columns.T @ columns - along.T @ along
            right = columns.T @ residual
            explained = float(right @ np.linalg.lstsq(gram, right, rcond=None)[0])
            if explained > best_ss:
                best, best_ss = n, explained
        return Trial(measurement.project(self.columns(measurement, best)), float(best))

    def describe(self, measurement, trial, fitted_um):
        way = "changing sign with the direction" if self.flips else "the same both ways"
        return (f"{int(trial.location)} cycles per turn, {np.ptp(fitted_um) / 2:.3g} µm, {way}: "
                "no effect of either axis explains it")


def comparison_lines(comparison):
    """ISO 230-4 figures, measured against the residual after the model, and the set-up."""
    setup = comparison["setup"]
    lines = [f"circle R {comparison['radius_mm']:g} mm at {comparison['feed_mm_min']:g} mm/min, "
             f"axes {' '.join(comparison['axes'])}; model: "
             f"{', '.join(comparison['effects']) or '(none)'}",
             *figure_table("ISO 230-4 figure (µm), about its centre", 72, comparison)]
    first, second = comparison["axes"]
    lines.append(f"set-up (not the machine's): centre off by {setup['center_first_um']:+.3f} µm "
                 f"along {first}, {setup['center_second_um']:+.3f} µm along {second}; radius "
                 f"{setup['radius_um']:+.3f} µm; drift {setup['drift_um_per_s']:+.4g} µm/s")
    if not comparison["bidirectional"]:
        lines.append("(one direction: G per direction and H need both)")
    return "\n".join(lines)
