"""Positioning deviations at targets (positioning.csv, laser-interferometer style).

The model's effects add errors at each target (:attr:`feedaxis.effects.Effect.additive`).
The noise model the samples support (:mod:`feedaxis.stats.noise`): replicates where
samples repeat at a target and direction (the pure error); in a single pass each way, the
+ and - readings at a target about a reversal, constant or linear along the travel where
the pairs show it, their noise looked for along the travel; otherwise the
residual mean square; and wherever there are enough samples in the order they were taken,
serially correlated noise estimated from the residual, used by every test when the data
show it. Structure is searched along the travel: a sinusoid of free wavelength, a reversal
changing along the travel, a trend; a drift along the test's clock is a nuisance of every
fit; what is left is tested for lack of fit against the replicates. Without replicates the
data cannot tell noise from an irregular error along the travel, and the diagnosis says so
(``undetermined``). ``compare`` gives the ISO 230-2 figures of the measurement and of the
residual.
"""
from __future__ import annotations

from dataclasses import dataclass, replace
from functools import cached_property, partial
from pathlib import Path

import numpy as np
import scipy

from .. import kinds, standards
from ..case import (DUTY_FILE, CaseError, _check_travel, _first_bad, _read_csv, checked_run,
                    length_mm)
from ..iso230 import (SAME_TARGET_MM, compact_index, index_type, iso230_figures, sampling_notes,
                      target_clusters)
from ..standards import DEFAULT
from ..plausibility import positioning_problems, warn_implausible
from ..stats import judge
from ..stats.aliasing import aliased
from ..stats.coloured import peak_p_value
from ..stats.distributions import f_sf
from ..stats.judge import Layout, Test, drift_basis
from ..stats.linear import Columns, normal_solve
from ..stats.noise import PureError, ResidualMeanSquare, Serial, SerialPairs
from ..stats.spectrum import amplitude_spectrum, resolvable_band_per_mm
from .base import Measurement, Shape, Trial

MAX_TREND_DEGREE = 3
MIN_TREND_TARGETS = 8  # a cubic through fewer targets follows any zig-zag
# A periodic error is claimed only where it repeats at least this often over the travel:
# fewer cycles are a trend or a drift, and under serially correlated noise the longest
# wavelengths of one pass are the noise's own (they passed at p ~ 1e-6 on AR(1) nulls).
MIN_CYCLES = 4
MIN_PAIRED_DOF = 4
REVERSAL_ALPHA = 0.05  # one pass each way: the pairs about a reversal changing along the travel
SERIAL_MIN_SAMPLES = 30  # an autoregressive noise model needs this many samples in order
# A catalog wavelength is resolvable when a sinusoid of any phase at the targets keeps at
# least this share of its size apart from an offset and a slope (its amplitude's standard
# error is then at most 1/0.3 = 3.3 times that of evenly spread phases).
RESOLVABLE_SHARE = 0.3
SAMPLE_COLUMNS = ("target_mm", "error_um", "direction", "run", "time_s", "ambient_C",
                  "material_C")
POSITIONING_FILE = "positioning.csv"
POSITIONING_COLUMNS = {"target_mm": True, "error_um": True, "direction": False, "run": False,
                       "time_s": False, "ambient_C": False, "material_C": False}


@dataclass(frozen=True)
class PositioningSamples:
    """positioning.csv as arrays; ``direction`` is ±1 (+1 when the column is absent);
    ``ambient_C`` the air and ``material_C`` the machine temperature (°C) when given."""

    target_mm: np.ndarray
    error_um: np.ndarray
    direction: np.ndarray
    run: np.ndarray | None = None
    time_s: np.ndarray | None = None
    ambient_C: np.ndarray | None = None
    has_direction: bool = False
    material_C: np.ndarray | None = None

    @property
    def size(self):
        return self.target_mm.size

    @property
    def bidirectional(self):
        """True when both approach directions were measured."""
        return self.has_direction and bool(np.any(self.direction == 1.0)
                                           and np.any(self.direction == -1.0))


