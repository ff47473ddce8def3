"""ISO 230-4 figures of a circular test, as pure functions (a leaf: imports no feedaxis module).

A sample is a nominal angle θ (deg, counted from the first axis towards the second), the
radial deviation d (µm, measured radius − nominal radius, + outside) and the direction
(+1 counter-clockwise, −1 clockwise). The terms of ISO 230-4 (clause 3, "Terms and
definitions", of the 2005 edition, carried into ISO 230-4:2022):

- *radial deviation F*: the deviation of the actual path from the nominal path, the centre
  of the nominal path being found by centring the instrument or as the least-squares
  circle centre (LSC) of the actual path; F_max and F_min are its extremes;
- *circular deviation G*: the minimum radial separation of two concentric circles
  enveloping the actual path; the centre is the LSC, or the centre giving the minimum
  separation (minimum zone, MZC) when so stated. G_ccw and G_cw are those of one direction,
  ``G`` (bidirectional, G(b)) that of both paths together about one centre;
- *circular hysteresis H*: the maximum radial difference between the counter-clockwise
  and the clockwise actual paths.

Here every figure is taken about the least-squares centre: G_ccw and G_cw about the LSC of
their own path, G, F and H about the LSC of both paths together (one centre, so H is not
changed by a centring difference). G, the one figure whose definition allows another
centre, is also given about the minimum-zone centre (:func:`minimum_zone_figures`: G_mz
of both paths about one centre, G_ccw_mz and G_cw_mz each about its own); F and H keep the
LSC (the definitions give no minimum-zone form of them). The LSC is the linearised least-squares circle, exact to first order in d/R
(the deviations are micrometres on a radius of millimetres): d ≈ r + a·cos θ + b·sin θ,
(a, b) the centre's offset, r the mean radius deviation.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class CircularFigures:
    """ISO 230-4 figures (µm) and the least-squares centre offset (µm, along the two axes)
    and mean radius deviation of both directions together."""

    G_um: float
    G_ccw_um: float | None
    G_cw_um: float | None
    H_um: float | None
    F_max_um: float
    F_min_um: float
    center_um: tuple
    radius_um: float

    def as_dict(self):
        return {"G_um": self.G_um, "G_ccw_um": self.G_ccw_um, "G_cw_um": self.G_cw_um,
                "H_um": self.H_um, "F_max_um": self.F_max_um, "F_min_um": self.F_min_um}


def centring_basis(angle_deg):
    """Columns 1, cos θ, sin θ: the mean radius and the centre offset (first order)."""
    theta = np.radians(angle_deg)
    return np.column_stack((np.ones_like(theta), np.cos(theta), np.sin(theta)))


def least_squares_centre(angle_deg, deviation_um):
    """(r, a, b) µm of the linearised least-squares circle d ≈ r + a cos θ + b sin θ."""
    coefficients = np.linalg.lstsq(centring_basis(angle_deg), deviation_um, rcond=None)[0]
    return tuple(float(c) for c in coefficients)


def about_centre(angle_deg, deviation_um, centre):
    """The deviation about the centre ``(r, a, b)``: the centre's offset taken out, the mean
    radius deviation kept (the radial deviation F of ISO 230-4)."""
    _, a, b = centre
    theta = np.radians(angle_deg)
    return deviation_um - a * np.cos(theta) - b * np.sin(theta)


def circular_deviation_um(angle_deg, deviation_um):
    """G (µm) of one path about its own least-squares centre."""
    radial = about_centre(angle_deg, deviation_um, least_squares_centre(angle_deg, deviation_um))
    return float(np.ptp(radial))


def hysteresis_um(angle_ccw_deg, radial_ccw_um, angle_cw_deg, radial_cw_um):
    """H (µm): the largest |CCW − CW| radial difference at the same angle, the clockwise
    path interpolated linearly (periodically) at the counter-clockwise path's angles and
    the other way round."""
    return float(max(np.max(np.abs(radial_ccw_um - _at(angle_ccw_deg, angle_cw_deg,
                                                        radial_cw_um))),
                     np.max(np.abs(radial_cw_um - _at(angle_cw_deg, angle_ccw_deg,
                                                      radial_ccw_um)))))


def _at(angle_deg, known_deg, values):
    order = np.argsort(known_deg)
    return np.interp(angle_deg, known_deg[order], values[order], period=360.0)


def circular_figures(angle_deg, deviation_um, direction):
    """The ISO 230-4 figures of a circular test (see the module's docstring).

    Parameters
    ----------
    angle_deg, deviation_um, direction : array_like
        Nominal angle (deg), radial deviation (µm), +1 CCW / −1 CW, one per sample.

    Returns
    -------
    CircularFigures
        G_ccw, G_cw and H are None when that direction (or one of the two) was not measured.
    """
    angle_deg, deviation_um = np.asarray(angle_deg, float), np.asarray(deviation_um, float)
    direction = np.asarray(direction, float)
    centre = least_squares_centre(angle_deg, deviation_um)
    radial = about_centre(angle_deg, deviation_um, centre)
    ccw, cw = direction > 0, direction < 0
    per_direction = [circular_deviation_um(angle_deg[mask], deviation_um[mask])
                     if mask.sum() >= 3 else None for mask in (ccw, cw)]
    both = ccw.any() and cw.any()
    hysteresis = (hysteresis_um(angle_deg[ccw], radial[ccw], angle_deg[cw], radial[cw])
                  if both else None)
    return CircularFigures(float(np.ptp(radial)), per_direction[0], per_direction[1],
                           hysteresis, float(radial.max()), float(radial.min()),
                           (centre[1], centre[2]), centre[0])


def minimum_zone_um(angle_deg, deviation_um):
    """G (µm) about the minimum-zone centre: the least radial separation of two concentric
    circles enveloping the path over every centre offset (linearised, a linear program:
    minimise u − l subject to l ≤ d_i − a cos θ_i − b sin θ_i ≤ u)."""
    from scipy.optimize import linprog

    theta = np.radians(np.asarray(angle_deg, float))
    d = np.asarray(deviation_um, float)
    c, s, one = np.cos(theta), np.sin(theta), np.ones_like(theta)
    zero = np.zeros_like(theta)
    # variables (a, b, u, l): d - a c - b s <= u  and  l <= d - a c - b s
    upper = np.column_stack((-c, -s, -one, zero))
    lower = np.column_stack((c, s, zero, one))
    solution = linprog([0.0, 0.0, 1.0, -1.0], A_ub=np.vstack((upper, lower)),
                       b_ub=np.concatenate((-d, d)), bounds=[(None, None)] * 4,
                       method="highs")
    if not solution.success:
        raise RuntimeError(f"minimum-zone linear program failed: {solution.message}")
    return float(solution.x[2] - solution.x[3])


def minimum_zone_figures(angle_deg, deviation_um, direction):
    """{G_mz_um, G_ccw_mz_um, G_cw_mz_um}: G about the minimum-zone centre
    (:func:`minimum_zone_um`) of both paths together and of each direction alone (None
    where that direction has fewer than 3 samples)."""
    angle_deg, deviation_um = np.asarray(angle_deg, float), np.asarray(deviation_um, float)
    direction = np.asarray(direction, float)
    per_direction = [minimum_zone_um(angle_deg[mask], deviation_um[mask])
                     if mask.sum() >= 3 else None for mask in (direction > 0, direction < 0)]
    return {"G_mz_um": minimum_zone_um(angle_deg, deviation_um),
            "G_ccw_mz_um": per_direction[0], "G_cw_mz_um": per_direction[1]}


def figures_um(angle_deg, deviation_um, direction):
    """{figure key: µm} about both centres: :func:`circular_figures` and
    :func:`minimum_zone_figures` together (None where a direction is missing)."""
    return {**circular_figures(angle_deg, deviation_um, direction).as_dict(),
            **minimum_zone_figures(angle_deg, deviation_um, direction)}
