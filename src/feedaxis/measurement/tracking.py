"""Servo tracking deviations over time (tracking.csv with the ``[servo]`` table of axis.toml).

The tracking effects (:mod:`feedaxis.effects.tracking`) act inside the closed loop: they set
the parameters of one simulation (:func:`feedaxis.physics.servo.simulate`, the NpidServo
FMU's physics) with the controller of ``[servo]``, the plant of Anang et al. 2017 Eq. 1 where the
model has no ``servo_plant``. The model predicts ``actual_mm`` from ``reference_mm`` (and
``disturbance_N``); the deviation is actual - reference in µm. The residual is serially
correlated, so the tests use the effective sample count n/τ and the uncertainties are
widened by τ. Structure is searched in time: a periodic force over the record or part of
it, a steady force, error locked to the velocity reversals; a slow drift is a nuisance of
every diagnosis, single-sample spikes are left out as outliers. ``compare`` gives the maximum and
RMS tracking error after the first second, as Anang et al. 2017 report them.

A record need not start at rest: the loop is simulated from rest on the first reference
sample over the whole record, but its samples in the first ``START_WINDOW_S`` (the start-up)
are left out of every fit, diagnosis and comparison, so a start mid-motion, whose transient
has died out by then, does not bend the plant.
"""
from __future__ import annotations

import weakref
from collections import OrderedDict
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np
import scipy

from .. import kinds
from ..case import (AXIS_FILE, DEFAULT_LOOP_STEP_S, CaseError, _first_bad, _read_csv)
from ..fmu_map import servo_to_fmu
from ..physics.identify import identify_plant, loop_start
from ..physics.motor import motor_error_period_mm
from ..physics.servo import (MAX_POSITION_MM, PLANT_BOUNDS, ServoParams, check_runs,
                             loop_budget_problem, simulate, simulate_record, step_counts)
from ..physics.servo_sensitivity import PARAMETERS as SENSITIVE, simulate_sensitivity
from ..plausibility import tracking_problems, warn_implausible
from ..stats.coloured import (MAX_AR_ORDER, autocorrelation_time, autoregression,
                              locate_sinusoid, noise_floor_um, peak_p_value, short_time_peak,
                              spikes)
from ..stats.distributions import chi2_isf, f_sf
from ..stats.judge import FAMILY_ALPHA, OUTLIER_ALPHA, Test, accepts, drift_basis
from ..stats.noise import Coloured
from .base import Measurement, NoStart, Shape, Trial

SETTLING_S = 1.0  # Anang et al. 2017 measures the tracking error after the first second
# The start-up left out of every comparison. A record that starts mid-motion differs from the
# loop simulated from rest by the free response of the loop's state at the first sample; for
# the loops of Anang et al. 2017 and the tests (closed-loop poles near 250 rad/s) it falls within
# 0.1 s to 5e-6 of its peak (what is left is the integrator's slow mode), so a 100 µm
# start-up error leaves under 1 nm after 0.2 s. Profiling the state instead (fitting it as
# nuisance parameters) was tried: on a single-sine reference the fit then moved the plant to
# a lightly damped one whose free ringing imitated a persistent 62.5 Hz force.
START_WINDOW_S = 0.2
REVERSAL_WINDOW_S = 0.2  # after a reversal or near-stop of the reference: where a spike of
# friction at rest is looked for (the axis reverses later, by the loop's lag)
REVERSAL_LEAD_S = 0.05  # and before it: the speed falls into the friction's rise at rest first
REVERSAL_SHARE = 0.8  # of force steps near the reversals: the spikes there, not steps of a load
NEAR_STOP_SHARE = 0.02  # of the largest reference speed: a near-stop, where friction at rest
# acts as at a reversal
UNIFORM_SAMPLING_TOLERANCE = 0.01
HELD_SHARE = 0.01  # of a force's first response left after the start-up: the loop holds it
WHOLE_RECORD_SHARE = 0.75  # of the periodic test's level: the record's periodogram, the rest
# the short-time periodogram's
ROUNDING_UM = 1e-3  # the diagnosis's resolution (diagnose.RESOLUTION_UM): below it, rounding
TRACKING_FILE = "tracking.csv"
# the loop's results kept per record (:class:`Recent`): a 500 s trace at 1 ms holds 4 MB of
# positions, 16 MB of a plant's sensitivities
RECENT_BYTES = 2**27

# Peak memory of the heaviest tracking command per row of tracking.csv (the case reader's
# refusal, feedaxis.case.check_fits_in_memory; benchmarks/bench_tracking_scale.py): on 10^7
# samples fit and report peaked at 5,857 MB resident, 571 bytes a sample above the
# interpreter's own 150 MB (the fit's trust region: feedaxis.fit); on 10^6, where freed
# blocks stay in the heap, report at 970 MB, 820 bytes. The figure kept covers both, with
# 75 % over the 10^7 figure, where a case meets the machine's memory.
ANALYSIS_BYTES_PER_ROW = 1000

TRACKING_COLUMNS = {"time_s": True, "reference_mm": True, "actual_mm": True,
                    "disturbance_N": False, "control_V": False}


@dataclass(frozen=True)
class TrackingSamples:
    """tracking.csv as arrays."""

    time_s: np.ndarray
    reference_mm: np.ndarray
    actual_mm: np.ndarray
    disturbance_N: np.ndarray | None = None
    control_V: np.ndarray | None = None


def read_tracking(path, loop_step_s=DEFAULT_LOOP_STEP_S):
    """Read tracking.csv: strictly increasing time, reference and actual position.

    The control loop steps ``loop_step_s`` through every interval, so samples too far apart
    for it (:func:`feedaxis.physics.servo.loop_budget_problem`) are refused at the row.
    """
    path = Path(path)
    values, rows = _read_csv(path, TRACKING_COLUMNS, ANALYSIS_BYTES_PER_ROW)
    time_s = values["time_s"]
    _first_bad(path, np.concatenate(([False], np.diff(time_s) <= 0)), rows, "time_s",
               "time_s must be strictly increasing")
    problem = loop_budget_problem(time_s, loop_step_s)
    if problem is not None:
        raise CaseError(path, problem[1], rows[problem[0]], "time_s")
    return TrackingSamples(time_s, values["reference_mm"], values["actual_mm"],
                           values.get("disturbance_N"), values.get("control_V"))


PLANT_KEYS = ("plant_gain_mm_per_Vs2", "plant_damping_per_s", "plant_stiffness_per_s2",
              "delay_s")


def servo_params(axis, model, values=None, plant=None):
    """The loop's :class:`ServoParams`: the controller of ``[servo]`` on ``plant`` (default
    the paper's, Anang et al. 2017 Eq. 1), then the model's tracking effects with ``values``
    (default the model's own)."""
    values = model.values if values is None else values
    merged = {**servo_to_fmu(axis.servo), **(plant or {})}
    for effect in model.effects:
        if effect.measurement == "tracking":
            merged.update({**effect.neutral, **values[effect.name]})
    return ServoParams(**merged)


class Start:
    """Where the loop of a tracking case starts: the plant a model without ``servo_plant``
    runs, and how it was found (``source``), or why none was (``problem``).

    - With ``control_V`` recorded: the inverse-dynamics least squares of the plant on its own
      input (:func:`feedaxis.physics.identify.identify_plant`), which also estimates the
      Coulomb friction and a constant force (``identified``: the starts of those effects).
    - Otherwise the paper's plant (Anang et al. 2017, Eq. 1) where it makes a stable loop
      with a PID or NPID that follows the record, and for a cascade, or where it does not,
      the plant a closed-loop search over the gain finds from the record
      (:func:`feedaxis.physics.identify.loop_start`).

    A start found from the record is then refined by the closed-loop fit of the plant
    (``servo_plant`` alone), so a model without ``servo_plant`` runs the plant the record
    shows, and an effect named on top is judged against it.
    """

    def __init__(self, plant, source, identified=None, problem=None, refine=True,
                 positions_mm=None):
        self.plant, self.source, self.identified, self.problem = (plant, source, identified,
                                                                  problem)
        self.refine = refine
        # the loop's positions (mm) over the record under this start's plant with the
        # record's own force, where finding the start simulated them (the paper's plant)
        self.positions_mm = positions_mm
        self.basin = plant  # where a fit of servo_plant starts (:func:`_refined`)
        # the Coulomb friction (N) fitted beside the basin's plant: where a friction law
        # starts (None where the start was not refined)
        self.friction_N = None


_STARTS = {}  # id(tracking record) -> (weak reference to it, Start)


def loop_start_of(case):
    """The :class:`Start` of ``case``'s tracking record, found once per record."""
    trace = case.tracking
    entry = _STARTS.get(id(trace))
    if entry is not None and entry[0]() is trace:
        return entry[1]
    for key in [key for key, (ref, _) in _STARTS.items() if ref() is None]:
        del _STARTS[key]
    start = _find_start(case)
    _STARTS[id(trace)] = (weakref.ref(trace), start)
    if start.plant and start.refine:
        start.basin, start.friction_N, start.plant = _refined(case, start.plant)
    return start


def _refined(case, plant):
    """(basin, friction_N, plant): ``plant`` after two closed-loop least-squares fits of the
    plant, the first with a Coulomb friction beside it as a nuisance (friction at the
    reversals would otherwise draw the search's plant into another optimum: the basin,
    where a fit of the plant with the effects starts, and friction_N, where a friction
    law's level starts), the second alone from there: the model without effects is the
    plant alone that fits the record best, so an effect is judged on top of it as on any
    model (a plant tuned beside a friction makes the plant alone, or that friction, look
    significant on a null). Bounded least squares on the samples compared (scipy's
    trust-region reflective, as the fit's)."""
    measurement = Tracking(case)
    beside = _fitted_plant(measurement, plant, ("friction_N",))
    basin = {key: beside[key] for key in PLANT_KEYS}
    return basin, beside["friction_N"], _fitted_plant(measurement, basin, ())