def read_positioning(path, duty_end_s=None, length_mm=None):
    """Read positioning.csv: target and deviation, optional direction, run, time, ambient.

    With ``duty_end_s`` (a thermal case) every sample needs a time within the duty; with
    ``length_mm`` (the screw's length) the targets must span no more than the screw.
    """
    path = Path(path)
    values, rows = _read_csv(path, POSITIONING_COLUMNS)
    _check_travel(path, values, rows, ("target_mm",), length_mm)
    direction = values.get("direction")
    if direction is not None:
        _first_bad(path, ~np.isin(direction, (-1.0, 1.0)), rows, "direction",
                   "direction must be +1 or -1")
    run = checked_run(path, values, rows)
    time_s = values.get("time_s")
    if time_s is not None:
        _first_bad(path, time_s < 0, rows, "time_s", "time_s must be >= 0 (seconds since the "
                                                     "start of duty.csv)")
    if duty_end_s is not None:
        _check_within_duty(path, time_s, rows, duty_end_s)
    run = run.astype(index_type(np.max(run))) if run is not None else None
    values = own_columns(values, "run")
    return PositioningSamples(read_only(values["target_mm"]), values["error_um"],
                              values["direction"] if direction is not None
                              else np.ones_like(values["target_mm"]),
                              run, values.get("time_s"), values.get("ambient_C"),
                              has_direction=direction is not None,
                              material_C=values.get("material_C"))


def own_columns(values, *dropped):
    """{column: a contiguous copy} of the table's columns (views into one rows x columns
    array as read) but ``dropped``: the table is let go (at 10^7 rows it held 80 MB a
    column beside the copies kept)."""
    return {name: np.ascontiguousarray(column) for name, column in values.items()
            if name not in dropped}


def read_only(target_mm):
    """``target_mm`` made read-only, so that :func:`feedaxis.iso230.target_clusters` keeps
    its clusters (a sort of every sample) for all that asks for them."""
    target_mm.flags.writeable = False
    return target_mm


def _check_within_duty(path, time_s, rows, duty_end_s):
    if time_s is None:
        raise CaseError(path, "a thermal case (duty.csv present) needs time_s on every sample",
                        "1", "time_s")
    _first_bad(path, time_s > duty_end_s * (1 + 1e-9), rows, "time_s",
               f"sample lies after the end of duty.csv ({duty_end_s:g} s): the duty does not "
               "match the samples' time span")


def iso_comparison_lines(comparison):
    """The figures of the comparison's standard (ISO 230-2:2014 unless ``--standard`` chose
    another, or all), measured against the residual after the model."""
    from ..standards.text import all_lines, standard_lines

    lines = [f"{comparison['targets']} targets, runs + {comparison['runs_up']} / "
             f"- {comparison['runs_down']}; model: {', '.join(comparison['effects']) or '(none)'}"]
    if comparison["standard"] == standards.ALL:
        return "\n".join(lines + all_lines(comparison["standards"]))
    lines += standard_lines(comparison, (comparison["rms_measured_um"],
                                         comparison["rms_residual_um"]))
    if not comparison["bidirectional"] and comparison["standard"] == "ISO 230-2:2014":
        lines.append("(one approach direction: reversal B, E, M and bidirectional R, A need both)")
    lines += [f"note: {note}" for note in comparison.get("sampling", ())]
    return "\n".join(lines)


