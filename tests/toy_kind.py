"""A kind of measurement defined in this one module, as a new engineer would add one: its
samples file (toy.csv: x_mm, deviation_um), its reader, one effect (a slope), its noise,
its figures, its terminal text and its simulated scenario (``feedaxis simulate toy``: the
co-simulated axis driven along a slow ramp). Registered on import, it is also a valid
effects file: ``--effects tests/toy_kind.py`` registers the kind and brings its effect and
its scenario to the command line.
"""
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from feedaxis import kinds
from feedaxis.case import _read_csv
from feedaxis.cosim.master import SimulationInterrupted
from feedaxis.cosim.scenarios.base import Scenario, ScenarioRun, Series, stop_time_s
from feedaxis.effects import Effect, Parameter
from feedaxis.measurement.base import Measurement
from feedaxis.stats.noise import ResidualMeanSquare

TOY_COLUMNS = {"x_mm": True, "deviation_um": True}


@dataclass(frozen=True)
class ToySamples:
    x_mm: np.ndarray
    deviation_um: np.ndarray


def toy_lines(comparison):
    """The figures of ``compare`` on toy samples, for the terminal."""
    return (f"{comparison['samples']} toy samples; model: "
            f"{', '.join(comparison['effects']) or '(none)'}\n"
            f"RMS measured {comparison['rms_measured_um']:.4g} µm, residual "
            f"{comparison['rms_residual_um']:.4g} µm")


def run_ramp(master, length_mm=100.0, points=41, feed_mm_min=600.0, parameters=None,
             progress=None):
    """The axis driven from 0 to ``length_mm`` at ``feed_mm_min``; the deviation (table
    position - reference, µm) at ``points`` evenly spaced reference positions."""
    h = master.system.macro_step_s
    speed_mm_s = feed_mm_min / 60.0
    x_mm = np.linspace(0.0, length_mm, points)
    times_s = np.round((x_mm / speed_mm_s + 1.0) / h) * h   # 1 s standing first

    def reference_mm(t):
        return np.clip((t - 1.0) * speed_mm_s, 0.0, length_mm)

    try:
        rows, stopped = master.run(stop_time_s(times_s[-1], h),
                                   {"position_ref_mm": lambda t: reference_mm(t + h)},
                                   parameters, record_at_s=times_s, progress=progress), ""
    except SimulationInterrupted as interrupted:
        rows, stopped = interrupted.partial, "interrupted: the partial toy.csv is in"
    rows = rows[1:]
    x_mm = reference_mm(rows["time"])
    deviation_um = (rows["table_position_mm"] - x_mm) * 1e3
    figures = {"rms_deviation_um": float(np.sqrt(np.mean(deviation_um ** 2)))}
    return ScenarioRun("simulated toy ramp", parameters or {},
                       {"toy": {"x_mm": x_mm, "deviation_um": deviation_um}}, figures,
                       Series("x_mm", x_mm, "deviation_um", deviation_um, ("ramp",) * x_mm.size),
                       {"samples": int(x_mm.size), **figures}, stopped)


def _ramp_options(parser):
    parser.add_argument("--length-mm", type=float, default=100.0, help="default 100")
    parser.add_argument("--points", type=int, default=41, help="default 41")


RAMP = Scenario("toy", run_ramp, _ramp_options,
                lambda args: {"length_mm": args.length_mm, "points": args.points},
                lambda args, summary: f"{args.out}: {summary['samples']} toy samples",
                help="a slow ramp -> toy.csv")


@kinds.register
class Toy(Measurement):
    """Deviations at positions x, compared with a straight line."""

    kind = "toy"
    file = "toy.csv"
    location_key = "x_mm"
    location_unit = "mm"
    coordinate_label = "x (mm)"
    reference_label = "measured"
    stages = ("effects",)
    measured_column = ("deviation_um", 1.0)
    text = toy_lines
    scenarios = (RAMP,)

    def __init__(self, case):
        super().__init__(case)
        samples = self.samples_of(case)
        self.coordinate = samples.x_mm
        self.measured_um = np.asarray(samples.deviation_um, dtype=float)

    @classmethod
    def read(cls, folder, axis, duty):
        path = Path(folder) / cls.file
        if not path.exists():
            return None
        values, _ = _read_csv(path, TOY_COLUMNS)
        return ToySamples(values["x_mm"], values["deviation_um"])

    @property
    def noise(self):
        return ResidualMeanSquare(np.arange(self.size))

    def subset(self, keep):
        samples = ToySamples(self.coordinate[keep], self.measured_um[keep])
        return Toy(self.case.with_samples(self.kind, samples))

    def figures(self, result):
        return {"kind": self.kind, "samples": self.size, "effects": list(result.model.names),
                "rms_measured_um": float(np.sqrt(np.mean(result.measured_um ** 2))),
                "rms_residual_um": result.rms_um}


class ToySlope(Effect):
    """A deviation growing along x."""

    name = "toy_slope"
    meaning = "a deviation growing linearly along x"
    measurement = "toy"
    parameters = (Parameter("slope_um_per_mm", "um/mm", -100.0, 100.0, "slope"),)
    linear = ("slope_um_per_mm",)

    def unavailable(self, case):
        return "the case has no toy.csv" if not Toy.holds(case) else super().unavailable(case)

    def prepare(self, case):
        x_mm = Toy.samples_of(case).x_mm
        return lambda values: values["slope_um_per_mm"] * x_mm


TOY_SLOPE = ToySlope()
