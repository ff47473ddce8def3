"""The tracking diagnosis's fast paths find what the straightforward ones find, on seeded
records and on every ordering of hand-set p-values (issue 35, item 4)."""
import itertools
import math
from dataclasses import replace

import numpy as np
import pytest
import scipy.linalg

from feedaxis import diagnose as diagnosis
from feedaxis.case import read_case
from feedaxis.diagnose import diagnose
from feedaxis.effects import CATALOG, Model
from feedaxis.measurement.base import Shape, Trial
from feedaxis.stats import judge
from tracking_synthetic import sine, step_loop, two_sines, write_tracking_case

PLANT = {"plant_gain_mm_per_Vs2": 70000.0, "plant_damping_per_s": 150.0,
         "plant_stiffness_per_s2": 250.0, "delay_s": 0.0015}
SERVO_PLANT = Model((CATALOG["servo_plant"],))
RECORDS = {
    "null": dict(trajectory=two_sines, duration_s=2.0),
    "friction": dict(trajectory=two_sines, duration_s=2.0, friction_N=1.5),
    "periodic force": dict(trajectory=sine(10.0, 0.4), duration_s=3.0,
                           force_N=lambda t: 3.0 * math.sin(2 * math.pi * 62.5 * t)),
}


def _record_case(label, tmp_path, seed):
    """The case of the seeded record ``label`` of :data:`RECORDS`."""
    spec = dict(RECORDS[label])
    run = step_loop(spec.pop("trajectory"), spec.pop("duration_s"), plant=PLANT, **spec)
    return read_case(write_tracking_case(tmp_path / "case", run, seed))


@pytest.mark.parametrize("label", sorted(RECORDS))
def test_a_search_that_cannot_pass_is_not_located_and_nothing_changes(label, tmp_path,
                                                                      monkeypatch):
    """The periodic search left unlocated where its own test fails (``search_test``): the
    diagnosis equals the one locating it every time, to the bit, in fewer locations."""
    from feedaxis.measurement import tracking

    case = _record_case(label, tmp_path, 7)
    located = []
    locate = tracking.locate_sinusoid
    monkeypatch.setattr(tracking, "locate_sinusoid",
                        lambda *args: located.append(1) or locate(*args))
    fast = diagnose(case, SERVO_PLANT)
    fast_located, located[:] = len(located), []
    monkeypatch.setattr(tracking.PeriodicForce, "search_test", Shape.search_test)
    slow = diagnose(case, SERVO_PLANT)
    assert fast.to_json() == slow.to_json()
    np.testing.assert_array_equal(fast.final.residual_um, slow.final.residual_um)
    if label == "periodic force":
        assert fast.unexplained[0].kind == "periodic"
    else:
        assert fast_located < len(located)


class _Searched(Shape):
    """A shape with a set p-value, its test known before its basis (or not), whose trial may
    come to None."""

    def __init__(self, p_value, early, counted, column):
        self.p_value, self.early, self.counted, self.column = p_value, early, counted, column

    def search_test(self, measurement, current):
        return judge.Test(1.0, (1, 1), self.p_value, "set") if self.early else None

    def trial(self, measurement, current):
        if not self.counted:
            return None
        return Trial(self.column[:, None], None, judge.Test(1.0, (1, 1), self.p_value, "set"))

    def amplitude_um(self, measurement, fitted_um, location):
        return 1.0


class _Current:
    residual_um = np.linspace(-1.0, 1.0, 50)


def test_the_shapes_tried_are_counted_as_locating_every_search_counts_them():
    """Over p-values on both sides of each Bonferroni threshold, shapes with and without an
    early test and trials that do or do not come to None: the best shape and whether it
    passes are those of locating every search."""
    stages = 3
    thresholds = [0.01 / stages / tried for tried in (1, 2, 3)]
    levels = sorted({t * f for t in thresholds for f in (0.9, 1.1)} | {0.5})
    column = np.sin(np.linspace(0.0, 6.0, 50))
    cases = 0
    for p_values in itertools.product(levels, repeat=3):
        for counted in itertools.product((True, False), repeat=3):
            shapes = [_Searched(p_values[0], False, True, column),
                      *(_Searched(p, True, c, column) for p, c in zip(p_values[1:], counted))]
            fast = diagnosis._best_shape(None, _Current, shapes, stages)
            for shape in shapes:
                shape.early = False
            slow = diagnosis._best_shape(None, _Current, shapes, stages)
            passes = [best is not None and judge.accepts(best[0].p_value, best[-1], stages)
                      for best in (fast, slow)]
            assert passes[0] == passes[1]
            if passes[1]:
                assert fast[1] is slow[1] and fast[-1] == slow[-1]
            cases += 1
    assert cases == len(levels) ** 3 * 8


