"""Mapping between axis coordinates and the screw, Rong et al. 2023 Eq. 15-16.

P_f (``fixed_end_mm``) is the axis coordinate at which the nut would sit over the fixed end
of the screw. For P_f < 0 the screw coordinate grows with the axis coordinate (Eq. 16),
for P_f > 0 it shrinks and errors change sign (Eq. 15).
"""
from __future__ import annotations

from .scalar import values


def axis_sign(fixed_end_mm):
    """+1 when P_f <= 0 (Rong et al. 2023 Eq. 16), -1 when P_f > 0 (Eq. 15)."""
    return -1.0 if fixed_end_mm > 0 else 1.0


def screw_coordinate_m(position_mm, fixed_end_mm):
    """Distance of the nut from the fixed end (m) at axis coordinate P_x (mm).

    Eq. 16: s = P_x - P_f for P_f <= 0; Eq. 15: s = P_f - P_x for P_f > 0 (the sign of
    :func:`axis_sign`, written out: this runs in every FMU step).
    """
    if fixed_end_mm > 0:
        return (fixed_end_mm - values(position_mm)) * 1e-3
    return (values(position_mm) - fixed_end_mm) * 1e-3
