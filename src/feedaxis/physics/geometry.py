"""Geometric transmission error of the screw-nut pair.

Sources: Liu 2022 Eq. 1-5 and Liu 2023 (the same study) for the
fitted case-study coefficients. All positions are axis coordinates in mm, all errors in µm
(deviation = actual - nominal, ISO 230-2 sign).
"""
from __future__ import annotations

import numpy as np

from .checks import ParameterError, require_positive, require_representable
from .scalar import clip, interp, table, values, values_and_module

GRAVITY_M_S2 = 9.80665
SUPPORTS = ("fixed-free", "fixed-fixed", "supported-supported")


def lead_error_um(position_mm, offset_um, slope_um_per_mm):
    """Cumulative lead deviation f1(y) = a1*y + b1 (Liu 2023, fitted low-frequency part).

    Parameters
    ----------
    position_mm : array_like
        Axis position y (mm).
    offset_um : float
        b1, deviation at y = 0 (µm).
    slope_um_per_mm : float
        a1, cumulative lead deviation per mm of travel (µm/mm).
    """
    return offset_um + slope_um_per_mm * values(position_mm)


def lead_error_columns(position_mm, out):
    """1 and y written into the two columns of ``out`` (samples x 2): :func:`lead_error_um`
    per unit b1 and per unit a1, with no sample-sized temporary."""
    out[:, 0] = 1.0
    out[:, 1] = position_mm
    return out


def eccentricity_error_um(position_mm, lead_mm, cos_um, sin_um):
    """Assembly eccentricity f2(y) = a2·cos(ωy) + b2·sin(ωy), ω = 2π/lead (Liu 2022 Eq. 1-2).

    The contact point runs on an ellipse once per screw revolution, so the axial error is a
    sinusoid whose wavelength is the lead and whose amplitude hypot(a2, b2) = δ·tanθ.

    Parameters
    ----------
    position_mm : array_like
        Axis position y (mm).
    lead_mm : float
        Screw lead: axial travel per revolution (mm).
    cos_um, sin_um : float
        a2 and b2 (µm).
    """
    require_positive("lead_mm", lead_mm)
    position_mm, xp = values_and_module(position_mm)
    phase_rad = 2.0 * xp.pi * position_mm / lead_mm
    return cos_um * xp.cos(phase_rad) + sin_um * xp.sin(phase_rad)


def eccentricity_columns(position_mm, lead_mm, out):
    """cos(ωy) and sin(ωy), ω = 2π/lead, written into the two columns of ``out`` (samples x
    2): :func:`eccentricity_error_um` per unit a2 and per unit b2 (Liu 2022 Eq. 1-2), the
    same phase, with no sample-sized temporary."""
    require_positive("lead_mm", lead_mm)
    cosine, sine = out[:, 0], out[:, 1]
    np.divide(np.multiply(2.0 * np.pi, position_mm, out=cosine), lead_mm, out=cosine)
    np.sin(cosine, out=sine)
    np.cos(cosine, out=cosine)
    return out


def screw_line_load_N_per_m(diameter_m, density_kg_m3):
    """Weight per unit length q = ρ·g·πD²/4 of a solid screw (Liu 2022 Eq. 3)."""
    require_positive("diameter_m", diameter_m)
    require_positive("density_kg_m3", density_kg_m3)
    return density_kg_m3 * GRAVITY_M_S2 * np.pi * diameter_m**2 / 4.0


def second_moment_m4(diameter_m):
    """Area moment of inertia I = πD⁴/64 of a solid round screw (m⁴)."""
    require_positive("diameter_m", diameter_m)
    return np.pi * diameter_m**4 / 64.0


def sag_slope(screw_coord_m, length_m, line_load_N_per_m, flexural_rigidity_Nm2, support):
    """Slope w'(y) of the screw bent by its own weight (Euler-Bernoulli beam, Liu 2022 Eq. 3-4).

    Parameters
    ----------
    screw_coord_m : array_like
        Distance y from the fixed (or left) end along the screw (m).
    length_m : float
        Screw length L between supports (m).
    line_load_N_per_m : float
        Distributed weight q (N/m).
    flexural_rigidity_Nm2 : float
        E·I (N·m²).
    support : str
        One of ``"fixed-free"`` (cantilever fixed at y = 0), ``"fixed-fixed"``,
        ``"supported-supported"``.
    """
    y = np.asarray(screw_coord_m, dtype=float)
    L = length_m
    scale = line_load_N_per_m / flexural_rigidity_Nm2
    if support == "fixed-free":
        return scale * y * (3 * L**2 - 3 * L * y + y**2) / 6.0
    if support == "fixed-fixed":
        return scale * y * (L - y) * (L - 2 * y) / 12.0
    if support == "supported-supported":
        return scale * (L**3 - 6 * L * y**2 + 4 * y**3) / 24.0
    raise ParameterError(f"must be one of {SUPPORTS}, got {support!r}", "support")