def test_the_autocorrelation_time_is_kept_by_content(monkeypatch):
    """A residual asked for again (equal content, another array) gets the τ computed for
    it, to the bit; another residual its own; the oldest kept leaves first."""
    from feedaxis.stats import coloured

    monkeypatch.setattr(coloured, "_KEPT_TAUS", coloured.KeptByContent(coloured.TAUS_KEPT))
    computed = []
    anew = coloured._autocorrelation_time
    monkeypatch.setattr(coloured, "_autocorrelation_time",
                        lambda values: computed.append(1) or anew(values))
    rng = np.random.default_rng(8)
    residuals = [np.convolve(rng.normal(size=5000), np.ones(k + 2), "same")
                 for k in range(coloured.TAUS_KEPT + 1)]
    first = coloured.autocorrelation_time(residuals[0])
    assert first == anew(residuals[0]) and first > 1.5
    assert coloured.autocorrelation_time(residuals[0].copy()) == first and len(computed) == 1
    taus = [coloured.autocorrelation_time(r) for r in residuals[1:]]
    assert [t == anew(r) for t, r in zip(taus, residuals[1:])] == [True] * len(taus)
    assert len(computed) == len(residuals) and len(coloured._KEPT_TAUS) == coloured.TAUS_KEPT
    assert coloured.autocorrelation_time(residuals[0]) == first
    assert len(computed) == len(residuals) + 1  # the oldest had left


@pytest.mark.parametrize("label", ("null", "friction"))
def test_the_friction_screens_from_one_pass_find_what_their_own_passes_find(label, tmp_path,
                                                                           monkeypatch):
    """The score screens of Coulomb and Stribeck friction take their columns from one
    sensitivity pass in all their parameters (``_screen_together``): the diagnosis equals
    the one running a pass per screen, to the bit, in one pass fewer."""
    from feedaxis.measurement import tracking

    case = _record_case(label, tmp_path, 3)
    passes = []
    one_pass = tracking.simulate_sensitivity
    monkeypatch.setattr(tracking, "simulate_sensitivity",
                        lambda *args: passes.append(tuple(args[1])) or one_pass(*args))
    together = diagnose(case, SERVO_PLANT)
    together_passes, passes[:] = list(passes), []
    monkeypatch.setattr(diagnosis, "_screen_together", lambda *args: None)
    apart = diagnose(case, SERVO_PLANT)
    assert together.to_json() == apart.to_json()
    np.testing.assert_array_equal(together.final.residual_um, apart.final.residual_um)
    # the first round screens both laws; after a law is named the other is screened alone
    assert ("friction_N",) in passes and ("friction_N",) not in together_passes
    assert ("friction_N", "coulomb_N", "static_N", "stribeck_velocity_mm_s") in together_passes
    assert len(together_passes) == len(passes) - 1


def test_each_friction_laws_neutral_values_are_the_loops_own():
    """The premise of one pass for the screens: each tracking effect at its neutral values
    sets the loop's parameters as the loop without it does, so the loop of the plant with
    every friction law at its neutral values is that of the plant with any one of them."""
    from feedaxis.physics.servo import ServoParams

    defaults = ServoParams()
    for effect in CATALOG.values():
        if effect.measurement == "tracking" and effect.name != "servo_plant":
            for name, value in effect.neutral.items():
                assert getattr(defaults, name) == value, (effect.name, name)


def test_the_start_s_simulation_is_the_held_force_s(tmp_path, monkeypatch):
    """The loop the start's search ran under the paper's plant is the one a held constant
    force is measured against (the record's own force, none here, as zeros): the same
    positions to the bit, and the same finding in one simulation fewer."""
    from feedaxis.fmu_map import servo_to_fmu
    from feedaxis.measurement import tracking
    from feedaxis.physics.servo import ServoParams, simulate

    case = _record_case("null", tmp_path, 3)
    measurement = tracking.Tracking(case)
    assert measurement.start.plant == {} and measurement.start.positions_mm is not None
    params = ServoParams(**servo_to_fmu(case.axis.servo))
    np.testing.assert_array_equal(measurement.start.positions_mm, simulate(
        params, measurement.record_time_s, measurement.record_reference_mm,
        np.zeros(measurement.record_time_s.size), measurement.counts))
    calls = []
    simulate_once = tracking.simulate
    monkeypatch.setattr(tracking, "simulate",
                        lambda *args: calls.append(1) or simulate_once(*args))
    kept, kept_calls = measurement.held_force(), len(calls)
    monkeypatch.setattr(measurement.start, "positions_mm", None)
    assert measurement.held_force() == kept
    assert (kept_calls, len(calls)) == (1, 3)


