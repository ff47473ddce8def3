"""The distributions a budget assigns to its input quantities (JCGM 101:2008 §6.4), drawn
for the Monte Carlo and with the standard uncertainty the GUM law of propagation uses.

Each is centred on 0 and set by one size: the half-width ``a`` of a bounded distribution or
the standard uncertainty ``u`` of a normal one.

| name          | JCGM 101 | values                         | standard uncertainty |
|---------------|----------|--------------------------------|----------------------|
| `rectangular` | §6.4.2   | uniform on [-a, a]             | a/√3                 |
| `triangular`  | §6.4.5   | (r1 + r2 - 1)·a, r uniform     | a/√6                 |
| `arcsine`     | §6.4.6   | a·sin(2πr) (U-shaped)          | a/√2                 |
| `normal`      | §6.4.7   | u·z, z standard normal         | u                    |
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

BOUNDED = {"rectangular": math.sqrt(3.0), "triangular": math.sqrt(6.0),
           "arcsine": math.sqrt(2.0)}
DISTRIBUTIONS = (*BOUNDED, "normal")


@dataclass(frozen=True)
class Distribution:
    """A zero-centred distribution: ``kind`` (one of :data:`DISTRIBUTIONS`) and ``size``,
    the half-width (bounded kinds) or the standard uncertainty (normal), in the quantity's
    unit."""

    kind: str
    size: float

    def __post_init__(self):
        if self.kind not in DISTRIBUTIONS:
            raise ValueError(f"unknown distribution {self.kind!r}; known: "
                             f"{', '.join(DISTRIBUTIONS)}")
        if not (math.isfinite(self.size) and self.size >= 0):
            raise ValueError(f"size must be a finite number >= 0, got {self.size!r}")

    @property
    def standard_uncertainty(self):
        """u of the distribution (JCGM 101 §6.4), in the quantity's unit."""
        return self.size if self.kind == "normal" else self.size / BOUNDED[self.kind]

    def sample(self, rng, shape):
        """Values drawn with the generator ``rng``, an array of ``shape``."""
        if self.kind == "normal":
            return self.size * rng.standard_normal(shape)
        if self.kind == "rectangular":
            return self.size * rng.uniform(-1.0, 1.0, shape)
        if self.kind == "triangular":
            return self.size * (rng.random(shape) + rng.random(shape) - 1.0)
        return self.size * np.sin(2.0 * np.pi * rng.random(shape))