@kinds.register
class Positioning(Measurement):
    """The positioning samples of a case."""

    kind = "positioning"
    file = POSITIONING_FILE
    capabilities = ("outliers", "nuisances", "shapes", "tables", "resolution", "correlated")
    measured_column = ("error_um", 1.0)
    details = "feedaxis.positioning_details:positioning_details"
    views = "feedaxis.report.positioning:VIEWS"
    scenarios = "feedaxis.cosim.scenarios.positioning:SCENARIOS"
    text = staticmethod(iso_comparison_lines)
    standards = "feedaxis.standards.compare:standard_figures"

    @classmethod
    def read(cls, folder, axis, duty):
        path = Path(folder) / cls.file
        if not path.exists():
            if duty is not None:
                raise CaseError(Path(folder) / DUTY_FILE, f"a thermal test needs {cls.file} "
                                                          "with time_s beside duty.csv")
            return None
        samples = read_positioning(path, duty.end_s if duty is not None else None,
                                   length_mm(axis))
        warn_implausible(positioning_problems(samples.target_mm, samples.direction,
                                              samples.error_um, axis.lead_mm))
        return samples

    location_key = "wavelength_mm"
    location_unit = "mm"
    coordinate_label = "target position (mm)"
    reference_label = "measured"
    stages = ("drift", "effects", "structures", "lack of fit")

    def __init__(self, case):
        super().__init__(case)
        self.samples = self.samples_of(case)
        self.measured_um = np.asarray(self.samples.error_um, dtype=float)
        self.position_mm = self.coordinate = self.samples.target_mm
        self.direction = self.samples.direction
        self.bidirectional = self.samples.bidirectional
        self.marks = {}

    @cached_property
    def clusters(self):
        """(target positions, target index of each sample): :func:`target_clusters`."""
        return target_clusters(self.position_mm)

    @cached_property
    def layout(self):
        """Repeat groups and the test's clock."""
        return Layout.of(self.samples, self.clusters)

    def describe(self):
        return (f"{self.size} samples at {self.clusters[0].size} targets, "
                f"{self.position_mm.min():g} to {self.position_mm.max():g} mm")

    def wavelength_mm(self, effect):
        """The effect's wavelength along the travel on this axis (mm); None when it has none
        or the axis lacks what it needs."""
        try:
            return effect.wavelength_mm(self.case.axis)
        except KeyError:
            return None

    def unresolvable(self, effect):
        """Why the targets cannot resolve a periodic effect's wavelength (None when they
        can), the one rule every command applies (diagnose passes the effect over, fit
        calls its terms undetermined, comp-table leaves it out, the report does not mark it):
        its cosine and sine at the targets, taken apart from an offset and a slope (the lead
        error every positioning model carries), keep less than ``RESOLVABLE_SHARE`` of their
        size, or the targets cannot tell its wavelength from another in the band they
        resolve (:func:`feedaxis.stats.aliasing.aliased`). Irregular targets resolve
        wavelengths below their spacing only when they are many (ISO 230-2 staggers them so
        that a periodic error does not sit at one phase); targets at whole multiples of the
        wavelength resolve nothing."""
        wavelength_mm = self.wavelength_mm(effect)
        if not wavelength_mm:
            return None
        centres_mm, _ = self.clusters
        if centres_mm.size < 4:
            return f"its {wavelength_mm:.4g} mm wavelength needs at least 4 targets"
        share = resolved_share(centres_mm, wavelength_mm)
        if share < RESOLVABLE_SHARE:
            return (f"the targets do not resolve its {wavelength_mm:.4g} mm wavelength: its "
                    f"cosine and sine at the {centres_mm.size} targets keep {share:.2f} of "
                    f"their size apart from an offset and a slope (at least "
                    f"{RESOLVABLE_SHARE} needed)")
        return aliased(centres_mm, wavelength_mm)

    def degenerate(self):
        if np.ptp(self.position_mm) < SAME_TARGET_MM and self.samples.time_s is None:
            return (f"every sample is at the one target {self.position_mm[0]:g} mm (within "
                    f"{SAME_TARGET_MM * 1e3:g} µm): a positioning test needs at least "
                    "two targets")
        return None

    @cached_property
    def order(self):
        """Sample indices in the order taken: by the test's clock, else as the rows."""
        clock = self.layout.clock
        return compact_index(np.arange(self.size) if clock is None
                             else np.argsort(clock, kind="stable"))

    @cached_property
    def replicates(self):
        """The replicates the samples hold (:class:`PureError`), None without any: repeated
        runs, else one pass each way read as pairs about a constant reversal, or about one
        linear along the travel where the pairs show it (:func:`changing_reversal`): a
        reversal that changes along the travel, or a drift linear in time over the two
        passes, would otherwise be taken for noise and hide a trend."""
        if self.layout.has_repeats:
            return PureError(self.layout.groups)
        if not self.bidirectional:
            return None
        _, target = self.clusters
        constant = PureError(target, within=self.direction, paired=True,
                             measured_um=self.measured_um)
        linear = PureError(target, within=np.column_stack(
            (self.direction, self.direction * _normalised(self.position_mm))), paired=True,
            measured_um=self.measured_um)
        pairs = (linear if linear.dof >= MIN_PAIRED_DOF
                 and changing_reversal(constant, linear, self.measured_um) else constant)
        return pairs if pairs.dof >= MIN_PAIRED_DOF else None

    @cached_property
    def noise(self):
        """The replicates' pure error, else the residual mean square; serially correlated
        noise (:class:`Serial`) where ``SERIAL_MIN_SAMPLES`` samples in the order taken can
        carry an autoregressive model. One pass each way: the pairs, their noise looked for
        along the travel (:class:`SerialPairs`): an AR model of the noise part in the order
        taken, each half-difference twice and mirrored about the turn, decided the lead
        error by its low-frequency power (white single-pass nulls named a structure in 3-4 %,
        a trend of 17 µm against a pair scatter of 4 µm went unnamed;
        benchmarks/bench_single_pass.py)."""
        white = self.replicates or ResidualMeanSquare(self.order)
        if getattr(white, "paired", False):
            return self._serial_pairs(white)
        return Serial(self.order, white) if self.size >= SERIAL_MIN_SAMPLES else white

    def _serial_pairs(self, pairs):
        """:class:`SerialPairs` where every target holds one + and one - reading, else
        ``pairs``."""
        centres, target = self.clusters
        counts = [np.bincount(target[self.direction * sign > 0], minlength=centres.size)
                  for sign in (1, -1)]
        if not all(np.all(count == 1) for count in counts):
            return pairs
        return SerialPairs(pairs, self.direction, np.argsort(centres))

    def noise_gram(self, jacobian, residual_um, variance):
        if isinstance(self.noise, Serial):
            return self.noise.gram(jacobian, residual_um, variance)
        return super().noise_gram(jacobian, residual_um, variance)

    def outliers(self, residual_um):
        return judge.outlier_rows(self.layout, self.position_mm, residual_um)

    def transients(self, indices):
        """Those of ``indices`` that run without a gap from the first or the last sample of
        a continuous scan (no repeat groups: taken on the fly) in the order taken: the
        motion's start or stop, not isolated outliers."""
        if self.layout.has_repeats:
            return np.zeros(0, dtype=int)
        flagged = np.zeros(self.size, dtype=bool)
        flagged[indices] = True
        runs = self.samples.run if self.samples.run is not None else np.zeros(self.size)
        found = []
        for run in np.unique(runs):
            members = self.order[runs[self.order] == run]
            for ends in (members, members[::-1]):
                edge = np.argmin(flagged[ends]) if not flagged[ends].all() else ends.size
                found.extend(ends[:edge])
        return np.unique(np.asarray(found, dtype=int))

    def subset(self, keep):
        kept = {name: None if getattr(self.samples, name) is None else
                getattr(self.samples, name)[keep] for name in SAMPLE_COLUMNS}
        kept["target_mm"] = read_only(kept["target_mm"])
        return Positioning(self.case.with_samples(self.kind, replace(self.samples, **kept)))

    def rival(self, effect, left, result):
        """Why a periodic catalog effect is not what the data show (None when it is): it
        follows an irregular error from target to target (significant against the replicates
        but not against the lack of fit left, the noise model's shape test at the policy's
        level), or the data show the periodic error at another wavelength (the best free
        sinusoid in the resolvable band, fitted to the residual before the effect, leaves
        significantly less than the effect refitted with the model does: F test at
        ``judge.FAMILY_ALPHA``). The structure is then described for what it is instead."""
        wavelength_mm = self.wavelength_mm(effect)
        if not wavelength_mm:
            return None
        shape = self.noise.shape_test(left.residual_um, result.residual_um,
                                      len(effect.parameters), result.statistics.n_free)
        if not judge.accepts(shape.p_value, 1, len(self.stages)):
            return (f"it follows an irregular error from target to target: against the "
                    f"lack of fit left it is not significant ({shape.describe()})")
        free = Periodic().trial(self, left) if Periodic().trials(self) else None
        if free is None:
            return None
        residual = left.residual_um
        free_residual = residual - least_squares_fit(residual, free.basis)
        test = self.noise.extra_ss_test(result.residual_um, free_residual, 1,
                                        left.statistics.n_free + Periodic.extra)
        if test.p_value >= judge.FAMILY_ALPHA:
            return None
        return (f"its {wavelength_mm:.4g} mm wavelength explains the periodic error less "
                f"well than the data's own at {free.location:.4g} mm ({test.describe()})")

    def even_step_mm(self):
        """The step (mm) when the samples, in the order taken, are one evenly spaced pass
        in one direction (within 1 %) of at least ``SERIAL_MIN_SAMPLES``; else None."""
        if self.size < SERIAL_MIN_SAMPLES:
            return None
        steps = np.diff(self.position_mm[self.order])
        step = float(np.median(steps))
        uniform = step != 0 and np.max(np.abs(steps - step)) <= 0.01 * abs(step)
        return abs(step) if uniform else None

    def nuisances(self):
        """A drift along the clock, whenever repeated runs show one can be told from the
        targets: in a bidirectional test + and - runs alternate, so an unmodelled drift
        would alias into the reversal. (In one pass each way a drift linear in time equals
        a reversal changing along the travel: the two cannot be told apart.)"""
        drift = Drift()
        if not drift.trials(self):
            return []
        return [("drift", drift, Columns(drift.extra, partial(drift_basis, self.layout.clock)))]

    def shapes(self, effects):
        self.marks = marked_wavelengths(self.case.axis, effects)
        return (Periodic(), Direction(), Trend())

    def irregular(self, current):
        """An irregular error along the travel: the target means of the residual scatter
        beyond the replicates (the lack-of-fit F test), None without replicates or where
        the pairs of one pass each way show slow noise (:meth:`undetermined` says so)."""
        replicates, residual = self.replicates, current.residual_um
        if self._slow_pairs(residual):
            return None
        n_within = sum(len(e.parameters) for e in current.model.effects if e.name == "drift")
        n_between = current.statistics.n_free - n_within
        if replicates is None or replicates.n_groups <= n_between + 1:
            return None
        test = replicates.lack_of_fit_test(residual, n_between, n_within)
        means = replicates.group_means(residual)
        return ("irregular", test, means,
                f"the mean error at each target scatters {np.std(means):.3g} µm beyond the "
                f"{replicates.source}, irregularly along the travel: a lead-error table "
                "would capture it")

    def undetermined(self, current, stages):
        """Why the data cannot tell noise from an irregular error along the travel (None
        when they can): no replicates, and either too few samples or a residual serially
        correlated in the order taken (the von Neumann ratio test)."""
        slow = self._slow_pairs(current.residual_um)
        if slow:
            return (f"the + and - readings' half-differences are serially correlated along "
                    f"the travel ({slow.describe()}): slow noise (air, drift) or an irregular "
                    "error, which one pass each way cannot tell apart; repeat the runs (ISO "
                    "230-2: 5 each way)")
        if self.replicates is not None:
            return None
        if self.size < SERIAL_MIN_SAMPLES:
            return (f"one pass at {self.clusters[0].size} targets without "
                    "replicates: the scatter from target to target is the error itself or "
                    "noise, and the data cannot tell which; repeat the runs (ISO 230-2: 5 each "
                    "way) or measure both directions")
        test = judge.serial_correlation_test(current.residual_um[self.order])
        if not judge.accepts(test.p_value, 1, stages):
            return None
        return (f"the residual is serially correlated in the order taken ({test.describe()}): "
                "slow noise (air, drift) or an irregular error along the travel, which one "
                "pass cannot tell apart; repeat the run to decide")

    def _slow_pairs(self, residual_um):
        """The test that found the pairs of one pass each way serially correlated along the
        travel (:class:`SerialPairs`), else None."""
        if not isinstance(self.noise, SerialPairs):
            return None
        return self.noise.correlation(residual_um)

    def repeatability(self):
        """ISO 230-2 repeatability R set against the systematic deviation E of the measured
        runs (µm); None without repeated runs. The axis does not repeat when R > E: what
        varies from run to run is larger than what a model or a table can remove."""
        figures = iso230_figures(self.position_mm, self.measured_um, self.direction)
        for r_key, e_key in (("R_um", "E_um"), ("R_up_um", "E_up_um"),
                             ("R_down_um", "E_down_um")):
            if r_key in figures:
                r_um, e_um = figures[r_key], figures[e_key]
                return {"R_um": r_um, "E_um": e_um, "repeatable": bool(r_um <= e_um)}
        return None

    def head(self, result):
        """What ``compare`` says of the test and the fit before any standard's figures."""
        samples = self.samples
        measured = iso230_figures(samples.target_mm, result.measured_um, samples.direction)
        return {"case": str(self.case.folder), "kind": self.kind,
                "effects": list(result.model.names), "targets": measured["targets"],
                "runs_up": measured.get("runs_up", 0), "runs_down": measured.get("runs_down", 0),
                "sampling": sampling_notes(samples.target_mm, samples.direction, samples.run),
                "bidirectional": samples.bidirectional,
                "rms_measured_um": result.statistics.rms_before_um,
                "rms_residual_um": result.statistics.rms_um}

    def figures(self, result, standard=DEFAULT):
        """The figures of the positioning standard ``standard`` (default ISO 230-2:2014;
        ``all``: every one side by side) of the measurement and of the residual after the
        model; ``explained`` = 1 - residual / measured, the share the model explains
        (:mod:`feedaxis.standards`)."""
        samples = self.samples
        return {**self.head(result), **standards.figures_payload(
            standard, samples.target_mm, result.measured_um, result.residual_um,
            samples.direction)}


