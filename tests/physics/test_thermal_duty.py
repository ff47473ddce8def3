"""The thermal field over a long duty, run by run (``thermal.duty_unit_fields``), against
the same closed form taken segment by segment and against Eq. 10 stepped explicitly.

Seeded duties mix runs of repeated segments, alternating paths, standstills at several
positions and durations that are not whole time steps; one parameter set has λ high
enough that the stability limit sets dt and the fastest modes alternate in sign.
"""
import numpy as np
import pytest

from feedaxis.physics import thermal
from feedaxis.physics.threads import one_blas_thread

TABLE1 = thermal.ThermalScrewParams()
CONDUCTIVE = thermal.ThermalScrewParams(conductivity_W_mK=4000.0, fixed_end_mm=-60.0)
PATHS = [(6000.0, 0.0, 500.0), (3000.0, 100.0, 300.0), (1500.0, 400.0, 50.0),
         (0.0, 0.0, 0.0), (0.0, 250.0, 250.0)]


def seeded_duty(seed, n_segments, repeat=0.6, whole_steps_of=None):
    """Consecutive segments from t = 0: a path is kept with probability ``repeat``;
    durations in whole multiples of ``whole_steps_of`` seconds when given."""
    rng = np.random.default_rng(seed)
    segments, now_s, path = [], 0.0, PATHS[0]
    for _ in range(n_segments):
        if rng.random() > repeat:
            path = PATHS[rng.integers(len(PATHS))]
        duration_s = (rng.integers(1, 60) * whole_steps_of if whole_steps_of
                      else rng.uniform(0.03, 40.0))
        segments.append(thermal.DutySegment(now_s, duration_s, *path))
        now_s += duration_s
    return segments


def sample_times(segments, seed, n=200):
    """Random times over the duty, every segment start and the duty's end."""
    end_s = segments[-1].end_s
    rng = np.random.default_rng(seed)
    return np.concatenate((rng.uniform(0.0, end_s, n), [s.start_s for s in segments],
                           [end_s]))


@one_blas_thread
def stepwise_unit_fields(params, segments, times_s):
    """The field segment by segment: each segment's closed form from the field the one
    before left (what duty_unit_fields computed before it merged runs)."""
    unit_K = np.zeros((2, times_s.size, params.n_cells))
    state_K = np.zeros((2, params.n_cells))
    modes = {}
    for segment in segments:
        path = (abs(segment.feed_mm_min), segment.from_mm, segment.to_mm)
        if path not in modes:
            modes[path] = thermal._path_modes(params, *path)
        mode = modes[path]

        def propagate(state, elapsed_s):
            steps = np.asarray(elapsed_s, dtype=float) / mode.dt_s
            decay = np.abs(mode.growth)[None, :] ** steps[:, None]
            decay[:, mode.alternating] *= np.cos(np.pi * steps)[:, None]
            modes = (state - mode.steady_K) @ mode.vectors
            return (decay[None] * modes[:, None, :]) @ mode.vectors.T + mode.steady_K[:, None]

        inside = (times_s >= segment.start_s) & (times_s <= segment.end_s)
        if inside.any():
            unit_K[:, inside] = propagate(state_K, times_s[inside] - segment.start_s)
        state_K = propagate(state_K, [segment.duration_s])[:, 0]
    return unit_K


@one_blas_thread
def euler_unit_fields(params, segments, times_s):
    """Eq. 10 stepped explicitly (:func:`thermal.euler_step`, the nut averaged over its
    path) at the stable dt of each segment; for durations of whole steps, times on steps."""
    unit_K = np.zeros((2, times_s.size, params.n_cells))
    state_K = np.zeros((2, params.n_cells))
    for segment in segments:
        feed = abs(segment.feed_mm_min)
        path_m = thermal.screw_coordinate_m(np.array([segment.from_mm, segment.to_mm]),
                                            params.fixed_end_mm)
        nut = thermal.averaged_nut_cells(params, *path_m)
        loss_W_K = thermal.convective_loss_W_K(params.cells, feed, nut)
        dt_s = thermal.stable_time_step_s(params.cells, loss_W_K)
        sources_K_s = thermal.unit_source_rates(params, feed, nut)
        steps = int(round(segment.duration_s / dt_s))
        for step in range(steps + 1):
            at = np.isclose(times_s, segment.start_s + step * dt_s, rtol=0, atol=1e-9)
            unit_K[:, at] = state_K[:, None]
            if step < steps:
                state_K = np.stack([thermal.euler_step(
                    params.cells, state_K[i], loss_W_K, dt_s / params.cell_heat_capacity_J_K,
                    dt_s * sources_K_s[i]) for i in range(2)])
    return unit_K


