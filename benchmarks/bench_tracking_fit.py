"""Tracking fit benchmark (issue 12): feedaxis against plain least squares on a plain stepping.

Both fit servo_plant + coulomb_friction (plant b, a1, a0, delay and the Coulomb force: 5
parameters) to one 5 s record sampled at 1 ms with the 0.1 ms loop (5,000 samples, 50,000
loop steps per simulation), from the same starting point (the plant of Anang et al. 2017, the friction
from feedaxis's linearised first step), minimising the same sum of squares. The record
comes from the straightforward Runge-Kutta stepping of tests/tracking_synthetic.py (a plant
unlike Anang et al. 2017's, 1.5 N of friction, white + AR(1) noise).

- feedaxis: ``feedaxis.fit.fit`` on the tracking measurement: scipy TRF over the exact
  zero-order-hold loop (fractional delay included) compiled by numba.
- baseline: scipy ``least_squares`` (TRF, default finite differences) over the same loop
  stepped in plain Python (the Runge-Kutta stepping, the reference itself).

Both minimise the sum of squares over the samples the tracking measurement compares (after
the first 0.2 s, the start-up).

Then the diagnosis's measured error rates over ``--seeds`` seeds of 2 s records: the null
false-alarm rate (servo_plant fitted to runs without friction or force; an effect or a
structure other than a drift named), the power for a small friction (coulomb_friction named
first), for a periodic force at 62.5 Hz over the record and for a 0.5 s burst of one at 50 Hz
from 1 s (a periodic structure named within 2 % of the frequency; for the burst also its
window within 32 ms of the truth).

Last, the tests' calibration on pure coloured noise (``--seeds`` x 3 records): the
rejection rate at α = 0.01 and 0.001 of the periodic tests (the record's and the short-time
periodogram's) and of the n/τ F test (for a trend and for a square wave locked to the
reversals).

The fit and ``diagnose`` on a long trace (``--long-s``, default 500 s at 1 ms: the
5·10^6-step loop of bench_diagnose_scale.py, model servo_plant at the truth) are also timed
beside the paths before the loop's sensitivities (forward-difference Jacobians, every fit of
a diagnosis made anew: ``common.slow_tracking_paths``), interleaved, wall and CPU time.

Run: ``python benchmarks/bench_tracking_fit.py [--repeats 5] [--seeds 100] [--rates-only]``
(``--smoke``: one of each, for CI). Times are medians of repeats in this one run, BLAS on
one thread for both.
"""
import argparse
import contextlib
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares
from threadpoolctl import threadpool_limits

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
sys.path.insert(0, str(Path(__file__).resolve().parent))

from common import arguments  # noqa: E402
from feedaxis.case import read_case  # noqa: E402
from feedaxis.effects import CATALOG, Model  # noqa: E402
from feedaxis.diagnose import diagnose  # noqa: E402
from feedaxis.fit import ParameterLayout, fit, starting_values  # noqa: E402
from feedaxis.measurement import Tracking  # noqa: E402
from feedaxis.physics.servo import ServoParams, compiled_loop, simulate  # noqa: E402
from feedaxis.stats.coloured import peak_p_value, short_time_peak  # noqa: E402
from feedaxis.stats.noise import Coloured  # noqa: E402
from tracking_synthetic import noise_um, step_loop, two_sines, write_tracking_case  # noqa: E402

from bench_diagnose_scale import tracking_trace  # noqa: E402
from common import (machine, ratio_lines, side_by_side, slow_tracking_paths)  # noqa: E402

PLANT = {"plant_gain_mm_per_Vs2": 70000.0, "plant_damping_per_s": 150.0,
         "plant_stiffness_per_s2": 250.0, "delay_s": 0.0015}
FRICTION_N = 1.5
MODEL = Model((CATALOG["servo_plant"], CATALOG["coulomb_friction"]))


def timed(function, repeats):
    times, result = [], None
    for _ in range(repeats):
        start = time.perf_counter()
        result = function()
        times.append(time.perf_counter() - start)
    return statistics.median(times), result


def baseline_fit(case, start_model):
    """Plain least squares over the Runge-Kutta stepping of the loop (reference in time)."""
    layout = ParameterLayout(start_model, case.axis)
    tracking = case.tracking
    compared = Tracking(case).index
    measured_mm = tracking.actual_mm[compared]
    evaluations = [0]

    def reference(t):
        return float(np.interp(t, tracking.time_s, tracking.reference_mm))

    def residual(x):
        evaluations[0] += 1
        values = layout.values(x)
        _, _, position_mm = step_loop(reference, tracking.time_s[-1], plant=values["servo_plant"],
                                      friction_N=values["coulomb_friction"]["friction_N"])
        return (measured_mm - position_mm[compared]) * 1e3

    solution = least_squares(residual, layout.start(), bounds=layout.bounds(), x_scale="jac",
                             method="trf")
    return layout.values(solution.x), evaluations[0], float(np.sqrt(np.mean(solution.fun**2)))