def changing_reversal(constant, linear, measured_um):
    """True when the pairs' reversal changes along the travel: the F test of the linear
    change against the scatter left about it, at ``REVERSAL_ALPHA`` (the pairs' noise model
    chosen by the data; with it always, a dozen targets lost a degree of freedom of twelve
    and the irregular error of tests/fit_diagnosis/test_verdicts.py went unnamed in 5 of
    40 seeds instead of 2)."""
    before, after = constant.pure_ss(measured_um), linear.pure_ss(measured_um)
    statistic = (before - after) / max(after / linear.dof, 1e-300)
    return float(f_sf(statistic, 1, linear.dof)) < REVERSAL_ALPHA


def marked_wavelengths(axis, effects):
    """{effect name: wavelength (mm)} of the periodic effects this axis defines."""
    marks = {}
    for name, effect in effects.items():
        try:
            wavelength = effect.wavelength_mm(axis)
        except KeyError:
            continue
        if wavelength:
            marks[name] = float(wavelength)
    return marks


def resolved_share(position_mm, wavelength_mm):
    """How well the targets ``position_mm`` resolve a sinusoid at ``wavelength_mm``, 1 fully,
    0 not at all: the smallest singular value of its cosine and sine columns, after
    projecting off an offset and a slope, over √(n/2), their size were the phases evenly
    spread (a sinusoid of any phase keeps at least this share of its size)."""
    phase = 2 * np.pi * position_mm / wavelength_mm
    pair = np.column_stack((np.cos(phase), np.sin(phase)))
    others = np.linalg.qr(np.column_stack((np.ones_like(position_mm),
                                           _normalised(position_mm))))[0]
    apart = pair - others @ (others.T @ pair)
    return float(np.linalg.svd(apart, compute_uv=False).min() / np.sqrt(position_mm.size / 2))