def _fitted_plant(measurement, plant, nuisances):
    """The plant (``PLANT_KEYS``) that fits ``measurement`` best from ``plant``, and the
    loop parameters ``nuisances`` (from 0, at least 0) fitted beside it."""
    from scipy.optimize import least_squares

    keys = (*PLANT_KEYS, *nuisances)
    lower = np.array([PLANT_BOUNDS[k][0] if k in PLANT_BOUNDS else 0.0 for k in keys])
    upper = np.array([PLANT_BOUNDS[k][1] if k in PLANT_BOUNDS else np.inf for k in keys])
    start = np.clip([plant[k] if k in plant else 0.0 for k in keys], lower, upper)
    base = {**servo_to_fmu(measurement.case.axis.servo)}

    def residual(x):
        params = ServoParams(**{**base, **dict(zip(keys, x))})
        return measurement.measured_um - measurement.deviation_um(params)

    def jacobian(x):
        params = ServoParams(**{**base, **dict(zip(keys, x))})
        return -measurement.deviation_sensitivity(params, keys)[1]

    with np.errstate(over="ignore", invalid="ignore"):
        solution = least_squares(residual, start, bounds=(lower, upper), x_scale="jac",
                                 jac=jacobian if measurement.sensitivities else "2-point",
                                 method="trf")
    return {k: float(v) for k, v in zip(keys, solution.x)}


def _runs(params, trace, counts):
    """The loop's positions (mm) over the record under ``params`` where they make a loop
    that stays on any axis, else None."""
    with np.errstate(all="ignore"):
        position_mm = simulate(params, trace.time_s, trace.reference_mm, trace.disturbance_N,
                               counts)
    return position_mm if np.all(np.abs(position_mm) <= MAX_POSITION_MM) else None


def _find_start(case):
    servo = case.axis.servo
    trace = case.tracking
    base = ServoParams(**servo_to_fmu(servo))
    counts = step_counts(trace.time_s, servo["loop_step_s"])
    if trace.control_V is not None:
        identified = identify_plant(trace.time_s, trace.actual_mm, trace.control_V,
                                    servo["force_constant_N_per_V"], trace.disturbance_N)
        if identified is not None:
            plant = {key: float(np.clip(identified.values[key], *PLANT_BOUNDS[key]))
                     for key in PLANT_KEYS}
            if _runs(replace(base, **plant), trace, counts) is not None:
                return Start(plant, "identified from the recorded controller output "
                                    "(inverse dynamics)", identified)
    position_mm = _runs(base, trace, counts) if base.controller != "cascade" else None
    if position_mm is not None:
        return Start({}, "the plant of Anang et al. 2017, Eq. 1", refine=False,
                     positions_mm=position_mm)
    plant = loop_start(base, trace.time_s, trace.reference_mm, trace.actual_mm,
                       trace.disturbance_N, START_WINDOW_S)
    if plant is None:
        return Start(None, "", problem=(
            f"no plant gain from {PLANT_BOUNDS['plant_gain_mm_per_Vs2'][0]:g} to "
            f"{PLANT_BOUNDS['plant_gain_mm_per_Vs2'][1]:g} mm/(V.s2) makes a stable loop with "
            f"the controller of [servo] ({servo['controller']}): check its gains and units, "
            "or record the controller output (control_V) so the plant can be identified "
            "from its own input"))
    return Start(plant, "found from the record by a closed-loop search over the plant gain")


def tracking_comparison_lines(comparison):
    """Anang et al.'s (2017) figures after the first second: measured, predicted; then the residual."""
    maximum, rms = comparison["max_tracking_error_mm"], comparison["rms_tracking_error_mm"]
    return "\n".join([
        f"{comparison['samples']} samples after the first {comparison['after_s']:g} s; model: "
        f"{', '.join(comparison['effects']) or '(no effect: the starting plant)'}",
        f"{'tracking error (mm)':24s} {'measured':>10s} {'predicted':>10s}",
        f"{'max':24s} {maximum['measured']:10.5f} {maximum['predicted']:10.5f}",
        f"{'RMS':24s} {rms['measured']:10.5f} {rms['predicted']:10.5f}",
        f"residual actual - predicted: max {comparison['residual_max_um']:.4g} µm, RMS "
        f"{comparison['residual_rms_um']:.4g} µm"])