def test_the_stops_are_found_once_and_are_those_found_anew(tmp_path):
    from feedaxis.measurement import tracking

    measurement = tracking.Tracking(_record_case("null", tmp_path, 3))
    stops = measurement.stops_s()
    assert measurement.stops_s() is stops and not stops.flags.writeable and stops.size > 2
    np.testing.assert_array_equal(stops, measurement._found_stops_s())


def test_values_at_every_sample_are_gridded_as_interpolation_grids_them(tmp_path):
    """With no outlier left out the gridded values are a copy of the values, with some
    left out interpolated over them: np.interp's over the samples compared either way, to
    the bit."""
    from feedaxis.measurement import tracking

    measurement = tracking.Tracking(_record_case("null", tmp_path, 3))
    rng = np.random.default_rng(12)
    for left_out in ([], [3, 4, 50, measurement.index.size - 2]):
        measurement.index = np.delete(measurement.index, left_out)
        values = rng.normal(size=measurement.index.size)
        grid = np.arange(measurement.index[0], measurement.index[-1] + 1)
        time_s, gridded = measurement.gridded(values)
        np.testing.assert_array_equal(time_s, measurement.record_time_s[grid])
        np.testing.assert_array_equal(gridded, np.interp(grid, measurement.index, values))
        assert gridded is not values and (grid.size == values.size) == (not left_out)


def test_the_gap_to_the_nearest_reversal_is_the_matrix_minimum_to_the_bit():
    """The near-stops' gap to the nearest reversal from its two neighbours in sorted order
    is the minimum over every reversal (the times x reversals matrix it replaced), to the
    bit: on rounded times (ties, a time on a reversal) and outside the reversals' span."""
    from feedaxis.measurement.tracking import _nearest_gap

    rng = np.random.default_rng(7)
    for trial in range(300):
        reversals = np.sort(rng.uniform(0.0, 100.0, rng.integers(1, 40)))
        times = rng.uniform(-5.0, 105.0, rng.integers(0, 60))
        if trial % 2:
            reversals, times = np.round(reversals, 1), np.concatenate((np.round(times, 1),
                                                                        reversals[:3]))
        matrix = (np.min(np.abs(times[:, None] - reversals[None, :]), axis=1) if times.size
                  else np.zeros(0))
        assert _nearest_gap(times, reversals).tobytes() == matrix.tobytes()


class _Anew:
    """A keep-by-content that keeps nothing: every result computed anew."""

    @staticmethod
    def get(values, compute):
        return compute(np.ascontiguousarray(values, dtype=float))


@pytest.mark.parametrize("label", ("null", "periodic force"))
def test_the_robust_noise_model_is_kept_by_the_residual_s_content(label, tmp_path,
                                                                 monkeypatch):
    """The structure searches whiten the same residual by its robust AR model: kept by
    content, it is fitted once per residual, and the diagnosis equals the one fitting it
    anew every time, to the bit; what is kept cannot be written to."""
    from feedaxis.stats import coloured

    case = _record_case(label, tmp_path, 5)
    monkeypatch.setattr(coloured, "_KEPT_ROBUST", coloured.KeptByContent(coloured.TAUS_KEPT))
    fitted = []
    anew = coloured._autoregression
    monkeypatch.setattr(coloured, "_autoregression",
                        lambda *args: fitted.append(args[-1]) or anew(*args))
    kept = diagnose(case, SERVO_PLANT)
    kept_fits, fitted[:] = fitted.count(True), []
    monkeypatch.setattr(coloured, "_KEPT_ROBUST", _Anew())
    every = diagnose(case, SERVO_PLANT)
    assert kept.to_json() == every.to_json()
    np.testing.assert_array_equal(kept.final.residual_um, every.final.residual_um)
    assert 0 < kept_fits < fitted.count(True)
    monkeypatch.undo()
    residual = np.sin(np.arange(4000.0)) + np.random.default_rng(1).normal(size=4000)
    model = coloured.autoregression(residual, robust=True)
    assert model is coloured.autoregression(residual.copy(), robust=True)
    assert not model.coefficients.flags.writeable