POWER_FRICTIONS_N = (0.02, 0.05, 0.2)
POWER_PERIODIC_N = (0.01, 0.015, 0.02, 0.03)  # 62.5 Hz over the record
POWER_BURST_N = (0.02, 0.04, 0.06, 0.08)  # 50 Hz from 1 s to 1.5 s
BURST_S = (1.0, 1.5)


def _periodic_named(found, frequency_hz, window_s=None):
    """A periodic structure named within 2 % of ``frequency_hz`` (and within 32 ms of the
    window, when given)."""
    for structure in found.unexplained:
        report = structure.to_json()
        if structure.kind != "periodic" or abs(structure.location / frequency_hz - 1) > 0.02:
            continue
        if window_s is None or (abs(report.get("start_s", -1) - window_s[0]) <= 0.032
                                and abs(report.get("end_s", -1) - window_s[1]) <= 0.032):
            return True
    return False


def _share(folder, label, run, seeds, named):
    plant_only = Model((CATALOG["servo_plant"],))
    hits = 0
    for seed in range(seeds):
        case = read_case(write_tracking_case(Path(folder) / f"{label}-{seed}", run, seed))
        hits += bool(named(diagnose(case, plant_only)))
    return hits / seeds


def error_rates(folder, seeds):
    """(null false-alarm rate, {what: {size: power}}) of the diagnosis over ``seeds``."""
    def sinusoid(amplitude_N, frequency_hz, window_s=None):
        def force(t):
            on = window_s is None or window_s[0] <= t < window_s[1]
            return amplitude_N * np.sin(2 * np.pi * frequency_hz * t) if on else 0.0
        return force

    null = _share(folder, "null", step_loop(two_sines, 2.0, plant=PLANT), seeds,
                  lambda found: found.candidates or
                  any(s.kind != "drift" for s in found.unexplained))
    power = {"friction (N)": {f: _share(
        folder, f"f{f}", step_loop(two_sines, 2.0, plant=PLANT, friction_N=f), seeds,
        lambda found: found.candidates and found.candidates[0].effect == "coulomb_friction")
        for f in POWER_FRICTIONS_N}}
    power["62.5 Hz force over the record (N)"] = {a: _share(
        folder, f"p{a}", step_loop(two_sines, 2.0, plant=PLANT, force_N=sinusoid(a, 62.5)),
        seeds, lambda found: _periodic_named(found, 62.5)) for a in POWER_PERIODIC_N}
    power["50 Hz burst 1-1.5 s (N), frequency"] = {a: _share(
        folder, f"b{a}", step_loop(two_sines, 2.0, plant=PLANT,
                                   force_N=sinusoid(a, 50.0, BURST_S)),
        seeds, lambda found: _periodic_named(found, 50.0)) for a in POWER_BURST_N}
    power["50 Hz burst 1-1.5 s (N), and window"] = {a: _share(
        folder, f"w{a}", step_loop(two_sines, 2.0, plant=PLANT,
                                   force_N=sinusoid(a, 50.0, BURST_S)),
        seeds, lambda found: _periodic_named(found, 50.0, BURST_S)) for a in POWER_BURST_N}
    return null, power


def calibration(seeds):
    """{test: (rate at 0.01, rate at 0.001)} on pure noise, 5,001 samples at 1 ms."""
    time_s = np.arange(5001) * 1e-3
    regressors = {"F test, trend": time_s - time_s.mean(),
                  "F test, reversal square wave": np.sign(np.sin(np.pi * time_s))}
    p_values = {"periodic (whitened max periodogram)": [], "periodic (short-time periodogram)": [],
                **{name: [] for name in regressors}}
    for seed in range(3 * seeds):
        residual = noise_um(time_s.size, 10_000 + seed)
        p_values["periodic (whitened max periodogram)"].append(peak_p_value(residual, 1e-3)[1])
        p_values["periodic (short-time periodogram)"].append(
            short_time_peak(residual, 1e-3).p_value)
        for name, column in regressors.items():
            after = residual - column * (column @ residual) / (column @ column)
            p_values[name].append(Coloured().extra_ss_test(residual, after, 1, 1).p_value)
    return {name: (np.mean(np.array(p) < 0.01), np.mean(np.array(p) < 0.001))
            for name, p in p_values.items()}