def least_squares_fit(residual_um, basis):
    """Projection of the residual on the few columns of ``basis`` (normal equations of the
    unit-scaled columns, :func:`feedaxis.stats.linear.normal_solve`)."""
    return basis @ normal_solve(basis, residual_um)


def _weighted_misfit(clusters, residual_um, frequency_per_mm):
    """Sum of squares left by a sinusoid at ``frequency_per_mm`` fitted to the target means
    of the residual, each weighted by its sample count: the fit to every sample, for a
    basis constant at a target, at the cost of the targets."""
    centres_mm, index = clusters
    counts = np.bincount(index)
    means = np.bincount(index, residual_um) / counts
    weights = np.sqrt(counts)
    basis = sinusoid(centres_mm, frequency_per_mm) * weights[:, None]
    return _rss(means * weights - least_squares_fit(means * weights, basis))


def _normalised(values):
    span = np.ptp(values)
    return (values - values.mean()) / (span if span > 0 else 1.0)


def sinusoid(position_mm, frequency_per_mm):
    """Basis cos, sin, 1 at one spatial frequency (1/mm)."""
    phase = 2 * np.pi * frequency_per_mm * position_mm
    return np.column_stack((np.cos(phase), np.sin(phase), np.ones_like(phase)))


def _rss(values):
    return float(values @ values)