@pytest.mark.parametrize("recorded", (False, True))
def test_a_steady_force_s_response_is_the_constant_force_s_loop(recorded, tmp_path,
                                                               monkeypatch):
    """The loop's response to a steady force is simulated as the model's constant force
    (kept by parameters, where the constant force's screen ran it): the same response to
    the bit as adding it to the record's force, with and without a recorded force; a
    force that varies takes the record's path."""
    from feedaxis.measurement import tracking

    force = (lambda t: 0.5 * np.sin(3.0 * t)) if recorded else None
    run = step_loop(two_sines, 2.0, plant=PLANT, force_N=force)
    case = read_case(write_tracking_case(tmp_path / "case", run, 3,
                                         force_N=force(run[0]) if recorded else None))
    measurement = tracking.Tracking(case)
    model = Model((CATALOG["servo_plant"],), {"servo_plant": PLANT})
    ones = np.ones(measurement.record_time_s.size)
    fast = measurement.loop_response_um(model, 2.0 * ones)
    params = measurement.params(model)
    known = 0.0 if measurement.disturbance_N is None else measurement.disturbance_N
    slow = measurement.deviation_um(params, known + 2.0 * ones) - measurement.deviation_um(params)
    np.testing.assert_array_equal(fast, slow)
    assert np.abs(fast).max() > 1e-3
    assert ("positions", replace(params, force_N=2.0)) in measurement.recent.items
    varying = np.linspace(0.0, 1.0, ones.size)
    np.testing.assert_array_equal(
        measurement.loop_response_um(model, varying),
        measurement.deviation_um(params, known + varying) - measurement.deviation_um(params))


def _every_sine_fit(time_s, values, frequencies_hz):
    """The straightforward path :func:`_best_sine_fit` replaced: each frequency's residual
    formed, the least RMS (the lowest frequency among equals)."""
    elapsed = time_s - time_s[0]
    phasor = np.exp(2j * np.pi * frequencies_hz[0] * elapsed)
    turn = np.exp(2j * np.pi * (frequencies_hz[1] - frequencies_hz[0]) * elapsed)
    total, left = float(np.sum(values)), []
    for _ in frequencies_hz:
        cosine, sine = np.ascontiguousarray(phasor.real), np.ascontiguousarray(phasor.imag)
        cross = float(cosine @ sine)
        gram = np.array([[cosine @ cosine, cross, np.sum(cosine)],
                         [cross, sine @ sine, np.sum(sine)],
                         [np.sum(cosine), np.sum(sine), values.size]])
        a, b, c = np.linalg.lstsq(gram, [cosine @ values, sine @ values, total], rcond=None)[0]
        left.append(float(np.sqrt(np.mean(np.square(values - a * cosine - b * sine - c)))))
        phasor *= turn
    return min(zip(left, frequencies_hz))


@pytest.mark.parametrize("seed", range(4))
def test_the_best_sine_fit_forms_few_residuals_and_is_every_fit_s_least(seed, monkeypatch):
    """A sine's reference (noisy, off the Fourier grid), a sine under a larger second one, a
    triangle and pure noise over 41 frequencies about the spectrum's peak: the same least
    RMS and frequency as forming every residual, to the bit; a sine's forms one or two."""
    from feedaxis.measurement import tracking

    rng = np.random.default_rng(seed)
    time_s = np.delete(np.arange(20000) * 1e-3, rng.integers(0, 20000, 3 * seed)) \
        + rng.uniform(0.0, 5.0)  # uneven where samples are left out as outliers are
    hz = rng.uniform(0.3, 3.0)
    signals = [3.0 * np.sin(2 * np.pi * hz * time_s + 1.0) + rng.normal(0.0, 1e-3, time_s.size),
               np.sin(2 * np.pi * hz * time_s) + 0.5 * np.sin(2 * np.pi * 2.2 * hz * time_s),
               np.abs(((hz * time_s) % 1.0) - 0.5), rng.normal(size=time_s.size)]
    formed = []
    less = tracking._less_sinusoid
    monkeypatch.setattr(tracking, "_less_sinusoid", lambda *a: formed.append(1) or less(*a))
    for values in signals:
        centred = values - np.mean(values)
        bin_hz = 1.0 / (20000 * 1e-3)
        peak_hz = (np.argmax(np.abs(np.fft.rfft(centred))[1:]) + 1) * bin_hz
        frequencies_hz = np.linspace(max(peak_hz - bin_hz, bin_hz / 2), peak_hz + bin_hz, 41)
        formed[:] = []
        assert tracking._best_sine_fit(time_s, centred, frequencies_hz) == \
            _every_sine_fit(time_s, centred, frequencies_hz)
        assert 1 <= len(formed) <= (2 if values is signals[0] else 41)


