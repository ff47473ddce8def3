"""Thermal identification benchmark (issue 5): feedaxis against the straightforward baseline.

Both identify lead_error + thermal_screw (k1..k4, λ, P_f; Rong et al. 2023 Eq. 20) on the three
Table 2 conditions jointly, from the same starting point (Table 3 X, P_f as axis.toml
states it, 30 mm off), minimising the same sum of squares. The data are synthetic: an axis
with the Table 3 Y coefficients mounted as X (P_f = -141 mm), 1 µm noise, generated with
Eq. 10 stepped at dt = 0.1 s with the nut moving; so the start is not the answer.

- feedaxis: ``feedaxis.fit`` (closed-form field per segment, nut heat averaged over its
  path, k3/k4 and the lead error solved linearly inside TRF, then a TRF polish).
- plain TRF: the same closed form, all 8 parameters in TRF (no projection), for scale.
- baseline: scipy SLSQP, finite-difference gradients, over the explicit dt = 0.1 s model of
  Eq. 10 with the nut moving (``thermal.explicit_duty``), parameters scaled by their start.
  It is capped at ``--baseline-iterations``; its full run is extrapolated: the same SLSQP on
  the closed-form model (which differs from the explicit one by < 0.01 µm) counts the
  evaluations it needs, times the measured cost of one explicit evaluation, and its end
  point is evaluated on the explicit model for the baseline's final cost.

Run: ``python benchmarks/bench_thermal_identification.py [--repeats 5]``. Times are medians
of interleaved repeats in this one run; every method runs with BLAS on one thread, as
``feedaxis.fit`` does.
"""
import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from scipy.optimize import least_squares, minimize
from threadpoolctl import threadpool_limits

from feedaxis.case import read_case
from feedaxis.effects import CATALOG, Model
from feedaxis.examples import write_table2_case
from feedaxis.fit import ParameterLayout, fit, starting_values
from feedaxis.measurement import Positioning
from feedaxis.physics import geometry, thermal

sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import arguments  # noqa: E402

FEEDS_MM_MIN = (3000.0, 6000.0, 9000.0)
MODEL = Model((CATALOG["lead_error"], CATALOG["thermal_screw"]))


TRUTH = thermal.ThermalScrewParams(k1_W_m2K_per_mm_min=0.703e-3, k2_W_m2K=16.746,
                                   k3_W_per_mm_min=0.997e-3, k4_W_per_mm_min=1.76e-3,
                                   conductivity_W_mK=278.1, fixed_end_mm=-141.0)


def table2_cases(folder):
    return [read_case(write_table2_case(Path(folder) / f"x{int(feed)}", feed, TRUTH, seed=index,
                                        axis_fixed_end_mm=-111.0,
                                        simulate=thermal.explicit_duty))
            for index, feed in enumerate(FEEDS_MM_MIN)]


def sum_of_squares_um2(residual_um):
    return float(residual_um @ residual_um)


class Objective:
    """Sum of squares (µm²) of a parameter vector, scaled by the start, on one thermal model."""

    def __init__(self, cases, layout, x0, simulate):
        self.cases, self.layout, self.x0, self.simulate = cases, layout, x0, simulate
        self.measured = np.concatenate([c.positioning.error_um for c in cases])
        self.evaluations = 0

    def residual_um(self, x):
        values = self.layout.values(x)
        lead, heat = values["lead_error"], values["thermal_screw"]
        predicted = []
        for case in self.cases:
            params = CATALOG["thermal_screw"].screw_params(case.axis, heat)
            position_mm, time_s = case.positioning.target_mm, case.positioning.time_s
            rise_K = self.simulate(params, case.duty.segments, time_s)
            predicted.append(thermal.thermal_error_um(params, rise_K, position_mm)
                             + geometry.lead_error_um(position_mm, **lead))
        return self.measured - np.concatenate(predicted)

    def __call__(self, z):
        self.evaluations += 1
        return sum_of_squares_um2(self.residual_um(z * self.x0))


def slsqp(objective, layout, x0, max_iterations):
    lower, upper = layout.bounds()
    bounds = list(zip(lower / x0, upper / x0))
    bounds = [(min(a, b), max(a, b)) for a, b in bounds]
    started = time.perf_counter()
    result = minimize(objective, np.ones_like(x0), method="SLSQP", bounds=bounds,
                      options={"maxiter": max_iterations})
    return result, time.perf_counter() - started