def speed(folder, args):
    """The fit's time against the baseline's on one record of ``args.record_s``."""
    start = time.perf_counter()
    compiled_loop()
    load_s = time.perf_counter() - start
    run = step_loop(two_sines, args.record_s, plant=PLANT, friction_N=FRICTION_N)
    case = read_case(write_tracking_case(Path(folder) / "case", run, 7))
    start_model = starting_values(MODEL, [Tracking(case)])
    params = ServoParams(**PLANT, friction_N=FRICTION_N)
    one_fast_s, _ = timed(lambda: simulate(params, *run[:2]), args.repeats)
    one_plain_s, _ = timed(lambda: step_loop(two_sines, args.record_s, plant=PLANT,
                                             friction_N=FRICTION_N), args.repeats)
    fits = {"fit, sensitivities": (contextlib.nullcontext, lambda: fit(MODEL, case)),
            "fit, differences": (slow_tracking_paths, lambda: fit(MODEL, case))}
    side_by_side(fits, 1)  # both paths' kernels compiled or loaded from numba's cache
    paths = side_by_side(fits, args.repeats)
    fast_s, result = statistics.median(paths["fit, sensitivities"][0]), \
        paths["fit, sensitivities"][2]
    plain_s, (plain_values, evaluations, plain_rms) = timed(
        lambda: baseline_fit(case, start_model), args.baseline_repeats)
    print(f"record: {case.tracking.time_s.size} samples at 1 ms, loop 0.1 ms; numba "
          f"kernel load {load_s:.2f} s (once per process, cached on disk)")
    print(f"one simulation: compiled {1e3 * one_fast_s:.1f} ms, plain Python stepping "
          f"{1e3 * one_plain_s:.0f} ms ({one_plain_s / one_fast_s:.0f}x)")
    print(f"{'method':34s} {'time (s)':>9s} {'RMS (um)':>9s} {'friction (N)':>13s} "
          f"{'b (mm/V/s2)':>12s} {'delay (ms)':>10s}")
    fitted = result.params()
    for name, seconds, values, rms in (
            ("feedaxis (exact ZOH, numba, TRF)", fast_s, fitted, result.rms_um),
            ("plain least_squares, RK4 stepping", plain_s, plain_values, plain_rms)):
        print(f"{name:34s} {seconds:9.2f} {rms:9.4f} "
              f"{values['coulomb_friction']['friction_N']:13.4f} "
              f"{values['servo_plant']['plant_gain_mm_per_Vs2']:12.1f} "
              f"{1e3 * values['servo_plant']['delay_s']:10.4f}")
    print(f"truth: friction {FRICTION_N} N, b {PLANT['plant_gain_mm_per_Vs2']:.1f}, delay "
          f"{1e3 * PLANT['delay_s']:.4f} ms; baseline {evaluations} evaluations")
    print(f"ratio baseline / feedaxis: {plain_s / fast_s:.0f}x; target <= 10 s: "
          f"{'met' if fast_s <= 10.0 else 'MISSED'} ({fast_s:.2f} s)")
    print("the fit's Jacobians from the loop's sensitivities against forward differences:")
    print("\n".join(ratio_lines(paths, "fit, sensitivities", "fit, differences")))


def long_trace(args):
    """diagnose on ``args.long_s`` of trace, the new paths beside the old."""
    trace = tracking_trace(args.long_s)
    plant = Model([CATALOG["servo_plant"]], {"servo_plant": PLANT})
    diagnose(tracking_trace(3.0), plant)  # the kernels compiled or loaded once
    runs = side_by_side({"diagnose, sensitivities, fits kept": (
        contextlib.nullcontext, lambda: diagnose(trace, plant).verdict),
        "diagnose, differences, every fit anew": (
        slow_tracking_paths, lambda: diagnose(trace, plant).verdict)}, args.long_repeats)
    print(f"diagnose on {args.long_s:g} s at 1 ms ({trace.tracking.time_s.size} samples, loop "
          f"0.1 ms), verdicts {runs['diagnose, sensitivities, fits kept'][2]} / "
          f"{runs['diagnose, differences, every fit anew'][2]}:")
    print("\n".join(ratio_lines(runs, "diagnose, sensitivities, fits kept",
                                "diagnose, differences, every fit anew")))


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--baseline-repeats", type=int, default=1)
    parser.add_argument("--seeds", type=int, default=100)
    parser.add_argument("--record-s", type=float, default=5.0,
                        help="length of the fitted record (default 5 s)")
    parser.add_argument("--long-s", type=float, default=500.0,
                        help="length of the long trace diagnosed (default 500 s)")
    parser.add_argument("--long-repeats", type=int, default=3)
    parser.add_argument("--rates-only", action="store_true",
                        help="only the error rates and the calibration (no timing)")
    parser.add_argument("--speed-only", action="store_true",
                        help="only the timings (no error rates, no calibration)")
    args = arguments(parser, argv, repeats=1, baseline_repeats=1, seeds=1, record_s=0.5,
                     long_s=3.0, long_repeats=1)
    with tempfile.TemporaryDirectory() as folder, threadpool_limits(limits=1, user_api="blas"):
        if not args.rates_only:
            print(machine())
            speed(folder, args)
            long_trace(args)
        if args.speed_only:
            return
        false_alarm, power = error_rates(folder, args.seeds)
        print(f"diagnosis over {args.seeds} seeds (2 s records, noise 0.1 um white + 0.3 um "
              f"AR(1)): null false-alarm rate {false_alarm:.3f}; power:")
        for what, shares in power.items():
            print(f"  {what}: " + ", ".join(f"{size:g}: {share:.2f}"
                                            for size, share in shares.items()))
        print(f"calibration on pure coloured noise, {3 * args.seeds} records:")
        for name, (at_1pc, at_01pc) in calibration(args.seeds).items():
            print(f"  {name:38s} rejects {100 * at_1pc:5.2f} % at alpha 0.01, "
                  f"{100 * at_01pc:5.2f} % at 0.001")


if __name__ == "__main__":
    main()
