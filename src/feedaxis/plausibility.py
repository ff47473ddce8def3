"""Warnings, not refusals, where a case is readable but implausible for a machine axis: the
likely unit slip named (deviations in mm, targets in m, positions in µm).

A value beyond any physical axis is refused by the reader (:data:`feedaxis.case.PHYSICAL_RANGE`);
these are values inside those limits that a laser test or a drive trace still cannot give.
Each check takes plain arrays and returns its messages; a kind of measurement runs its own
when it reads its file and :func:`warn_implausible` issues them as
:class:`ImplausibleWarning`.
"""
from __future__ import annotations

import warnings

import numpy as np

from .iso230 import row_groups

# A laser interferometer resolves about 1 nm; a positioning test whose repeat scatter is
# below this is deviations written in mm (µm / 1000).
MIN_SCATTER_UM = 1e-3
# Below a picometre the scatter is rounding: data computed without noise, not a unit slip
ROUNDING_UM = 1e-6
# No machine axis a tracking trace comes from travels 10 m back and forth; positions in µm
# (mm × 1000) do.
MAX_TRACKING_TRAVEL_MM = 1e4
# Friction takes a few per cent of a feed drive's thrust, and ball-screw axes push at most a
# few tens of kN: 5 kN of friction is beyond any; a trace in µm fits about 1000 × the
# friction it has (1 N becomes 1 kN).
MAX_FRICTION_N = 5e3


class ImplausibleWarning(UserWarning):
    """A value a machine axis cannot give: the likely unit slip."""


def replicate_scatter_um(target_mm, direction, error_um):
    """The pooled standard deviation (µm) of the deviations about their (target, direction)
    means; None without replicates."""
    groups = row_groups(target_mm, direction)
    counts = np.bincount(groups)
    freedom = error_um.size - counts.size
    if freedom < 1:
        return None
    means = np.bincount(groups, weights=error_um) / counts
    return float(np.sqrt(np.sum((error_um - means[groups]) ** 2) / freedom))


def positioning_problems(target_mm, direction, error_um, lead_mm):
    """The messages of a positioning test's implausible values (empty when none)."""
    problems = []
    scatter_um = replicate_scatter_um(target_mm, direction, error_um)
    if scatter_um is not None and ROUNDING_UM < scatter_um < MIN_SCATTER_UM:
        problems.append(f"positioning.csv: the deviations scatter {scatter_um * 1e3:.3g} nm "
                        "between repeats, below what a laser resolves: error_um in mm? "
                        "(multiply by 1000)")
    elif scatter_um is None and ROUNDING_UM < np.max(np.abs(error_um)) < MIN_SCATTER_UM:
        problems.append(f"positioning.csv: every deviation is under {MIN_SCATTER_UM * 1e3:g} nm: "
                        "error_um in mm? (multiply by 1000)")
    span_mm = float(np.ptp(target_mm))
    if 0 < span_mm < lead_mm:
        problems.append(f"positioning.csv: the targets span {span_mm:g} mm, less than one "
                        f"screw revolution ({lead_mm:g} mm lead): target_mm in m? "
                        "(multiply by 1000)")
    return problems


def tracking_problems(reference_mm):
    """The messages of a tracking trace's implausible values (empty when none)."""
    travel_mm = float(np.ptp(reference_mm))
    if travel_mm > MAX_TRACKING_TRAVEL_MM:
        return [f"tracking.csv: the reference travels {travel_mm / 1e3:g} m, more than any "
                "axis a trace comes from: positions in µm? (divide by 1000)"]
    return []


def friction_problem(friction_N):
    """The message for a fitted friction force no drive has (None when plausible)."""
    if abs(friction_N) > MAX_FRICTION_N:
        return (f"a friction of {friction_N:.3g} N is beyond any feed drive: tracking.csv "
                "positions in µm? (divide by 1000)")
    return None


def warn_implausible_fit(model):
    """Issue an :class:`ImplausibleWarning` for each fitted force no drive has (a parameter
    in newtons, ``..._N``, beyond ``MAX_FRICTION_N``)."""
    problems = [f"{problem} ({name}.{parameter})" for name in model.names
                for parameter, value in model.values[name].items() if parameter.endswith("_N")
                if (problem := friction_problem(value))]
    for problem in problems:
        warnings.warn(problem, ImplausibleWarning, stacklevel=2)
    return problems


def warn_implausible(problems):
    """Issue each of ``problems`` (a kind's messages) as an :class:`ImplausibleWarning`."""
    for problem in problems:
        warnings.warn(problem, ImplausibleWarning, stacklevel=3)
    return problems
