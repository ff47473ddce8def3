"""Circular tests: the two-axis co-simulation against one axis, and the diagnosis at 2 x 10^4 samples.

Run: ``python benchmarks/bench_circular.py [--repeats 3] [--radius-mm 100] [--samples 20000]``.
In one run, with repeats interleaved, it times

- the machine (two axes, eight FMUs, feedaxis.cosim.machine) driven round one 360° circle
  at 1000 mm/min and a 1 ms macro step, from standing through the 45° lead-in and lead-out
  arcs, end to end (extract, instantiate, every macro step, free);
- one axis (the four FMUs) for the same number of macro steps, driven by the first axis's
  reference;
- ``diagnose`` on a circular case of ``--samples`` samples (half each direction): backlash
  of Y, squareness, and a set-up (centring offset, radius, drift) with 0.1 µm noise.

It prints medians (and ranges), the machine / one-axis ratio (target <= 2.2) and the
diagnosis time (target <= 2 s), wall and CPU: the co-simulation and the diagnosis run on
one thread, so on a shared machine their wall time grows with the load while their CPU time
does not. Each finished repeat and trial prints a line on stderr (the results come at the
end).

Then false alarms and power of the diagnosis on circular cases written from the closed
forms (720 samples per direction, both directions): ``--trials`` nulls of a random set-up
(centring offset up to 5 µm, radius up to 5 µm, drift up to 0.02 µm/s) with white noise
(σ 0.1 µm) and with AR(1) noise in the order taken (ρ 0.9, σ 0.1 µm); a false alarm is any
verdict but ``adequate`` (the family-wise rate is 0.001). Power: the share of trials that
name ``backlash@Y`` first for a backlash B of Y in white noise. Where both axes' ``[servo]``
are given (``--servo-trials``): nulls of the loops' own deviation (the kernel run along the
circle) with a random set-up and white noise, and the power of naming
``coulomb_friction@X`` first for a friction through X's loop (0.005 N: X trails by
0.056 µm each way). Each rate with its 95 % Clopper-Pearson interval.
"""
import argparse
import statistics
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from feedaxis.cosim.circular import run_circular
from feedaxis.cosim.machine import machine_system
from feedaxis.cosim.master import Master
from feedaxis.cosim.system import default_axis
from feedaxis.diagnose import diagnose
from feedaxis.effects import Model
from feedaxis.effects.circular import circular_effects
from feedaxis.fmu_build import build_fmus
from feedaxis.fmu_map import servo_to_fmu
from feedaxis.physics import circle
from feedaxis.physics.circle import CircleInterpolator

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))
from circular_cases import CENTER_MM, RADIUS_MM, circle_columns, synthetic_case  # noqa: E402
sys.path.insert(0, str(Path(__file__).resolve().parent))
from common import arguments, describe, rate  # noqa: E402

FEED_MM_MIN = 1000.0
SERVO = {"controller": "pid", "kp_V_per_mm": 0.8998, "ki_V_per_mm_s": 0.0006077,
         "kd_V_s_per_mm": 0.005155, "force_constant_N_per_V": 100.0, "loop_step_s": 1e-4}


def time_machine(fmu_paths, radius_mm):
    """(wall seconds end to end, CPU seconds of this process, macro steps) of one
    counter-clockwise circle on the machine."""
    system = machine_system()
    started, cpu = time.perf_counter(), time.process_time()
    with Master(system, fmu_paths) as master:
        run_circular(master, radius_mm, FEED_MM_MIN, (radius_mm, radius_mm), directions=(1,),
                     samples_per_turn=360)
        steps = master.timing.macro_steps
    return time.perf_counter() - started, time.process_time() - cpu, steps


def time_one_axis(fmu_paths, radius_mm, steps):
    """(wall, CPU) seconds end to end of one axis for ``steps`` macro steps of the circle's X
    reference."""
    system = default_axis()
    path = CircleInterpolator(radius_mm, FEED_MM_MIN, (radius_mm, radius_mm))
    h = system.macro_step_s
    started, cpu = time.perf_counter(), time.process_time()
    with Master(system, fmu_paths) as master:
        master.run(steps * h, {"position_ref_mm": lambda t: path.position_mm(t + h, 0)},
                   {"NpidServo": circle.MACHINE_PLANT})
    return time.perf_counter() - started, time.process_time() - cpu