class Periodic(Shape):
    """A sinusoid of free wavelength along the travel (cos, sin and the wavelength).

    On one evenly spaced pass the strongest line of the whitened periodogram along the pass
    is tested by Fisher's maximum (:func:`feedaxis.stats.coloured.peak_p_value`, family-wise
    over the wavelengths searched, calibrated under serially correlated noise); elsewhere
    the least-squares spectrum of the target means is searched and each resolvable
    frequency counted in the Bonferroni correction.
    """

    kind = "periodic"
    extra = 3

    def trials(self, measurement):
        """1 on an even pass (its p-value is family-wise), else the independent frequencies
        in the resolvable band (Rayleigh spacing 1/span)."""
        if measurement.even_step_mm():
            return 1
        centres, _ = measurement.clusters
        if centres.size < 8:
            return 0
        low, high = self.band_per_mm(centres)
        return max(int((high - low) * np.ptp(centres)), 0)

    @staticmethod
    def band_per_mm(centres_mm):
        """(lowest, highest) spatial frequency searched (1/mm): the resolvable band from
        ``MIN_CYCLES`` cycles over the travel."""
        low, high = resolvable_band_per_mm(centres_mm)
        return MIN_CYCLES * low, high

    def trial(self, measurement, current):
        residual_um, position_mm = current.residual_um, measurement.position_mm
        step_mm, test = measurement.even_step_mm(), None
        if step_mm:
            peak, p_value, ratio = peak_p_value(residual_um[measurement.order], step_mm,
                                                MIN_CYCLES)
            width = 1.0 / (residual_um.size * step_mm)
            test = Test(ratio, (1, residual_um.size), p_value,
                        "whitened periodogram maximum along the pass, family-wise over the "
                        "wavelengths searched", "ratio")
        else:
            spectrum = amplitude_spectrum(position_mm, residual_um, measurement.clusters)
            low = self.band_per_mm(measurement.clusters[0])[0]
            if spectrum is None or not np.any(1.0 / spectrum.wavelength_mm >= low):
                return None
            searched = 1.0 / spectrum.wavelength_mm >= low
            peak = 1.0 / spectrum.wavelength_mm[searched][int(np.argmax(
                spectrum.amplitude_um[searched]))]
            width = 1.0 / (5 * np.ptp(measurement.clusters[0]))
        best = scipy.optimize.minimize_scalar(
            lambda f: _weighted_misfit(measurement.clusters, residual_um, f),
            bounds=(max(peak - width, width / 2), peak + width), method="bounded",
            options={"xatol": width * 1e-4})
        return Trial(sinusoid(position_mm, best.x), float(1.0 / best.x), test)

    def describe(self, measurement, trial, fitted_um):
        amplitude = np.ptp(fitted_um) / 2
        return (f"peak at {trial.location:.4g} mm, amplitude {amplitude:.3g} µm; "
                f"{_compare_to_marks(trial.location, measurement.marks)}")