@pytest.mark.parametrize("label", ("null", "friction"))
def test_the_screens_projection_in_blocks_finds_what_the_whole_arrays_lstsq_finds(
        label, tmp_path, monkeypatch):
    """The screens' least squares by the projection through a QR in blocks of rows
    (:func:`feedaxis.stats.linear.projection`) against NumPy's lstsq of the whole design
    (the solve before): the same diagnosis, and each screened residual within 1e-12 of its
    norm or, where the design's condition (10^8 on these short records) leaves lstsq's own
    no closer, within 10 times the distance of LAPACK's other SVD solver's (gelss, at
    lstsq's cut-off). Its rank is lstsq's: tests/stats/test_linear.py."""
    case = _record_case(label, tmp_path, 3)
    solved = []
    in_blocks = diagnosis.projection
    monkeypatch.setattr(diagnosis, "projection", lambda columns, target: solved.append(
        (columns, target, in_blocks(columns, target))) or solved[-1][2])
    fast = diagnose(case, SERVO_PLANT)
    monkeypatch.setattr(diagnosis, "projection", lambda columns, target: columns @ np.linalg.lstsq(
        columns, target, rcond=None)[0])
    whole = diagnose(case, SERVO_PLANT)
    assert fast.to_json() == whole.to_json()
    np.testing.assert_array_equal(fast.final.residual_um, whole.final.residual_um)
    assert len(solved) >= 2
    for columns, target, fitted in solved:
        cut_off = np.finfo(float).eps * max(columns.shape)
        residual = target - columns @ np.linalg.lstsq(columns, target, rcond=cut_off)[0]
        other = target - columns @ scipy.linalg.lstsq(columns, target, cond=cut_off,
                                                      lapack_driver="gelss")[0]
        allowed = max(1e-12 * np.linalg.norm(residual), 10 * np.linalg.norm(other - residual))
        assert np.linalg.norm(target - fitted - residual) <= allowed


@pytest.mark.parametrize("label", ("null", "friction"))
def test_the_step_pursuit_s_nuisance_column_by_column_finds_what_row_by_row_finds(
        label, tmp_path, monkeypatch):
    """The force steps' nuisance (the Jacobian) whitened column by column against the same
    row by row (the layout before): the filter gives the same values, so the pursuit's
    orthonormal basis and the diagnosis are the same to the bit."""
    from feedaxis.measurement import tracking

    case = _record_case(label, tmp_path, 3)
    nuisances = []
    pursue = tracking._pursued_steps
    monkeypatch.setattr(tracking, "_pursued_steps",
                        lambda *args: nuisances.append(args[4]) or pursue(*args))
    by_column = diagnose(case, SERVO_PLANT)
    assert nuisances
    bases = [np.linalg.qr(n)[0] for n in nuisances]
    nuisances[:] = []
    ar_filter = tracking._ar_filter
    monkeypatch.setattr(tracking, "_ar_filter", lambda coefficients: lambda values: ar_filter(
        coefficients)(np.ascontiguousarray(values)))
    by_row = diagnose(case, SERVO_PLANT)
    assert by_column.to_json() == by_row.to_json()
    np.testing.assert_array_equal(by_column.final.residual_um, by_row.final.residual_um)
    assert len(bases) == len(nuisances)
    for basis, nuisance in zip(bases, nuisances):
        np.testing.assert_array_equal(basis, np.linalg.qr(nuisance)[0])


@pytest.mark.parametrize("label", ("null", "friction"))
def test_the_step_pursuit_s_basis_is_numpys_qr_to_the_bit(label, tmp_path, monkeypatch):
    """The pursuit's orthonormal basis of its nuisance from SciPy's QR of the columns as
    they are (``_orthonormal``) against ``np.linalg.qr`` (the call before): the same values
    in the same layout, so the same diagnosis to the bit."""
    from feedaxis.measurement import tracking

    case = _record_case(label, tmp_path, 3)
    nuisances = []
    orthonormal = tracking._orthonormal
    monkeypatch.setattr(tracking, "_orthonormal",
                        lambda columns: nuisances.append(columns) or orthonormal(columns))
    by_scipy = diagnose(case, SERVO_PLANT)
    assert nuisances
    for nuisance in nuisances:
        basis = orthonormal(nuisance)
        np.testing.assert_array_equal(basis, np.linalg.qr(nuisance)[0])
        assert basis.flags.c_contiguous
    monkeypatch.setattr(tracking, "_orthonormal", lambda columns: np.linalg.qr(columns)[0])
    by_numpy = diagnose(case, SERVO_PLANT)
    assert by_scipy.to_json() == by_numpy.to_json()
    np.testing.assert_array_equal(by_scipy.final.residual_um, by_numpy.final.residual_um)