@kinds.register
class Tracking(Measurement):
    """The tracking record of a case, ready for repeated simulation.

    The loop is simulated over the whole record; the samples compared (``index`` into the
    record) are those after the start-up window, less any outliers left out.
    """

    kind = "tracking"
    file = TRACKING_FILE
    capabilities = ("outliers", "nuisances", "shapes", "core", "correlated", "resolution")
    refits_selection = True
    measured_column = ("actual_mm", 1e-3)
    details = "feedaxis.tracking_details:tracking_details"
    views = "feedaxis.report.tracking:VIEWS"
    scenarios = "feedaxis.cosim.scenarios.tracking:SCENARIOS"
    text = staticmethod(tracking_comparison_lines)
    location_key = "frequency_hz"
    location_unit = "Hz"
    coordinate_label = "time (s)"
    reference_label = "the starting plant"
    stages = ("drift", "effects", "structures")
    loose_share = 0.5

    def __init__(self, case, index=None):
        super().__init__(case)
        if not case.axis.servo:
            raise CaseError(Path(case.folder or ".") / AXIS_FILE, "a tracking case needs the "
                            "[servo] table (the controller as set in the drive)", column="servo")
        trace = self.samples_of(case)
        self.record_time_s, self.record_reference_mm = trace.time_s, trace.reference_mm
        self.disturbance_N = trace.disturbance_N
        self.counts = step_counts(trace.time_s, case.axis.servo["loop_step_s"])
        self.index = (np.arange(_first_settled(trace.time_s), trace.time_s.size)
                      if index is None else np.asarray(index, dtype=int))
        self.compared = _selector(self.index)
        self.time_s = self.coordinate = trace.time_s[self.index]
        self.reference_mm = trace.reference_mm[self.index]
        self.measured_um = (trace.actual_mm - trace.reference_mm)[self.index] * 1e3
        self.start = loop_start_of(case)
        self._reference_kind = self._stops_s = None
        self.recent = Recent()

    start_of = staticmethod(loop_start_of)  # the start the tracking effects guess from

    def neutral(self, effect):
        """``effect``'s values that switch it off: for ``servo_plant`` the starting plant."""
        if effect.name == "servo_plant" and self.start.plant:
            return {**effect.neutral, **self.start.plant}
        return super().neutral(effect)

    @classmethod
    def read(cls, folder, axis, duty):
        path = Path(folder) / cls.file
        if not path.exists():
            return None
        samples = read_tracking(path, axis.servo.get("loop_step_s", DEFAULT_LOOP_STEP_S))
        warn_implausible(tracking_problems(samples.reference_mm))
        return samples

    @property
    def noise(self):
        return Coloured()

    @property
    def start_s(self):
        """Time (s) from the record's first sample to the first sample compared."""
        return float(self.record_time_s[self.index[0]] - self.record_time_s[0])

    def describe(self):
        start = f" after the first {self.start_s:.3g} s" if self.start_s > 0 else ""
        return (f"{self.size} samples over {np.ptp(self.time_s):.4g} s{start}, "
                f"{self.case.axis.servo['controller'].upper()} controller")

    def rows(self, indices):
        return [int(self.index[i]) + 2 for i in indices]

    def outliers(self, residual_um):
        """Single-sample spikes in time (:func:`feedaxis.stats.coloured.spikes`, at the
        outlier level of every diagnosis); a departure of 1 nm or less is rounding (the
        diagnosis's resolution)."""
        return spikes(residual_um, OUTLIER_ALPHA, floor=ROUNDING_UM)

    def subset(self, keep):
        subset = Tracking(self.case, self.index[keep])
        subset.recent = self.recent  # the same record: the same loop
        return subset

    def unresolvable(self, effect):
        """A constant force the controller's integral action holds (``held_force``), where
        no controller output is recorded: the position trace cannot show it."""
        if effect.name == "constant_force" and self.case.tracking.control_V is None:
            return self.held_force()
        return None

    def held_force(self):
        """Why a constant force is hidden from the position trace, or None: the starting
        loop's response to 1 N acting from the first sample, over the samples compared, under
        ``HELD_SHARE`` of its largest over the whole record (the integral action has taken
        it over within the start-up), so only the recorded controller output shows it."""
        if not self.start.plant and self.start.problem:
            return None
        params = ServoParams(**{**servo_to_fmu(self.case.axis.servo), **self.start.plant})
        ones = np.ones(self.record_time_s.size)
        known = np.zeros_like(ones) if self.disturbance_N is None else self.disturbance_N
        with np.errstate(all="ignore"):
            unmoved_mm = (self.start.positions_mm if self.start.positions_mm is not None else
                          simulate(params, self.record_time_s, self.record_reference_mm, known,
                                   self.counts))
            moved_um = (simulate(params, self.record_time_s, self.record_reference_mm,
                                 known + ones, self.counts) - unmoved_mm) * 1e3
        largest = float(np.max(np.abs(moved_um)))
        lasting = float(np.max(np.abs(moved_um[self.index])))
        if not np.isfinite(largest) or largest == 0.0 or lasting >= HELD_SHARE * largest:
            return None
        return (f"undetermined: the controller's integral action holds a constant force, "
                f"leaving {lasting / largest:.1%} of its first response in the position "
                f"trace after the first {self.start_s:.3g} s; record the controller output "
                "(control_V) to see it")

    def recorded_findings(self, left, pending, stages):
        """A constant force the tracking error cannot show (an integral action holds it) but
        the recorded controller output does: the output the fitted loop predicts is
        subtracted from ``control_V``, and what is left regressed on the predicted output's
        change under 1 N (the integral holds −1/K_F); F test with the effective sample count
        n/τ of what is left, at the policy's level. The force's standard uncertainty is
        that of the regression widened by √τ."""
        trace = self.case.tracking
        effect = pending.get("constant_force")
        if trace.control_V is None or effect is None:
            return []
        params = self.params(left.model)
        known = trace.disturbance_N
        ones = np.ones(trace.time_s.size)
        outputs = [simulate_record(params, trace.time_s, trace.reference_mm, force,
                                   self.counts)[1][self.index]
                   for force in (known, ones if known is None else known + ones)]
        left_V = trace.control_V[self.index] - outputs[0]
        column = outputs[1] - outputs[0]
        energy = float(column @ column)
        if energy <= 0.0:
            return []
        force_N = float(column @ left_V) / energy
        after_V = left_V - force_N * column
        test = self.noise.extra_ss_test(left_V, after_V, 1, left.statistics.n_free + 1)
        if not accepts(test.p_value, 1, stages):
            return []
        variance = float(after_V @ after_V) / max(after_V.size - 1, 1)
        sigma_N = float(np.sqrt(autocorrelation_time(after_V) * variance / energy))
        test = Test(test.statistic, test.dof, test.p_value,
                    f"{test.name}, on the recorded controller output", test.symbol)
        evidence = (f"a constant force of {force_N:+.3g} N on the axis, held by the "
                    f"controller's integral action: the recorded output carries "
                    f"{-force_N / params.force_constant_N_per_V:+.3g} V for it, the tracking "
                    "error nothing lasting")
        return [(effect, {"force_N": force_N}, {"force_N": sigma_N}, test, evidence)]

    def offset_unknown(self, current):
        """Why a steady offset of the deviation in the fit ``current`` cannot be told from a
        constant force, or None. A measured position that drifts (the drift nuisance
        significant in ``current``, its own test at the policy's level) is not the loop's
        own feedback (the loop would hold that at the reference), so its offset at the
        first sample, the drift since the axis was referenced, is unknown; a constant force
        gives the same steady deviation. The recorded controller output tells them apart:
        it holds the force, not the measurement's offset."""
        if self.refitter is None or "drift" not in current.model:
            return None
        test = self.refitter.nuisance_test(current, "drift", TimeDrift.extra)
        if not accepts(test.p_value, 1, len(self.stages)):
            return None
        remedy = ("the recorded controller output (control_V) does not show one" if
                  self.case.tracking.control_V is not None else
                  "record the controller output (control_V) to tell them apart")
        return ("undetermined: the measured position drifts, so it is not the loop's own "
                "feedback and its offset at the first sample (the drift since the axis was "
                "referenced) is unknown; a constant force gives the same steady deviation, "
                f"and {remedy} ({test.describe()})")

    def withdrawn(self, final):
        """{name: (why, columns in its place)} of a constant force named where the final
        fit's measured position drifts (:meth:`offset_unknown`), judged on the final fit
        (where the other effects named no longer hide the drift's test behind their
        misfit): a constant column, the measurement's unknown offset, takes its place, and
        a recorded controller output may still show the force
        (:meth:`recorded_findings`)."""
        reason = "constant_force" in final.model and self.offset_unknown(final)
        return {"constant_force": (reason, np.ones((self.size, 1)))} if reason else {}

    def rival(self, effect, left, result):
        """Why a friction law is not what the data show, each judged with the plant
        refitted (the start's plant was fitted beside a friction, so a friction tested on
        top of it alone would look more significant than it is): not significant against
        the plant alone (F test at the policy's level over the tracking effects), or the
        other law describes the reversals better (F test on the two parameters of the
        Stribeck rise): ``stribeck_friction`` when its rise at rest is not significant
        against Coulomb friction alone, ``coulomb_friction`` when it is. Only one of them
        is named, the one the data show."""
        laws = ("coulomb_friction", "stribeck_friction")
        if (effect.name not in laws or any(name in left.model for name in laws)
                or self.refitter is None
                or not all(name in self.refitter.catalog for name in (*laws, "servo_plant"))):
            return None
        plant = () if "servo_plant" in left.model else ("servo_plant",)
        plain = self.refitter(left.model, plant)
        coulomb, stribeck = (self.refitter(left.model, (*plant, law)) for law in laws)
        refitted = coulomb if effect.name == laws[0] else stribeck
        test = self.noise.extra_ss_test(plain.residual_um, refitted.residual_um,
                                        len(effect.parameters), refitted.statistics.n_free)
        tried = sum(e.measurement == self.kind for e in self.refitter.catalog.values())
        if not accepts(test.p_value, tried, len(self.stages)):
            return ("with the plant refitted beside it, it is not significant "
                    f"({test.describe()})")
        test = self.noise.extra_ss_test(coulomb.residual_um, stribeck.residual_um, 2,
                                        stribeck.statistics.n_free)
        rises = accepts(test.p_value, 1, len(self.stages))
        if effect.name == laws[0] and rises:
            return ("the friction rises at rest above its Coulomb level: Stribeck friction "
                    f"describes the reversals better ({test.describe()})")
        if effect.name == laws[1] and not rises:
            return ("its rise at rest above the Coulomb level is not significant against "
                    f"Coulomb friction alone ({test.describe()})")
        return None

    def params(self, model, values=None):
        return servo_params(self.case.axis, model, values, self.start.plant)

    def deviation_um(self, params, disturbance_N=None):
        """Predicted deviation position - reference (µm) at the samples under ``params``,
        with ``disturbance_N`` (over the whole record; default the record's own) acting on
        the axis; the loop is simulated from rest at the record's first sample."""
        position_mm = (self.positions_mm(params) if disturbance_N is None else
                       simulate(params, self.record_time_s, self.record_reference_mm,
                                disturbance_N, self.counts))
        with np.errstate(over="ignore", invalid="ignore"):  # a fit's trial loop may run away
            return (position_mm[self.compared] - self.record_reference_mm[self.compared]) * 1e3

    def positions_mm(self, params):
        """The loop's positions (mm) over the record under ``params`` with the record's own
        force, kept for the next calls (:class:`Recent`): a fit asks again where it stands,
        a diagnosis where the model it tests on top stands."""
        key = ("positions", params)
        kept = self.recent.get(key)
        if kept is None:
            kept = self.recent.put(key, simulate(params, self.record_time_s,
                                                 self.record_reference_mm, self.disturbance_N,
                                                 self.counts))
        return kept

    def check_start(self, model, values):
        """The closed loop must not run away with ``values``
        (:class:`~feedaxis.physics.servo.LoopRunsAway`); a fit's trial values may, the
        optimiser steps back from them. A model without ``servo_plant`` on a record no
        plant could be started from raises :class:`~feedaxis.measurement.base.NoStart`."""
        if self.start.problem and "servo_plant" not in model:
            raise NoStart(self.start.problem)
        params = self.params(model, values)
        check_runs(params, self.positions_mm(params))

    def core(self, model):
        return lambda values: self.deviation_um(self.params(model, values))

    def sensitivity(self, model):
        """The deviation and its derivatives in the loop's parameters from one forward-mode
        pass of the loop (:func:`feedaxis.physics.servo_sensitivity.simulate_sensitivity`);
        the slots' parameter names are the loop's (:func:`servo_params`). None where an
        effect sets a loop parameter the sensitivities do not differentiate (a user's effect
        on the loop step, say): the fit then differences."""
        names = {p.name for e in model.effects if not e.additive for p in e.parameters}
        if not self.sensitivities or not names <= set(SENSITIVE):
            return None
        return lambda values, slots: self.deviation_sensitivity(
            self.params(model, values), [parameter for _, parameter in slots])

    def deviation_sensitivity(self, params, names):
        """(:meth:`deviation_um` under ``params``, its derivatives in ``names``: samples x
        len(names), µm per unit), kept for the next calls as :meth:`positions_mm` (the
        positions too: the pass's are the loop's to the bit); columns kept from a pass in
        more names at the same parameters are taken from it (a column is the same beside
        other names: to the bit, within 1e-12 of its largest value where they change the
        pass's kernel: tests/physics/test_sensitivity.py)."""
        key = ("sensitivity", params, tuple(names))
        d_position_mm = self.recent.get(key)
        if d_position_mm is None:
            d_position_mm = self.recent.columns(params, names)
        if d_position_mm is None:
            position_mm, d_position_mm = simulate_sensitivity(
                params, names, self.record_time_s, self.record_reference_mm,
                self.disturbance_N, self.counts)
            d_position_mm = self.recent.put(key, d_position_mm)
            position_mm = self.recent.put(("positions", params), position_mm)
        else:
            position_mm = self.positions_mm(params)
        compared = d_position_mm[self.compared]
        with np.errstate(over="ignore", invalid="ignore"):  # a fit's trial loop may run away
            return ((position_mm[self.compared] - self.record_reference_mm[self.compared])
                    * 1e3, _scaled(compared, 1e3))

    def loop_response_um(self, model, disturbance_N):
        """Change of the predicted deviation (µm) at the samples when ``disturbance_N``
        (over the whole record) is added to the record's own force. A steady force on a
        model without one is the model's constant force: the same forces to the bit, so the
        loop is the one kept where a constant force's screen ran it (:meth:`positions_mm`)."""
        known = self.disturbance_N if self.disturbance_N is not None else 0.0
        params = self.params(model)
        disturbance_N = np.asarray(disturbance_N, dtype=float)
        if params.force_N == 0.0 and disturbance_N.size and np.all(
                disturbance_N == disturbance_N[0]):
            moved_um = self.deviation_um(replace(params, force_N=float(disturbance_N[0])))
        else:
            moved_um = self.deviation_um(params, known + disturbance_N)
        return moved_um - self.deviation_um(params)

    def impulse_response_um(self, model):
        """The deviation (µm) over the record after a 1 N force held over one sample
        interval (the record's second), from that sample on: the loop's response to any
        force is its convolution with this (exactly for a linear loop: PID without Coulomb
        friction)."""
        params = self.params(model)
        known = np.zeros(self.record_time_s.size) if self.disturbance_N is None else \
            self.disturbance_N
        kicked = known.copy()
        kicked[1] += 1.0
        record_um = [(position_mm - self.record_reference_mm) * 1e3 for position_mm in (
            self.positions_mm(params),  # the record's own force: kept where the fit ran it
            simulate(params, self.record_time_s, self.record_reference_mm, kicked,
                     self.counts))]
        return (record_um[1] - record_um[0])[1:]

    def fit_window(self, model, residual_um, frequency_hz, first, last):
        """(first, last) record samples of the window over which a force at
        ``frequency_hz``, through the loop, best fits ``residual_um`` (at the samples
        compared): each edge searched to the sample within the loop's settling (the impulse
        response above 1 % of its peak) plus the whitening filter's length of its estimate,
        alternately twice. Moving an edge by a sample adds or removes one shifted impulse
        response, so each edge's search costs one convolution."""
        impulse_um = self.impulse_response_um(model)
        size = impulse_um.size + 1
        settling = int(np.flatnonzero(np.abs(impulse_um) >= 0.01 * np.max(np.abs(impulse_um)))
                       [-1]) + MAX_AR_ORDER + 1
        phase = 2.0 * np.pi * frequency_hz * self.record_time_s
        forces = np.column_stack((np.cos(phase), np.sin(phase)))
        lowest, highest = int(self.index[0]), int(self.index[-1])

        def response(a, b):
            gated = np.zeros_like(forces)
            gated[a:b + 1] = forces[a:b + 1]
            return np.column_stack([scipy.signal.fftconvolve(column, impulse_um)[:size]
                                    for column in gated.T])

        def kick(sample):
            shifted = np.zeros((size, 2))
            shifted[sample:] = np.outer(impulse_um[:size - sample], forces[sample])
            return shifted

        def misfit(columns):
            return _rss(residual_um - _regress(residual_um, columns[self.index])[1])

        def best_edge(fixed, edges, start):
            """The best of ``edges`` (moving away from the first, each adding a sample)."""
            columns = response(edges[0], fixed) if start else response(fixed, edges[0])
            best = (misfit(columns), edges[0])
            for edge in edges[1:]:
                columns = columns + kick(edge)
                best = min(best, (misfit(columns), edge))
            return best[1]

        for _ in range(2):
            first = best_edge(last, list(range(min(first + settling, last),
                                               max(first - settling, lowest) - 1, -1)), True)
            last = best_edge(first, list(range(max(last - settling, first),
                                               min(last + settling, highest) + 1)), False)
        return first, last

    def noise_gram(self, jacobian, residual_um, variance):
        """τ · variance · J'J, τ the residual's integrated autocorrelation time: n/τ samples
        are independent."""
        return autocorrelation_time(residual_um) * variance * (jacobian.T @ jacobian)

    def confounded(self, model, slots, jacobian, residual_um, sigma):
        """The parameters a measurement delay would move unseen: actual_mm recorded late by
        δ reads x(t - δ) ≈ x(t) - ẋ·δ, so the residual moves by -ẋ·δ (ẋ the predicted
        velocity). Its least-squares projection on the Jacobian's columns is what the
        parameters absorb (β per second of delay); the rest ``u`` is what the residual would
        show, so a delay estimated on top of the fit has the standard error σ·√τ / ‖u‖.
        Reported: when a delay of one sample interval lies within 3 standard errors (the
        record cannot see it), each parameter it moves by more than its standard
        uncertainty."""
        step_s = float(np.median(np.diff(self.time_s)))
        position_mm = self.reference_mm + (self.measured_um - residual_um) * 1e-3
        velocity_um_s = np.gradient(position_mm, self.time_s) * 1e3
        absorbed, *_ = np.linalg.lstsq(jacobian, velocity_um_s, rcond=None)
        left_um_s = float(np.linalg.norm(velocity_um_s - jacobian @ absorbed))
        dof = max(residual_um.size - len(slots), 1)
        noise_um = float(np.sqrt(residual_um @ residual_um / dof
                                 * autocorrelation_time(residual_um)))
        unseen_s = 3.0 * noise_um / max(left_um_s, 1e-300)
        if unseen_s <= step_s:
            return {}
        units = {(e.name, p.name): p.unit for e in model.effects for p in e.parameters}
        moved = {slot: shift * step_s for slot, shift in zip(slots, absorbed)
                 if abs(shift * step_s) > sigma[slot[0]][slot[1]]}
        keys = [f"{effect}.{parameter}" for effect, parameter in moved]
        return {key: (
            f"the reference cannot separate it from a measurement delay (actual_mm recorded "
            f"late, outside the loop): the residual would not show a delay under "
            f"{1e3 * unseen_s:.3g} ms (3 standard errors), and each {1e3 * step_s:.3g} ms of it "
            f"moves this parameter by {shift:+.3g} {units[slot]} "
            f"({abs(shift) / sigma[slot[0]][slot[1]]:.0f} standard uncertainties)"
            + (f", {', '.join(k for k in keys if k != key)} with it" if len(keys) > 1 else ""))
            for key, (slot, shift) in zip(keys, moved.items())}

    def nuisances(self):
        """A slow drift in time (:class:`TimeDrift`), fitted with every model so it never
        passes for an effect or a force."""
        drift = TimeDrift()
        return [("drift", drift, drift.trial(self, None).basis)]

    def shapes(self, effects):
        return (ForceSteps(), PeriodicForce(), ConstantForce(), Reversal())

    def step_response_um(self, model):
        """The deviation (µm) over the record after a 1 N force step at the record's second
        sample, from that sample on: the running sum of :meth:`impulse_response_um` (exact
        for a linear loop, a linearisation with Coulomb or Stribeck friction)."""
        return np.cumsum(self.impulse_response_um(model))

    def settled(self):
        """Mask of the samples after the record's first second (all when none is)."""
        settled = self.time_s >= self.record_time_s[0] + SETTLING_S
        return settled if settled.any() else np.ones_like(settled)

    def figures(self, result):
        """Max and RMS tracking error (actual − reference, mm: the sign of every deviation)
        measured and predicted, and the residual (actual − predicted, µm), over the samples
        after the first second."""
        settled = self.settled()
        measured_mm = result.measured_um[settled] * 1e-3
        predicted_mm = (result.measured_um - result.residual_um)[settled] * 1e-3
        residual_um = result.residual_um[settled]
        return {"case": str(self.case.folder), "kind": self.kind,
                "effects": list(result.model.names), "samples": int(settled.sum()),
                "after_s": SETTLING_S,
                "max_tracking_error_mm": {"measured": float(np.max(np.abs(measured_mm))),
                                          "predicted": float(np.max(np.abs(predicted_mm)))},
                "rms_tracking_error_mm": {"measured": _rms(measured_mm),
                                          "predicted": _rms(predicted_mm)},
                "residual_max_um": float(np.max(np.abs(residual_um))),
                "residual_rms_um": _rms(residual_um)}

    def reversals_s(self):
        """Times (s) at which the reference velocity changes sign."""
        velocity = np.gradient(self.reference_mm, self.time_s)
        return self.time_s[1:][np.diff(np.sign(velocity)) != 0]

    def stops_s(self):
        """Times (s) at which the reference velocity changes sign or falls to a near-stop (a
        local minimum of its magnitude under ``NEAR_STOP_SHARE`` of its largest, more than
        two samples from a reversal): where friction at rest acts. Found once (read-only):
        the reversal shape and its spikes' test ask for them."""
        if self._stops_s is None:
            self._stops_s = self._found_stops_s()
            self._stops_s.setflags(write=False)
        return self._stops_s

    def _found_stops_s(self):
        velocity = np.abs(np.gradient(self.reference_mm, self.time_s))
        inner = np.flatnonzero((velocity[1:-1] <= velocity[:-2])
                               & (velocity[1:-1] < velocity[2:])) + 1
        slow = self.time_s[inner[velocity[inner] < NEAR_STOP_SHARE * np.max(velocity)]]
        reversals = self.reversals_s()
        step_s = float(np.median(np.diff(self.time_s))) if self.time_s.size > 1 else 0.0
        if reversals.size:
            slow = slow[_nearest_gap(slow, reversals) > 2.0 * step_s]
        return np.sort(np.concatenate((reversals, slow)))

    def near_stop(self, time_s):
        """Mask of the times (s) from ``REVERSAL_LEAD_S`` before to ``REVERSAL_WINDOW_S``
        after a reversal or near-stop of the reference (:meth:`stops_s`)."""
        stops = self.stops_s()
        near = np.zeros(np.shape(time_s), dtype=bool)
        if not stops.size:
            return near
        # the stops are sorted, so a time's window holds a stop if and only if it holds the
        # first stop at or after time - REVERSAL_WINDOW_S (or, at a rounding boundary, one
        # beside it): three candidates per time, not a times x stops matrix
        first = np.searchsorted(stops, time_s - REVERSAL_WINDOW_S)
        for offset in (-1, 0, 1):
            index = np.clip(first + offset, 0, stops.size - 1)
            since = time_s - stops[index]
            near |= (since >= -REVERSAL_LEAD_S) & (since <= REVERSAL_WINDOW_S)
        return near

    def reference_kind(self):
        """What the reference is, in words (:func:`_reference_kind`), found once: every fit
        of the samples asks for it."""
        if self._reference_kind is None:
            self._reference_kind = _reference_kind(self.time_s, self.reference_mm)
        return self._reference_kind

    def excitation(self):
        """What the reference is, and why it leaves a parameter loose: a single sine (its
        loop's gain and phase at one frequency), a point-to-point trajectory (moves between
        rests: a dwell where the speed stays under ``NEAR_STOP_SHARE`` of its largest over a
        tenth of the record), or a record with reversals."""
        what = self.reference_kind()
        if what.startswith("a single sine"):
            return f"the reference is {what}, which fixes only the loop's gain and phase there"
        return f"the reference ({what}) does not excite it enough"

    def uniform_step_s(self):
        """The sampling step (s) when the record is evenly sampled over the samples compared
        (outliers left out are gaps of it), else None."""
        steps = np.diff(self.record_time_s[self.index[0]:self.index[-1] + 1])
        if steps.size == 0:
            return None
        step = float(np.median(steps))
        return step if np.max(np.abs(steps - step)) <= UNIFORM_SAMPLING_TOLERANCE * step \
            else None

    def gridded(self, values):
        """(time_s, values) on the record's samples from the first to the last compared,
        ``values`` (one per sample compared) interpolated linearly over the outliers left
        out: what the spectral tests take. With none left out the values are on the grid
        already, and np.interp would return them to the bit (at a knot it takes the knot's
        value): copies of the times and them, not a search for each sample (15 -> 5 ms
        at 500,000, most of it the new arrays' page faults)."""
        first, last = int(self.index[0]), int(self.index[-1])
        if last - first + 1 == self.index.size:
            return self.record_time_s[first:last + 1].copy(), np.array(values, dtype=float)
        grid = np.arange(first, last + 1)
        return self.record_time_s[grid], np.interp(grid, self.index, values)