class Direction(Shape):
    """A reversal that changes along the travel (friction or stiffness, not a constant B)."""

    kind = "direction"
    extra = 2

    def trials(self, measurement):
        return 1 if measurement.bidirectional else 0

    def trial(self, measurement, current):
        scaled = _normalised(measurement.position_mm)
        return Trial(np.column_stack((measurement.direction, measurement.direction * scaled)))

    def describe(self, measurement, trial, fitted_um):
        position_mm, direction = measurement.position_mm, measurement.direction
        ends = [position_mm.min(), position_mm.max()]
        reversal = []
        for end in ends:
            near = np.abs(position_mm - end) <= 1e-9 + 0.05 * np.ptp(position_mm)
            reversal.append(np.mean(fitted_um[near & (direction > 0)])
                            - np.mean(fitted_um[near & (direction < 0)]))
        return (f"the reversal changes by {reversal[1] - reversal[0]:+.3g} µm along the travel "
                f"(left of the model: {reversal[0]:+.3g} µm at {ends[0]:g} mm, "
                f"{reversal[1]:+.3g} µm at {ends[1]:g} mm): friction or stiffness, not a "
                "constant backlash")


class Drift(Shape):
    """A drift along the test's clock (time, else run order): linear and quadratic."""

    kind = "drift"
    extra = 2

    def trials(self, measurement):
        return 1 if measurement.layout.clock_varies_within_groups else 0

    def trial(self, measurement, current):
        return Trial(drift_basis(measurement.layout.clock))

    def describe(self, measurement, trial, fitted_um):
        clock, unit = measurement.layout.clock, measurement.layout.clock_unit
        first, last = np.argmin(clock), np.argmax(clock)
        change = float(fitted_um[last] - fitted_um[first])
        span = float(np.ptp(clock))
        per = "per hour" if unit == "h" else "per run"
        over = f"{span:.2g} h" if unit == "h" else f"{span:.2g} runs"
        return (f"the error drifts {change:+.3g} µm over the test ({over}), {change / span:+.3g} "
                f"µm {per} on average, the same at every target; a drift, not an effect")