def assert_same_field(fast, slow, rtol=1e-12):
    """Every cell of every sample within ``rtol`` of the largest rise, per unit source."""
    for fast_K, slow_K in zip(fast, slow):
        scale = np.abs(slow_K).max()
        assert scale > 0
        assert np.abs(fast_K - slow_K).max() <= rtol * scale


@pytest.mark.parametrize("params", [TABLE1, CONDUCTIVE], ids=["table1", "dt-at-limit"])
@pytest.mark.parametrize("seed", [1, 2, 3])
def test_runs_match_segment_by_segment(params, seed):
    segments = seeded_duty(seed, 400)
    times_s = sample_times(segments, seed)
    fast = thermal.duty_unit_fields(params, segments, times_s)
    assert_same_field(fast, stepwise_unit_fields(params, segments, times_s))
    assert_same_field(thermal.duty_unit_fields(params, thermal.Segments.of(segments), times_s),
                      fast, rtol=0.0)


def test_the_limit_case_has_alternating_modes():
    """The second parameter set does exercise the alternating modes (growth < 0)."""
    modes = thermal._path_modes(CONDUCTIVE, *PATHS[0])
    assert modes.alternating.any() and modes.dt_s < CONDUCTIVE.time_step_s
    assert not thermal._path_modes(TABLE1, *PATHS[0]).alternating.any()


@pytest.mark.parametrize("seed", [4, 5])
def test_runs_match_eq10_stepped(seed):
    """Whole time steps: the run-by-run closed form is Eq. 10's explicit scheme."""
    dt_s = TABLE1.time_step_s
    segments = seeded_duty(seed, 60, whole_steps_of=dt_s * 7)
    times_s = np.minimum(np.round(sample_times(segments, seed, 50) / dt_s) * dt_s,
                         segments[-1].end_s)
    assert_same_field(thermal.duty_unit_fields(TABLE1, segments, times_s),
                      euler_unit_fields(TABLE1, segments, times_s), rtol=1e-11)


def test_one_long_run_is_its_segments():
    """10^4 one-second segments of one path give the field of one 10^4 s segment."""
    many = thermal.Segments(np.arange(10_000.0), np.ones(10_000), np.full(10_000, 6000.0),
                            np.zeros(10_000), np.full(10_000, 500.0))
    one = [thermal.DutySegment(0.0, 10_000.0, 6000.0, 0.0, 500.0)]
    times_s = np.array([0.0, 0.5, 999.25, 5000.0, 10_000.0])
    assert many.run_first.tolist() == [0]
    assert_same_field(thermal.duty_unit_fields(TABLE1, many, times_s),
                      thermal.duty_unit_fields(TABLE1, one, times_s))


def test_segments_behave_as_a_sequence():
    segments = seeded_duty(7, 20)
    columns = thermal.Segments.of(segments)
    assert len(columns) == 20 and list(columns) == segments
    assert columns[-1] == segments[-1] and columns[2:4] == segments[2:4]


def test_fit_progress_has_a_total_that_bounds_it(tmp_path):
    """The fit announces the most evaluations it can make before it starts, and stays
    within it (Rong et al. 2023's Table 2 duty, thermal_screw from Table 3 X)."""
    from feedaxis.case import read_case
    from feedaxis.effects import CATALOG, Model
    from feedaxis.examples import write_table2_case
    from feedaxis.fit import ParameterLayout, evaluation_bound, fit_with_artefacts

    write_table2_case(tmp_path / "case", 6000.0, run_every_s=900.0)
    case = read_case(tmp_path / "case")
    model = Model([CATALOG["thermal_screw"]])
    totals, counted = [], []

    def progress(step=None, total=None):
        if total is None:
            counted.append(step)
        else:
            totals.append(total)

    fit_with_artefacts(model, case, progress=progress)
    layout = ParameterLayout(model.with_values({"thermal_screw": {}}), case.axis)
    assert totals[0] == evaluation_bound(layout) == 100 * (4 + 6) * (1 + 4) + 2
    assert 0 < len(counted) <= sum(totals)