class Recent:
    """The loop's last results over one record by key (its parameters, the sensitivities'
    names), kept read-only within ``budget_bytes``, the oldest dropped first: a fit
    evaluates where it stands more than once (its start's check and first residual, the
    projection's optimum and the polish's start), a diagnosis the model it tests on top."""

    def __init__(self, budget_bytes=None):
        self.budget_bytes = RECENT_BYTES if budget_bytes is None else budget_bytes
        self.items = OrderedDict()

    def get(self, key):
        """The result kept under ``key``, or None."""
        value = self.items.get(key)
        if value is not None:
            self.items.move_to_end(key)
        return value

    def columns(self, params, names):
        """The columns of ``names`` (samples x len(names)) of a sensitivity pass kept at
        ``params`` in more names, or None."""
        for key, value in reversed(self.items.items()):
            if key[0] == "sensitivity" and key[1] == params and set(names) <= set(key[2]):
                self.items.move_to_end(key)
                return value[:, [key[2].index(name) for name in names]]
        return None

    def put(self, key, value):
        """Keep ``value`` (an array, made read-only) under ``key`` while the budget allows;
        returns it (left writable and the others kept where it alone exceeds the budget)."""
        if value.nbytes > self.budget_bytes:
            return value
        value.setflags(write=False)
        self.items[key] = value
        self.items.move_to_end(key)
        while self.items and sum(kept.nbytes for kept in self.items.values()) > \
                self.budget_bytes:
            self.items.popitem(last=False)
        return value