class Trend(Shape):
    """A straight line, bow or S-shape along the travel (a polynomial up to cubic), over at
    least ``MIN_TREND_TARGETS`` targets."""

    kind = "trend"
    extra = MAX_TREND_DEGREE

    def trials(self, measurement):
        targets = measurement.clusters[0].size
        return MAX_TREND_DEGREE if targets >= MIN_TREND_TARGETS else 0

    def trial(self, measurement, current):
        return Trial(np.vander(_normalised(measurement.position_mm), MAX_TREND_DEGREE + 1))

    def describe(self, measurement, trial, fitted_um):
        centres, index = measurement.clusters
        curve = np.bincount(index, fitted_um) / np.bincount(index)
        turns = int(np.count_nonzero(np.diff(np.sign(np.diff(curve))) != 0))
        shape = ("rises or falls steadily" if turns == 0 else "bows once" if turns == 1
                 else "bends into an S")
        return (f"the residual {shape} along the travel, {np.ptp(fitted_um):.3g} µm peak to "
                "valley (a polynomial up to cubic)")


def _compare_to_marks(wavelength_mm, marks):
    for label, mark_mm in marks.items():
        ratio = wavelength_mm / mark_mm
        for harmonic in (1, 2, 3):
            if abs(ratio * harmonic - 1) < 0.02:
                which = "the wavelength" if harmonic == 1 else f"harmonic {harmonic}"
                return (f"{which} of {label} ({mark_mm:.4g} mm), but that effect's shape "
                        "does not fit it")
    known = ", ".join(f"{label} {mm:.4g} mm" for label, mm in marks.items()) or "none"
    return f"matches no catalog wavelength ({known})"
