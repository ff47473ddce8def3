"""A kind of measurement defined in this one module, as a new engineer would add one: its
samples file (toy.csv: x_mm, deviation_um), its reader, one effect (a slope), its noise,
its figures and its terminal text. Registered on import, it is also a valid effects file:
``--effects tests/toy_kind.py`` registers the kind and brings its effect to the command line.
"""
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from feedaxis import kinds
from feedaxis.case import _read_csv
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