def _reference_kind(time_s, reference_mm):
    """What ``reference_mm`` is, in words: a single sine at its frequency (one sinusoid
    describes it to 1 % RMS), a point-to-point trajectory of its moves, or a record with its
    reversals."""
    centred = reference_mm - np.mean(reference_mm)
    step_s = float(np.median(np.diff(time_s)))
    spectrum = np.abs(np.fft.rfft(centred))
    if centred.size >= 8 and np.any(spectrum[1:]):
        bin_hz = 1.0 / (centred.size * step_s)
        peak_hz = (np.argmax(spectrum[1:]) + 1) * bin_hz
        frequencies_hz = np.linspace(max(peak_hz - bin_hz, bin_hz / 2), peak_hz + bin_hz, 41)
        left, frequency_hz = _best_sine_fit(time_s, centred, frequencies_hz)
        if left <= 0.01 * _rms(centred):
            return f"a single sine at {frequency_hz:.3g} Hz"
    speed = np.abs(np.gradient(reference_mm, time_s))
    resting = speed < NEAR_STOP_SHARE * max(float(np.max(speed)), 1e-300)
    moves = int(np.count_nonzero(np.diff(resting.astype(int)) == -1))
    if resting.mean() >= 0.1 and moves:
        return f"a point-to-point trajectory of {moves} move{'s' if moves > 1 else ''}"
    direction = np.sign(np.gradient(reference_mm, time_s))
    turns = int(np.count_nonzero(np.diff(direction[direction != 0]) != 0))
    return f"a record with {turns} velocity reversal{'s' if turns != 1 else ''}"


def _best_sine_fit(time_s, values, frequencies_hz):
    """(RMS, frequency) of the least-squares sinusoid (cosine, sine and a constant) that
    leaves the least of ``values`` over the evenly spaced ``frequencies_hz`` (the lowest
    frequency among equal RMS): each fit by its 3 x 3 normal equations (the columns are
    near orthogonal over the record), the cosine and sine of the next frequency by turning
    the phasor e^{iωt} by the spacing, not anew (a complex product per sample where a
    cosine and a sine cost ten times that).

    Only the residuals that can leave the least are formed: each fit's sum of squares from
    its normal equations, e = v'v − 2β'g + β'Gβ (exact for any coefficients β), is within
    m/2 of the one its residual gives, m = 4(n + 20)·ε·B with B = (|v| + Σ|β_k||c_k|)²,
    which bounds both sums' rounding (dot products of n terms, the residual's four
    operations a sample); a fit whose e − m exceeds the least e + m so far leaves more
    than that one by (m + m')/2, its RMS strictly more, so the one that leaves the least
    is among those kept and formed, each RMS that of its residual as before (where a
    reference is a sine, 41 residuals -> one or two: 0.2 -> 0.1 s at 500,000 samples)."""
    elapsed = time_s - time_s[0]
    phasor = np.exp(2j * np.pi * frequencies_hz[0] * elapsed)
    turn = np.exp(2j * np.pi * (frequencies_hz[1] - frequencies_hz[0]) * elapsed) \
        if frequencies_hz.size > 1 else phasor
    total, power = float(np.sum(values)), float(values @ values)
    rounding = 4.0 * (values.size + 20) * np.finfo(float).eps
    cosine, sine = np.empty(values.size), np.empty(values.size)
    least, kept = np.inf, []  # kept: (e − m, frequency, coefficients, phasor) that may be least
    for frequency_hz in frequencies_hz:
        np.copyto(cosine, phasor.real)
        np.copyto(sine, phasor.imag)
        gram = np.array([[cosine @ cosine, cosine @ sine, np.sum(cosine)],
                         [0.0, sine @ sine, np.sum(sine)],
                         [np.sum(cosine), np.sum(sine), values.size]])
        gram[1, 0] = gram[0, 1]
        projected = np.array([cosine @ values, sine @ values, total])
        coefficients = np.linalg.lstsq(gram, projected, rcond=None)[0]
        estimate = power - 2.0 * coefficients @ projected + coefficients @ gram @ coefficients
        margin = rounding * (np.sqrt(power)
                             + np.abs(coefficients) @ np.sqrt(np.diag(gram))) ** 2
        least = min(least, estimate + margin)
        kept = [fit for fit in kept if fit[0] <= least]
        if estimate - margin <= least:
            kept.append((estimate - margin, float(frequency_hz), coefficients, phasor.copy()))
        phasor *= turn
    return min((_rms(_less_sinusoid(values, np.ascontiguousarray(turned.real),
                                    np.ascontiguousarray(turned.imag), coefficients)),
                frequency_hz) for _, frequency_hz, coefficients, turned in kept)


def _less_sinusoid(values, cosine, sine, coefficients):
    """``values - a * cosine - b * sine - c`` (``coefficients`` a, b, c), in that order
    (the same rounding)."""
    a, b, c = coefficients
    return values - a * cosine - b * sine - c


def _nearest_gap(times_s, sorted_s):
    """|time − the nearest of ``sorted_s``| (s) for each of ``times_s``: the nearest is a
    neighbour in the sorted order (one of two candidates, not a times x sorted matrix: 10^4
    near-stops x 10^4 reversals on a 10^4 s trace were 16 GB)."""
    after = np.searchsorted(sorted_s, times_s)
    gaps = [np.abs(times_s - sorted_s[np.clip(after + offset, 0, sorted_s.size - 1)])
            for offset in (-1, 0)]
    return np.minimum(*gaps)


def _scaled(values, factor):
    """``values * factor``, in place where ``values`` is writable (no :class:`Recent` keeps
    it: a pass too large to keep, a copy of the samples compared): a record's derivatives
    are the largest array a fit makes."""
    if values.flags.writeable:
        return np.multiply(values, factor, out=values)
    return values * factor