def gravity_sag_table(length_m, diameter_m, density_kg_m3, youngs_modulus_Pa, support,
                      n_grid=2001):
    """Axial error y_a - y_i of the nut on the sagging screw, tabulated (Liu 2022 Eq. 3-5).

    The nominal travel is the arc length y_i = ∫₀^{y_a} √(1 + w'(y)²) dy of the bent screw,
    so the error y_a - y_i ≤ 0 grows along the screw. Computed from geometry and material
    by the trapezoidal rule, not fitted; for real screw sizes it is of the order of 0.01 µm.

    Parameters
    ----------
    length_m, diameter_m : float
        Screw length between supports and (root) diameter (m).
    density_kg_m3, youngs_modulus_Pa : float
        Material density and Young's modulus.
    support : str
        Bearing arrangement, see :func:`sag_slope`.
    n_grid : int
        Points of the arc-length integration.

    Returns
    -------
    scalar.Table
        Distance from the fixed end (x, m) and the error there (y, µm); evaluate with
        :func:`gravity_sag_error_um`.
    """
    require_positive("length_m", length_m)
    require_positive("youngs_modulus_Pa", youngs_modulus_Pa)
    with np.errstate(over="ignore", under="ignore", invalid="ignore"):  # checked below
        diameter, length = np.float64(diameter_m), np.float64(length_m)  # overflow to inf
        line_load = float(screw_line_load_N_per_m(diameter, density_kg_m3))
        require_representable("the weight per length q = ρ·g·πD²/4 (N/m)", line_load,
                              diameter_m=diameter_m, density_kg_m3=density_kg_m3)
        rigidity = float(youngs_modulus_Pa * second_moment_m4(diameter))
        require_representable("the flexural rigidity E·πD⁴/64 (N·m²)", rigidity,
                              youngs_modulus_Pa=youngs_modulus_Pa, diameter_m=diameter_m)
        grid_m = np.linspace(0.0, length_m, n_grid)
        slope = sag_slope(grid_m, length, line_load, rigidity, support)
        excess = np.sqrt(1.0 + slope**2) - 1.0
        cumulative_excess_m = np.concatenate(
            ([0.0], np.cumsum(0.5 * (excess[1:] + excess[:-1]) * np.diff(grid_m))))
    require_representable("the gravity sag at the far end (m)", cumulative_excess_m[-1], False,
                          length_m=length_m, diameter_m=diameter_m,
                          density_kg_m3=density_kg_m3, youngs_modulus_Pa=youngs_modulus_Pa)
    return table(grid_m, -1e6 * cumulative_excess_m)


def gravity_sag_error_um(screw_coord_m, sag_table):
    """Gravity-sag error (µm) at distances from the fixed end, from :func:`gravity_sag_table`."""
    return interp(screw_coord_m, sag_table)


def backlash_error_um(direction, backlash_um):
    """Reversal error ±B/2 by approach direction, so that x̄↑ - x̄↓ = B (ISO 230-2 reversal).

    Parameters
    ----------
    direction : array_like
        +1 when the position was approached moving in +, -1 moving in -; a value in
        between is the nut inside its play (:func:`play_engagement`), the error B/2 times it.
    backlash_um : float
        Reversal value B (µm).
    """
    return 0.5 * backlash_um * clip(direction, -1.0, 1.0)


def backlash_columns(direction, out):
    """±1/2 by approach direction written into the one column of ``out`` (samples x 1):
    :func:`backlash_error_um` per unit B, with no sample-sized temporary."""
    column = np.clip(values(direction), -1.0, 1.0, out=out[:, 0])
    np.multiply(0.5, column, out=column)
    return out


def play_engagement(engagement, travel_mm, backlash_um):
    """Where the nut sits in its play of width B after the screw travels ``travel_mm``.

    ``engagement`` runs from -1 (against the flank that drives in -) to +1 (in +): a play
    operator of width B. A reversal crosses the play over B of travel, the reversal error
    (:func:`backlash_error_um`) going from +B/2 to -B/2 on the way, so the nanometre creep
    of a settling servo never turns the approach direction, and an overshoot of more than B
    does. With B = 0 the engagement is the sign of the last travel. Scalars (the FMU's
    step).
    """
    if travel_mm == 0.0:
        return engagement
    if backlash_um == 0.0:
        return 1.0 if travel_mm > 0.0 else -1.0
    return clip(engagement + 2e3 * travel_mm / abs(backlash_um), -1.0, 1.0)


def transmission_error_um(position_mm, direction, lead_mm, offset_um, slope_um_per_mm,
                          cos_um, sin_um, backlash_um, sag_um=0.0):
    """Superposed transmission error f_T = f1 + f2 + backlash + sag (Liu 2022 Eq. 10).

    Parameters
    ----------
    position_mm, direction : array_like
        Axis position (mm) and approach direction (±1).
    lead_mm, offset_um, slope_um_per_mm, cos_um, sin_um, backlash_um : float
        See :func:`lead_error_um`, :func:`eccentricity_error_um`, :func:`backlash_error_um`.
    sag_um : array_like
        Gravity-sag error at the same positions, from :func:`gravity_sag_error_um` (µm).
    """
    return (lead_error_um(position_mm, offset_um, slope_um_per_mm)
            + eccentricity_error_um(position_mm, lead_mm, cos_um, sin_um)
            + backlash_error_um(direction, backlash_um)
            + sag_um)