def progress(label, done, total):
    """One line on stderr per finished trial or repeat (the results come at the end)."""
    print(f"{label}: {done}/{total}", file=sys.stderr, flush=True)


def diagnosis_case(folder, samples):
    columns = circle_columns(samples // 2)
    angle, direction = columns["angle_deg"], columns["direction"]
    rng = np.random.default_rng(0)
    theta = np.radians(angle)
    deviation = (circle.backlash_um(angle, direction, 1, 3.0, 20.0)
                 + circle.squareness_um(angle, 20.0, 50.0) + 2.0 + 1.5 * np.cos(theta)
                 - 0.5 * np.sin(theta) + 0.01 * columns["time_s"]
                 + rng.normal(0.0, 0.1, angle.size))
    return synthetic_case(folder, deviation, columns)


def time_diagnosis(case):
    """(wall seconds, CPU seconds of this process, the diagnosis)."""
    started, cpu = time.perf_counter(), time.process_time()
    found = diagnose(case, Model(), circular_effects(case.axis), kind="circular")
    return time.perf_counter() - started, time.process_time() - cpu, found


def set_up_um(columns, rng, noise):
    """A random set-up and noise: ``noise`` "white" or "ar1" (ρ 0.9), σ 0.1 µm."""
    theta = np.radians(columns["angle_deg"])
    a, b, r = rng.uniform(-5, 5, 3)
    drift = rng.uniform(-0.02, 0.02)
    white = rng.normal(0.0, 0.1, theta.size)
    if noise == "ar1":
        rho, correlated = 0.9, np.empty_like(white)
        correlated[0] = white[0]
        for i in range(1, white.size):
            correlated[i] = rho * correlated[i - 1] + np.sqrt(1 - rho ** 2) * white[i]
        white = correlated
    return r + a * np.cos(theta) + b * np.sin(theta) + drift * columns["time_s"] + white


def loop_um(columns, friction_N):
    """The radial deviation of both axes' loops (:data:`SERVO`, ``friction_N`` on X) along
    the circle of ``columns``: what the circular kind predicts where [servo] is given."""
    errors = [circle.loop_error_um(circle.servo_params(servo_to_fmu(SERVO),
                                                       {"friction_N": friction_N * (i == 0)}),
                                   columns["angle_deg"], columns["direction"], RADIUS_MM,
                                   FEED_MM_MIN, CENTER_MM, i) for i in (0, 1)]
    return circle.radius_change_um(columns["angle_deg"], RADIUS_MM, *errors)


def servo_rates(folder, trials):
    """{label: (hits, trials)}: nulls where both axes' [servo] are given (the loops' own
    deviation, a random set-up, white noise) and the power of naming Coulomb friction of X
    through its loop first."""
    columns = circle_columns()
    rng = np.random.default_rng(12)
    found = {}
    for label, friction_N in (("servo null, white", 0.0), ("power, 0.005 N on X", 0.005),
                              ("power, 0.01 N on X", 0.01)):
        hits, base_um = 0, loop_um(columns, friction_N)
        for trial in range(trials):
            case = synthetic_case(folder / f"servo-{friction_N}-{trial}",
                                  base_um + set_up_um(columns, rng, "white"), columns,
                                  servo=SERVO)
            _, _, result = time_diagnosis(case)
            progress(label, trial + 1, trials)
            if friction_N:
                hits += (bool(result.candidates)
                         and result.candidates[0].effect == "coulomb_friction@X")
            else:
                hits += result.verdict != "adequate"
        found[label] = (hits, trials)
    return found


def rates(folder, trials):
    """{label: (hits, trials)} of the nulls and the power trials."""
    columns = circle_columns()
    angle, direction = columns["angle_deg"], columns["direction"]
    rng = np.random.default_rng(11)
    found = {}
    plans = [("null, white noise", "white", 0.0), ("null, AR(1) 0.9", "ar1", 0.0),
             ("power, B = 0.03 µm", "white", 0.03), ("power, B = 0.06 µm", "white", 0.06)]
    for label, noise, backlash in plans:
        hits = 0
        for trial in range(trials):
            deviation = (set_up_um(columns, rng, noise)
                         + circle.backlash_um(angle, direction, 1, backlash, 20.0))
            case = synthetic_case(folder / f"{label[:4]}-{noise}-{backlash}-{trial}", deviation,
                                  columns)
            _, _, result = time_diagnosis(case)
            progress(label, trial + 1, trials)
            if backlash:
                hits += bool(result.candidates) and result.candidates[0].effect == "backlash@Y"
            else:
                hits += result.verdict != "adequate"
        found[label] = (hits, trials)
    return found


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--radius-mm", type=float, default=100.0)
    parser.add_argument("--samples", type=int, default=20000)
    parser.add_argument("--trials", type=int, default=100)
    parser.add_argument("--servo-trials", type=int, default=40)
    args = arguments(parser, argv, repeats=1, radius_mm=1.0, samples=400, trials=1,
                     servo_trials=1)
    with tempfile.TemporaryDirectory() as folder:
        fmu_paths = {p.stem: p for p in build_fmus(Path(folder) / "fmus")}
        case = diagnosis_case(Path(folder) / "case", args.samples)
        time_machine(fmu_paths, min(args.radius_mm, 5.0))  # warm-up: first imports
        machine_s, axis_s, diagnose_s, diagnose_cpu_s = [], [], [], []
        machine_cpu_s, axis_cpu_s = [], []
        for repeat in range(args.repeats):
            seconds, cpu_s, steps = time_machine(fmu_paths, args.radius_mm)
            machine_s.append(seconds)
            machine_cpu_s.append(cpu_s)
            seconds, cpu_s = time_one_axis(fmu_paths, args.radius_mm, steps)
            axis_s.append(seconds)
            axis_cpu_s.append(cpu_s)
            seconds, cpu_s, named = time_diagnosis(case)
            diagnose_s.append(seconds)
            diagnose_cpu_s.append(cpu_s)
            progress("timing repeats", repeat + 1, args.repeats)
        found = {**rates(Path(folder), args.trials),
                 **servo_rates(Path(folder), args.servo_trials)}
    ratio = statistics.median(machine_s) / statistics.median(axis_s)
    cpu_ratio = statistics.median(machine_cpu_s) / statistics.median(axis_cpu_s)
    print(f"one circle R {args.radius_mm:g} mm at {FEED_MM_MIN:g} mm/min (45° lead-in and "
          f"lead-out), macro step 1 ms = {steps} macro steps; {args.repeats} interleaved "
          "repeats")
    print(f"  machine, two axes (8 FMUs), end to end : wall {describe(machine_s)}, CPU "
          f"{describe(machine_cpu_s)}")
    print(f"  one axis (4 FMUs), same steps          : wall {describe(axis_s)}, CPU "
          f"{describe(axis_cpu_s)}")
    print(f"  machine / one axis: wall {ratio:.2f}, CPU {cpu_ratio:.2f} (target <= 2.2)")
    print(f"diagnose on {case.circular.size} samples (backlash of Y, squareness, set-up, "
          f"0.1 µm noise): wall {describe(diagnose_s)} (target <= 2 s), CPU "
          f"{describe(diagnose_cpu_s)} (one thread: the wall time of an idle machine); named: "
          f"{', '.join(c.effect for c in named.candidates) or 'none'}, verdict {named.verdict}")
    print("false alarms (any verdict but adequate) and power (backlash@Y, or "
          "coulomb_friction@X through its loop where [servo] is given, named first), 1440 "
          "samples, σ 0.1 µm:")
    for label, (hits, trials) in found.items():
        print(f"  {label:22s}: {rate(hits, trials)}")


if __name__ == "__main__":
    main()