def _selector(index):
    """``index`` (increasing record samples) as a slice where it is a run of consecutive
    samples (no outlier left out): a view, not a copy, of what the loop gives."""
    if index.size and index[-1] - index[0] + 1 == index.size:
        return slice(int(index[0]), int(index[-1]) + 1)
    return index


def _first_settled(time_s):
    """Index of the first sample after the start-up window; 0 (the record is taken to start
    at rest) when fewer than half the samples lie after it."""
    first = int(np.searchsorted(time_s, time_s[0] + START_WINDOW_S))
    return first if 2 * first <= time_s.size else 0


def _rms(values):
    return float(np.sqrt(np.mean(np.square(values))))


def _regress(residual, basis):
    coefficients = np.linalg.lstsq(basis, residual, rcond=None)[0]
    return coefficients, basis @ coefficients


def _sinusoid(time_s, frequency_hz):
    phase = 2.0 * np.pi * frequency_hz * (time_s - time_s[0])
    return np.column_stack((np.cos(phase), np.sin(phase), np.ones_like(phase)))


def _rss(values):
    return float(values @ values)


def _max_abs(fitted_um):
    return float(np.max(np.abs(fitted_um)))


MAX_EVENTS = 200


class ForceSteps(Shape):
    """Force steps as events in time: at each, the force on the axis changes by a size and
    stays (a cut starting or ending, a load put down, a clamp), so the residual takes the
    loop's step response from there on. A train of them (cuts every second) is found as
    its events, with their times, sizes and the period when they repeat, not as the
    harmonics of its period.

    Candidates by a matching pursuit with orthogonal refits (Pati, Rezaiifar &
    Krishnaprasad, "Orthogonal matching pursuit", 27th Asilomar Conference, 1993): the
    loop's step response shifted to every sample compared is correlated with the residual
    (one FFT), the best joins, all are refitted; candidates are taken while one explains
    more than the high-frequency noise floor could at its most over the samples searched
    (:func:`feedaxis.stats.coloured.noise_floor_um`). Then backward: each step is tested
    against the set without it, by the extra-sum-of-squares test under the coloured-noise
    model (n/τ of the residual left by all of them), Bonferroni over every sample it could
    sit at, at the family-wise level; the weakest failing step leaves and the rest are
    refitted, until every step left passes. The structure's test is the steps' joint test,
    family-wise over the samples searched.
    """

    kind = "force_steps"
    extra = 2  # each step's time and size

    def trials(self, measurement):
        return 1 if measurement.uniform_step_s() and measurement.size >= 20 else 0

    def trial(self, measurement, current):
        chosen, test = self._search(measurement, current.model, current.residual_um,
                                    current.jacobian, current.statistics.n_free)
        model = current.model
        if chosen and measurement.refitter is not None:  # once more on the model refitted
            # with the steps: a plant the unmodelled steps bent would leave steps of its own
            basis = self._basis(measurement, current.model, chosen)
            refit, steps_um = measurement.refitter.with_basis(current.model, basis)
            jacobian = None if refit.jacobian is None else refit.jacobian[:, :-len(chosen)]
            chosen, test = self._search(measurement, model, refit.residual_um + steps_um,
                                        jacobian, current.statistics.n_free)
        if not chosen:
            return None
        times_s = measurement.record_time_s[np.array(chosen)]
        if (self.kind == "force_steps"
                and np.mean(measurement.near_stop(times_s)) >= REVERSAL_SHARE):
            return None  # steps at the reversals: the spikes there (:class:`Reversal`)
        basis = self._basis(measurement, model, chosen)
        if _rivals(measurement, current, basis):
            return None
        return Trial(basis, None, test, {"event_times_s": [float(t) for t in times_s]})

    @staticmethod
    def _basis(measurement, model, chosen):
        """The loop's response (µm) to a 1 N step at each record sample of ``chosen``, at
        the samples compared."""
        response = measurement.step_response_um(model)
        return np.column_stack([_step_column(response, c, measurement.index)
                                for c in chosen])

    def _search(self, measurement, model, residual_um, jacobian, n_free):
        """(sorted record samples of the steps found, their joint test) on ``residual_um``
        (at the samples compared) of ``model``, its ``jacobian`` the nuisance; ([], None)
        when none passes. Residual, step response and nuisance are whitened by the
        autoregressive filter of the residual's noise (robust spectrum, persistence raised
        by two standard errors: :meth:`feedaxis.stats.coloured.Autoregression.cautious`),
        so the tests are those of white noise."""
        first, last = int(measurement.index[0]), int(measurement.index[-1])
        _, residual = measurement.gridded(residual_um)
        noise = autoregression(residual, robust=True).cautious()
        whiten = _ar_filter(noise.coefficients)
        response = whiten(measurement.step_response_um(model))
        residual = whiten(residual - np.mean(residual))
        grid = np.arange(first, last + 1)
        positions = grid[1:-1]
        # the nuisance's columns stacked as rows and transposed, not column_stack'ed: the
        # filter runs down contiguous columns (stacked and filtered 40 -> 21 ms at 500,000
        # samples; the same values, so the same numbers)
        nuisance = (None if jacobian is None or jacobian.shape[1] == 0 else
                    whiten(np.array([measurement.gridded(c)[1] for c in jacobian.T]).T))
        chosen = _pursued_steps(residual, response, first, positions, nuisance)
        kept, full = _pruned_steps(measurement, residual, response, grid, nuisance, chosen,
                                   n_free, positions.size, self.extra)
        if not kept:
            return [], None
        extra = self.extra * len(kept)
        before = _leftover(residual, nuisance, None)
        dof = max(full.size - n_free - extra, 1)
        statistic = max(_rss(before) - _rss(full), 0.0) / extra / max(_rss(full) / dof, 1e-300)
        p_value = float(f_sf(statistic, extra, dof))
        test = Test(float(statistic), (extra, dof), min(1.0, p_value * positions.size),
                    f"F test of the steps together on the residual whitened by its noise's "
                    f"autoregressive filter (order {noise.order}); each step alone "
                    f"family-wise over the {positions.size} samples it could sit at", "F")
        return sorted(kept), test

    def amplitude_um(self, measurement, fitted_um, location):
        return _max_abs(fitted_um)

    def describe(self, measurement, trial, fitted_um):
        sizes_N = _regress(fitted_um, trial.basis)[0]
        times_s = np.array(trial.extra["event_times_s"])
        trial.extra["event_sizes_N"] = [float(size) for size in sizes_N]
        period = _period_s(times_s)
        trial.extra["period_s"] = period
        listed = ", ".join(f"{t:.4g} s ({size:+.3g} N)"
                           for t, size in zip(times_s[:12], sizes_N[:12]))
        more = f" and {times_s.size - 12} more" if times_s.size > 12 else ""
        repeat = (f", repeating every {period:.4g} s" if period is not None else "")
        return (f"{times_s.size} force step{'s' if times_s.size > 1 else ''}{repeat}: the force "
                f"on the axis changes at {listed}{more} (median size "
                f"{np.median(np.abs(sizes_N)):.3g} N), the loop's step response after each "
                "(a cut starting or ending, a load put down)")


def _bic(residual_um, basis, parameters):
    """The Bayesian information criterion of ``basis`` fitted to ``residual_um``."""
    left = residual_um - _regress(residual_um, basis)[1]
    n = residual_um.size
    return n * np.log(max(_rss(left) / n, 1e-300)) + parameters * np.log(n)


def _rivals(measurement, current, steps):
    """Whether another shape describes the residual of ``current`` at least as well as the
    force ``steps`` by the Bayesian information criterion (each step a time and a size):
    the strongest sinusoid (:class:`PeriodicForce`: amplitude, phase, frequency and a
    window's two edges; a burst at 50 Hz is a periodic force, not a hundred steps)."""
    residual = current.residual_um
    steps_bic = _bic(residual, steps, ForceSteps.extra * steps.shape[1])
    shape = PeriodicForce()
    if not shape.trials(measurement):
        return False
    trial = shape.trial(measurement, current)
    if trial is None:
        return False
    parameters = 3 + (2 if trial.extra["localised"] else 0)
    return _bic(residual, trial.basis, parameters) <= steps_bic


def _step_column(response, sample, rows):
    """The loop's response (µm) to a 1 N step at record ``sample``, at record ``rows``."""
    column = np.zeros(rows.size)
    after = rows >= sample
    column[after] = response[np.minimum(rows[after] - sample, response.size - 1)]
    return column


def _leftover(residual, nuisance, columns):
    """``residual`` less its least-squares fit on ``nuisance`` and ``columns`` (either may
    be None or empty)."""
    parts = [part for part in (nuisance, columns) if part is not None and part.shape[1]]
    if not parts:
        return residual
    return residual - _regress(residual, np.column_stack(parts))[1]


def _ar_filter(coefficients):
    """The whitening filter of an autoregression, x_k − Σ φ_j x_{k−j}, along the first axis
    from rest (a step column, zero before its step, stays one shifted)."""
    taps = np.concatenate(([1.0], -np.asarray(coefficients, dtype=float)))
    return lambda values: scipy.signal.lfilter(taps, [1.0], values, axis=0)