def plain_trf(cases, layout, x0):
    predictors = [Positioning(case).predictor(layout.model) for case in cases]
    measured = np.concatenate([case.positioning.error_um for case in cases])
    result = least_squares(
        lambda x: measured - np.concatenate([p(layout.values(x)) for p in predictors]),
        x0, bounds=layout.bounds(), x_scale="jac")
    return sum_of_squares_um2(result.fun), result.nfev + result.njev * layout.size


def baseline_rows(explicit, closed, layout, x0, iterations, per_eval_s):
    """The baseline's rows: SLSQP on the explicit model capped at ``iterations``, and run to
    convergence (extrapolated from the same SLSQP on the closed form, whose end point is
    evaluated on the explicit model)."""
    explicit.evaluations = 0
    capped, capped_s = slsqp(explicit, layout, x0, iterations)
    surrogate, _ = slsqp(closed, layout, x0, 500)
    return [(f"baseline SLSQP + FD, explicit, capped at {iterations} it.", capped_s, capped.fun,
             f"measured, {capped.nfev} evaluations"),
            ("baseline SLSQP + FD, explicit, to convergence", surrogate.nfev * per_eval_s,
             explicit(surrogate.x),
             f"extrapolated: {surrogate.nfev} evaluations x {per_eval_s:.2f} s")]


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--baseline-iterations", type=int, default=2,
                        help="SLSQP iterations run on the explicit model (default 2; 0 leaves "
                             "the baseline out)")
    args = arguments(parser, argv, repeats=1, baseline_iterations=0)
    with tempfile.TemporaryDirectory() as folder:
        cases = table2_cases(folder)
        start = starting_values(MODEL, [Positioning(case) for case in cases])
        layout = ParameterLayout(start, cases[0].axis)
        x0 = layout.start()
        explicit = Objective(cases, layout, x0, thermal.explicit_duty)
        closed = Objective(cases, layout, x0, thermal.simulate_duty)

        ours_s, plain_s, explicit_eval_s = [], [], []
        for _ in range(args.repeats):
            started = time.perf_counter()
            ours = fit(MODEL, cases)
            ours_s.append(time.perf_counter() - started)
            started = time.perf_counter()
            plain_cost, plain_evaluations = plain_trf(cases, layout, x0)
            plain_s.append(time.perf_counter() - started)
            started = time.perf_counter()
            explicit(np.ones_like(x0))
            explicit_eval_s.append(time.perf_counter() - started)
        ours_cost = sum_of_squares_um2(ours.residual_um)

        ours_median_s = statistics.median(ours_s)
        rows = [
            ("feedaxis fit (projection + closed form)", ours_median_s, ours_cost, "measured"),
            ("plain TRF, closed form", statistics.median(plain_s), plain_cost,
             f"measured, {plain_evaluations} evaluations")]
        if args.baseline_iterations:
            rows += baseline_rows(explicit, closed, layout, x0, args.baseline_iterations,
                                  statistics.median(explicit_eval_s))
    n = ours.statistics.n_points
    print(f"3 Table 2 cases, {n} samples, 8 parameters; median of {args.repeats} interleaved "
          "repeats where measured\n")
    print(f"{'method':58s} {'wall (s)':>9s} {'cost (um2)':>11s} {'RMS (um)':>9s}  how")
    for label, seconds, cost, how in rows:
        print(f"{label:58s} {seconds:9.2f} {cost:11.2f} {np.sqrt(cost / n):9.4f}  {how}")
    if args.baseline_iterations:
        _, extrapolated_s, baseline_end_cost, _ = rows[-1]
        print(f"\nspeed-up against the baseline run to convergence: "
              f"{extrapolated_s / ours_median_s:.0f}x (target >= 100x); final cost feedaxis / "
              f"baseline {ours_cost / baseline_end_cost:.4f} (<= 1 is the same or better)")
    print(f"against plain TRF on the closed form: {statistics.median(plain_s) / ours_median_s:.1f}x")
    print(f"feedaxis fit times (s): {', '.join(f'{t:.2f}' for t in ours_s)}")
    fitted = ours.params()["thermal_screw"]
    print("identified / true: " + ", ".join(f"{name} {fitted[name] / getattr(TRUTH, name):.3f}"
                                           for name in fitted))


if __name__ == "__main__":
    with threadpool_limits(limits=1, user_api="blas"):
        main()