def _pursued_steps(residual, response, first, positions, nuisance):
    """Record samples of candidate steps (:class:`ForceSteps`), by orthogonal matching
    pursuit (each column orthogonalised against the nuisance and the steps before it): the
    pursuit stops when the best step explains less than the noise floor's largest chance
    drop over ``positions`` (its variance times the χ²₁ quantile at 1 − FAMILY_ALPHA /
    positions) or at ``MAX_EVENTS``. The floor is a lower bound under coloured noise, so
    the pursuit is liberal; :func:`_pruned_steps` tests what it found."""
    grid = np.arange(first, first + residual.size)
    basis = np.zeros((residual.size, 0)) if nuisance is None else _orthonormal(nuisance)
    left = residual - basis @ (basis.T @ residual)
    threshold = noise_floor_um(left) ** 2 * chi2_isf(FAMILY_ALPHA / positions.size, 1)
    chosen = []
    while len(chosen) < MAX_EVENTS:
        best = _best_step(left, response, first, positions, chosen)
        if best is None or best[1] <= threshold:
            break
        column = _step_column(response, best[0], grid)
        column = column - basis @ (basis.T @ column)
        norm = float(np.linalg.norm(column))
        chosen.append(best[0])
        if norm <= 1e-12 * max(float(np.linalg.norm(residual)), 1e-300):
            continue
        column /= norm
        basis = np.column_stack((basis, column))
        left = left - column * (column @ left)
    return chosen


def _orthonormal(columns):
    """Q of ``columns``' QR decomposition: ``np.linalg.qr(columns)[0]``, the same values in
    the same layout (C order), from the same LAPACK routines (geqrf, orgqr) called by SciPy
    on the columns as they are, without NumPy's copies of them in and of Q out (the step
    pursuit's nuisance on a 500 s servo trace, 500,000 x 6: 86 -> 40 ms)."""
    return np.ascontiguousarray(scipy.linalg.qr(columns, mode="economic",
                                                check_finite=False)[0])


def _pruned_steps(measurement, residual, response, grid, nuisance, chosen, n_free, searched,
                  extra):
    """(steps kept, the residual after them): backward elimination of ``chosen`` by
    each step's extra-sum-of-squares F test against the set without it (β² over the
    diagonal of (X'X)⁻¹, one fit per round) on the whitened residual, Bonferroni over the
    ``searched`` samples, at the family-wise level of a stage; each round drops the
    weakest half of the steps that fail (at least one)."""
    alpha = FAMILY_ALPHA / len(measurement.stages)
    chosen = list(chosen)
    offset = 0 if nuisance is None else nuisance.shape[1]
    while chosen:
        steps = np.column_stack([_step_column(response, c, grid) for c in chosen])
        design = steps if nuisance is None else np.column_stack((nuisance, steps))
        coefficients, _, rank, _ = np.linalg.lstsq(design, residual, rcond=None)
        full = residual - design @ coefficients
        inverse = np.diag(np.linalg.pinv(design.T @ design))[offset:]
        drops = coefficients[offset:] ** 2 / np.maximum(inverse, 1e-300)
        dof = max(full.size - n_free - extra * len(chosen), 1.0)
        statistic = drops / extra / max(float(full @ full) / dof, 1e-300)
        p_values = np.minimum(1.0, f_sf(statistic, extra, dof) * searched)
        failing = np.flatnonzero(p_values >= alpha)
        if not failing.size:
            return chosen, full
        weakest = failing[np.argsort(-p_values[failing])][:max(1, failing.size // 2)]
        chosen = [c for i, c in enumerate(chosen) if i not in set(weakest.tolist())]
    return [], residual


def _best_step(residual, response, first, positions, chosen):
    """The record sample among ``positions`` (not in ``chosen``) where the step response
    correlates best with ``residual`` (on the grid from record sample ``first``), and the
    drop in the residual sum of squares it alone would give; None when none does."""
    size = residual.size
    correlation = scipy.signal.fftconvolve(residual, response[:size][::-1])[size - 1:]
    # correlation[j] = sum_t residual[t + j] response[t]: a step at grid sample j
    energy = np.cumsum(response[:size] ** 2)[::-1]  # energy[j]: the response over size - j
    offsets = positions - first
    drop = correlation[offsets] ** 2 / np.maximum(energy[offsets], 1e-300)
    drop[np.isin(positions, chosen)] = 0.0
    best = int(np.argmax(drop))
    return (int(positions[best]), float(drop[best])) if drop[best] > 0.0 else None


def _period_s(times_s):
    """The period (s) of event times that repeat (three or more, every interval within 10 %
    of the median, or of half of it where a train alternates on and off), else None."""
    if times_s.size < 3:
        return None
    intervals = np.diff(times_s)
    median = float(np.median(intervals))
    if median > 0 and np.all(np.abs(intervals - median) <= 0.1 * median):
        return median
    return None


class PeriodicForce(Shape):
    """The strongest sinusoid in the residual, over the whole record or during part of it:
    the loop's response to a periodic force at that frequency (e.g. a cutting force at the
    tooth-passing frequency, Anang et al. 2017 Table 2), switched on and off where the residual shows
    it (a cut that lasts part of the record).

    Two searches of the whitened residual (:mod:`feedaxis.stats.coloured`): the record's
    periodogram maximum (a force lasting the record) and the short-time periodogram's
    (a burst), their p-values weighted by ``WHOLE_RECORD_SHARE`` and the rest of the
    level (a weighted Bonferroni: the record's search, the stronger for a lasting force,
    keeps most of it). The window and frequency are then found by least squares
    (:func:`locate_sinusoid`), the window kept when it describes the sinusoid better than
    the whole record does.
    """

    kind = "periodic"
    extra = 3  # cosine, sine and the frequency

    def __init__(self):
        self._searched = (None, None)  # (the residual searched, what its search found)

    def trials(self, measurement):
        return 1 if measurement.uniform_step_s() and measurement.size >= 8 else 0

    def search_test(self, measurement, current):
        """The two searches' weighted family-wise test (:meth:`trial`'s), before the
        sinusoid is located."""
        return self._search(measurement, current)[2]

    def _search(self, measurement, current):
        """(time_s, gridded residual, test, frequency_hz, bin_hz) of the stronger search on
        the residual of ``current``, kept for the residual's next search."""
        if self._searched[0] is not current.residual_um:
            self._searched = (current.residual_um, self._searched_anew(measurement, current))
        return self._searched[1]

    @staticmethod
    def _searched_anew(measurement, current):
        time_s, residual = measurement.gridded(current.residual_um)
        step_s = measurement.uniform_step_s()
        whole_hz, whole_p, whole_ratio = peak_p_value(residual, step_s, robust=True)
        burst = short_time_peak(residual, step_s)
        share = 1.0 if burst is None else WHOLE_RECORD_SHARE
        burst_p = 1.0 if burst is None else min(1.0, burst.p_value / (1.0 - share))
        whole_p = min(1.0, whole_p / share)
        if burst_p < whole_p:
            frequency_hz, bin_hz = burst.frequency_hz, 1.0 / (burst.window * step_s)
            test = Test(burst.ratio, (1, burst.trials), burst_p,
                        f"short-time periodogram maximum of the whitened residual, family-wise "
                        f"over {burst.trials} windows and frequencies and the whole record",
                        "ratio")
        else:
            frequency_hz, bin_hz = whole_hz, 1.0 / (residual.size * step_s)
            test = Test(whole_ratio, (1, residual.size), whole_p,
                        "whitened periodogram maximum, family-wise over the frequencies "
                        "searched and the short-time windows", "ratio")
        return time_s, residual, test, frequency_hz, bin_hz

    def trial(self, measurement, current):
        time_s, residual, test, frequency_hz, bin_hz = self._search(measurement, current)
        first, stop, frequency_hz, localised = locate_sinusoid(residual, time_s, frequency_hz,
                                                               bin_hz)
        record_s = measurement.record_time_s
        on, start_s, end_s = 1.0, float(time_s[0]), float(time_s[-1])
        if localised:
            first, last = first + int(measurement.index[0]), stop - 1 + int(measurement.index[0])
            if test.p_value < FAMILY_ALPHA:  # only a sinusoid that may pass is refined
                first, last = measurement.fit_window(current.model, current.residual_um,
                                                     frequency_hz, first, last)
            if np.all(measurement.near_stop(record_s[first:last + 1])):
                return None  # the ringing of a spike at the reversals: :class:`Reversal`'s
            start_s, end_s = float(record_s[first]), float(record_s[last])
            on = np.zeros(record_s.size)
            on[first:last + 1] = 1.0
        phase = 2.0 * np.pi * frequency_hz * record_s
        basis = np.column_stack([measurement.loop_response_um(current.model, np.cos(phase) * on),
                                 measurement.loop_response_um(current.model, np.sin(phase) * on)])
        return Trial(basis, frequency_hz, test,
                     {"start_s": start_s, "end_s": end_s, "localised": localised})

    def amplitude_um(self, measurement, fitted_um, location):
        """The sinusoid's amplitude where the loop's response to the force is on (at least
        half its largest value)."""
        on = np.abs(fitted_um) >= 0.5 * _max_abs(fitted_um)
        if on.sum() < 3:
            return _max_abs(fitted_um)
        return float(np.hypot(*_regress(fitted_um[on], _sinusoid(measurement.time_s[on],
                                                                 location))[0][:2]))

    def describe(self, measurement, trial, fitted_um):
        """The sinusoid, the force it answers (JSON ``force_N``) and, where the reference
        runs at a steady speed, what turns at that frequency (:func:`_turning_at`: JSON
        ``source``, ``rotation_hz``, ``harmonic``)."""
        amplitude_um = self.amplitude_um(measurement, fitted_um, trial.location)
        force_N = np.hypot(*_regress(fitted_um, trial.basis)[0])
        bin_hz = 1.0 / max(trial.extra["end_s"] - trial.extra["start_s"], 1e-300)
        named = _turning_at(measurement, trial.location, trial.extra["start_s"],
                            trial.extra["end_s"], bin_hz)
        trial.extra.update({**named[1], "force_N": float(force_N)})
        if trial.extra["localised"]:
            return (f"a sinusoid at {trial.location:.4g} Hz from {trial.extra['start_s']:.4g} s "
                    f"to {trial.extra['end_s']:.4g} s, {amplitude_um:.3g} µm in the residual "
                    f"(short-time periodogram {trial.test.statistic:.0f}x the noise level): the "
                    f"loop's response to a force of {force_N:.3g} N at that frequency during "
                    f"that time ({named[0] or 'e.g. a cutting force while the tool is engaged'})")
        return (f"a sinusoid at {trial.location:.4g} Hz, {amplitude_um:.3g} µm in the residual "
                f"(whitened periodogram {trial.test.statistic:.0f}x its mean level): the loop's "
                f"response to a force of {force_N:.3g} N at that frequency "
                f"({named[0] or 'e.g. a cutting force at the tooth-passing frequency'})")


STEADY_SPEED_SPREAD = 0.05  # the reference's speed varies less (interquartile range over
# median) while a sinusoid in time can be a rotation's
MAX_HARMONIC = 10  # of a rotation, named as such


def _turning_at(measurement, frequency_hz, start_s, end_s, bin_hz):
    """(text, JSON fields) naming what turns at ``frequency_hz`` while the reference runs at
    a steady speed v between ``start_s`` and ``end_s``: the screw, at v / lead (and its
    harmonics up to ``MAX_HARMONIC``), or the motor's angular error, whose period is
    ``error_period_steps`` steps of ``step_angle_deg`` (360 / (step angle × steps) per
    revolution), where [motor] gives them; a match within ``bin_hz`` plus the speed's
    spread. ("", {}) when the speed is not steady or nothing matches."""
    inside = (measurement.time_s >= start_s) & (measurement.time_s <= end_s)
    screw = measurement.case.axis.screw
    if inside.sum() < 3 or not screw.get("lead_mm"):
        return "", {}
    speed_mm_s = np.abs(np.gradient(measurement.reference_mm, measurement.time_s))[inside]
    median = float(np.median(speed_mm_s))
    spread = float(np.subtract(*np.percentile(speed_mm_s, [75, 25]))) / max(median, 1e-300)
    if median <= 0.0 or spread > STEADY_SPEED_SPREAD:
        return "", {}
    rotation_hz = median / screw["lead_mm"]
    sources = [("screw", rotation_hz, f"the screw's rotation at {median:.4g} mm/s over its "
                                      f"{screw['lead_mm']:g} mm lead, {rotation_hz:.4g} Hz")]
    motor = measurement.case.axis.motor
    if motor.get("step_angle_deg") and motor.get("error_period_steps"):
        per_turn = screw["lead_mm"] / motor_error_period_mm(
            screw["lead_mm"], motor["step_angle_deg"], motor["error_period_steps"])
        sources.append(("motor", rotation_hz * per_turn,
                        f"the motor's angular error, {per_turn:.4g} periods per revolution "
                        f"at {rotation_hz:.4g} rev/s, {rotation_hz * per_turn:.4g} Hz"))
    for source, base_hz, text in sources:
        harmonic = int(round(frequency_hz / base_hz))
        if 1 <= harmonic <= MAX_HARMONIC and abs(frequency_hz - harmonic * base_hz) <= (
                bin_hz + harmonic * base_hz * spread):
            which = "" if harmonic == 1 else f"harmonic {harmonic} of "
            return (f"{which}{text}: a force that turns with the {source}",
                    {"source": source, "rotation_hz": base_hz, "harmonic": harmonic})
    return "", {}


class ConstantForce(Shape):
    """A steady force: the fitted loop's response to 1 N, scaled."""

    kind = "constant_force"

    def trial(self, measurement, current):
        """None where the measured position drifts (:meth:`Tracking.offset_unknown`)."""
        if measurement.offset_unknown(current):
            return None
        response = measurement.loop_response_um(current.model,
                                               np.ones(measurement.record_time_s.size))
        return Trial(response[:, None])

    def amplitude_um(self, measurement, fitted_um, location):
        return _max_abs(fitted_um)

    def describe(self, measurement, trial, fitted_um):
        force_N = _regress(fitted_um, trial.basis)[0][0]
        return (f"a steady force of {force_N:+.3g} N acting on the axis (in a record that "
                "starts mid-motion, equally the controller's integral term at the first sample: "
                "the record cannot tell them apart)")


class Reversal(Shape):
    """Spikes at the velocity reversals (quadrant glitches) that the model does not carry: a
    Stribeck rise where the catalog's law does not match it, friction breaking away over
    time, stick-slip, backlash. The samples from ``REVERSAL_LEAD_S`` before to
    ``REVERSAL_WINDOW_S`` after each reversal or near-stop of the reference
    (:meth:`Tracking.stops_s`) are tested against the rest: the residual whitened by its
    noise's autoregressive filter (as :class:`ForceSteps`), the ratio of its mean square
    there to elsewhere an F statistic under white noise. What is described is the residual
    in those windows itself (a spike's shape after a reversal is the loop's nonlinear
    response to sticking, which no linear force term fits), and the search ends with it:
    those windows hold about half of a record that reverses often, and a residual with them
    taken out is no longer one the spectral tests can judge.
    """

    kind = "reversal"
    last = True  # the structure search ends with it

    def trials(self, measurement):
        return 1 if measurement.uniform_step_s() and measurement.stops_s().size else 0

    def trial(self, measurement, current):
        time_s, residual = measurement.gridded(current.residual_um)
        noise = autoregression(residual, robust=True).cautious()
        whitened = _ar_filter(noise.coefficients)(residual - np.mean(residual))[noise.order:]
        near = measurement.near_stop(time_s)
        inside, outside = near[noise.order:], ~near[noise.order:]
        if inside.sum() < 2 or outside.sum() < 2:
            return None
        statistic = float(np.mean(whitened[inside] ** 2) / max(np.mean(whitened[outside] ** 2),
                                                               1e-300))
        dof = (int(inside.sum()), int(outside.sum()))
        test = Test(statistic, dof, float(f_sf(statistic, *dof)),
                    "F test of the residual's mean square near the reversals against elsewhere, "
                    f"whitened by its noise's autoregressive filter (order {noise.order})", "F")
        near = measurement.near_stop(measurement.time_s)
        return Trial(np.where(near, current.residual_um, 0.0)[:, None], None, test)

    def amplitude_um(self, measurement, fitted_um, location):
        return _max_abs(fitted_um)

    def describe(self, measurement, trial, fitted_um):
        """``height_um`` (the largest departure near a reversal), ``median_height_um`` (its
        median over the reversals), ``decay_s`` (the median time from each peak to 1/e of
        it) and ``reversal_times_s``."""
        stops = measurement.stops_s()
        spike = _spike_size(measurement, stops, fitted_um) or {
            "height_um": None, "median_height_um": None, "decay_s": None}
        trial.extra = {"reversal_times_s": [float(t) for t in stops], **spike}
        height = ("" if spike["height_um"] is None else
                  f": up to {spike['height_um']:.3g} µm (median {spike['median_height_um']:.3g} "
                  f"µm over the {stops.size} reversals and near-stops)")
        decay = ("" if spike["decay_s"] is None else
                 f", falling to 1/e of its peak within {1e3 * spike['decay_s']:.3g} ms")
        return (f"a spike in the tracking error at the velocity reversals (a quadrant glitch)"
                f"{height}{decay}: friction at rest the model does not carry (a Stribeck rise "
                "of another shape, friction breaking away over time, stick-slip), or backlash")


def _spike_size(measurement, stops_s, fitted_um):
    """{height_um, median_height_um, decay_s} of ``fitted_um`` (at the samples compared)
    near the reversals or near-stops at ``stops_s``: the largest departure in any window
    (:meth:`Tracking.near_stop`), the median over the windows of the largest in each, the
    median over the windows whose peak reaches half the largest of the time from that peak
    until the departure falls below 1/e of it (None where it never does); None without a
    window of two samples."""
    heights, decays = [], []
    starts = np.searchsorted(measurement.time_s, stops_s - REVERSAL_LEAD_S)
    ends = np.searchsorted(measurement.time_s, stops_s + REVERSAL_WINDOW_S)
    for start, end in zip(starts, ends):
        inside = np.arange(start, end)  # the samples compared are sorted in time
        if inside.size < 2:
            continue
        values = np.abs(fitted_um[inside])
        peak = int(np.argmax(values))
        heights.append(values[peak])
        below = np.flatnonzero(values[peak:] < values[peak] / np.e)
        decays.append(measurement.time_s[inside[peak + below[0]]] - measurement.time_s[
            inside[peak]] if below.size else np.nan)
    if not heights:
        return None
    decays = np.array(decays)[np.array(heights) >= 0.5 * max(heights)]
    decay = float(np.nanmedian(decays)) if np.isfinite(decays).any() else None
    return {"height_um": float(np.max(heights)), "median_height_um": float(np.median(heights)),
            "decay_s": decay}


class TimeDrift(Shape):
    """A slow drift in time, linear and quadratic (thermal growth of the screw under a
    rotary encoder, a drifting scale): a nuisance of every diagnosis, not an effect."""

    kind = "drift"
    extra = 2

    def trial(self, measurement, current):
        return Trial(drift_basis(measurement.time_s))

    def amplitude_um(self, measurement, fitted_um, location):
        return _max_abs(fitted_um)

    def describe(self, measurement, trial, fitted_um):
        change = float(fitted_um[-1] - fitted_um[0])
        span_s = float(np.ptp(measurement.time_s))
        return (f"the deviation drifts {change:+.3g} µm over the record ({span_s:.3g} s), the "
                "same whatever the motion: a drift of the measurement (thermal growth, a "
                "drifting scale), not an effect of the loop")
