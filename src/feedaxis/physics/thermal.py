"""Finite-difference thermal model of a ball screw fixed at one end, Rong et al. 2023 Eq. 1-19.

The screw is a 1-D rod of N = L/dx cells (Eq. 4). Heat enters from the fixed-end bearing
(Q_B spread over L_B) and from the nut (Q_N spread over L_N, at the nut's position);
the remaining lateral surface and the free-end face lose heat by convection h to ambient;
the fixed-end face is adiabatic (Eq. 5-9). The state is the temperature rise above ambient,
θ_n = T_n - T_a, so Eq. 10 reads C·dθ_n/dt = conduction + sources - convection.

Two deliberate refinements of Eq. 10, both exact in the paper's limit:
- the nut covers cells by fractional overlap (Eq. 10 uses whole cells), so the nut delivers
  exactly Q_N and the error is a smooth function of the nut position and of P_f;
- a requested step larger than the explicit stability limit is split into sub-steps
  dt ≤ C/|diagonal| (at Table 1 values the limit is 0.31 s, so dt = 0.1 s runs unchanged).

Thermal error: E_n = α θ_n dx (Eq. 11), TE_m cumulative from the fixed end (Eq. 12-14),
axis coordinate mapped through P_f (Eq. 15-16), plus ambient expansion TE_a (Eq. 1).
"""
from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, fields
from functools import cached_property
from typing import NamedTuple

import numpy as np

from .checks import (ParameterError, require_finite, require_non_negative, require_positive,
                     require_representable)
from .mounting import axis_sign, screw_coordinate_m
from .scalar import is_scalar, trailing_axis, values
from .threads import one_blas_thread


class CellTerms(NamedTuple):
    """What the cells of one screw keep whatever the feed and the nut (Eq. 5-10), and the
    parameters a step reads (under their names in :class:`ThermalScrewParams`): the numbers
    the functions of one explicit step take (:func:`advance`, :func:`thermal_error_um` at one
    point). Arrays and floats only: ThermalScrew's compiled step (:mod:`.fmu_steps`)
    rebuilds it from its block of numbers and calls the same functions."""

    lower_m: np.ndarray  # cell start from the fixed end
    upper_m: np.ndarray  # cell end
    bearing_fraction: np.ndarray  # under the fixed-end bearing
    neighbours_W_K: np.ndarray  # conduction to the neighbours per cell (one at either end)
    exposed_area_m2: np.ndarray  # lateral surface not under the bearing (Eq. 7)
    bearing_share: np.ndarray  # dx/L_B on the bearing's cells: the share of Q_B each takes (Eq. 10)
    conductance_W_K: float  # λ·A_s/dx between neighbours
    area_m2: float  # A_s (Eq. 5)
    cell_heat_capacity_J_K: float  # C (Eq. 8)
    length_m: float
    cell_length_m: float
    nut_length_m: float
    time_step_s: float
    k1_W_m2K_per_mm_min: float
    k2_W_m2K: float
    k3_W_per_mm_min: float
    k4_W_per_mm_min: float
    expansion_per_K: float
    fixed_end_mm: float
    ambient_reference_offset_mm: float


# Cells of the finite-difference screw: a 100 m screw (the longest a case may describe) in
# 1 cm cells; the identification's closed form decomposes an N x N matrix.
MAX_CELLS = 10_000
# Sub-steps of one advance(): taken as a matrix power beyond EULER_LOOP_LIMIT, so the cost
# grows with their logarithm; more would be a time step no physics needs.
MAX_SUB_STEPS = 1e12


@dataclass(frozen=True)
class ThermalScrewParams:
    """Screw data (Rong et al. 2023 Table 1) and identified coefficients (Table 3, X axis).

    k1..k4 relate convection and heat flows to the feed speed v in mm/min (Eq. 17-19):
    h = k1·v + k2, Q_B = k3·v, Q_N = k4·v.
    """

    length_m: float = 0.8
    diameter_m: float = 0.034
    density_kg_m3: float = 7800.0
    specific_heat_J_kgK: float = 448.0
    expansion_per_K: float = 11.7e-6
    nut_length_m: float = 0.212
    bearing_length_m: float = 0.03
    cell_length_m: float = 0.01
    time_step_s: float = 0.1
    conductivity_W_mK: float = 566.3
    k1_W_m2K_per_mm_min: float = 0.911e-3
    k2_W_m2K: float = 26.034
    k3_W_per_mm_min: float = 0.904e-3
    k4_W_per_mm_min: float = 0.911e-3
    fixed_end_mm: float = -141.0
    ambient_reference_offset_mm: float = 0.0

    def __post_init__(self):
        for field in fields(self):
            value = getattr(self, field.name)
            if field.name.startswith("k") or field.name.endswith("_mm"):
                require_finite(field.name, value)
            else:
                require_positive(field.name, value)
        for name in ("k1_W_m2K_per_mm_min", "k2_W_m2K", "k3_W_per_mm_min", "k4_W_per_mm_min"):
            require_non_negative(name, getattr(self, name))
        if not 2 <= self.length_m / self.cell_length_m + 0.5 < MAX_CELLS + 1:
            raise ParameterError(f"length_m / cell_length_m must give 2 to {MAX_CELLS} cells, "
                                 f"got {self.length_m} / {self.cell_length_m}", "length_m")
        cell = {"cell_length_m": self.cell_length_m, "diameter_m": self.diameter_m}
        require_representable("the cross-section πD²/4 (m²)", self.area_m2,
                              diameter_m=self.diameter_m)
        require_representable("a cell's heat capacity ρ·c·A·dx (J/K)", self.cell_heat_capacity_J_K,
                              density_kg_m3=self.density_kg_m3,
                              specific_heat_J_kgK=self.specific_heat_J_kgK, **cell)
        require_representable("a cell's conductance λ·A/dx (W/K)",
                              self.conductivity_W_mK * self.area_m2 / self.cell_length_m,
                              conductivity_W_mK=self.conductivity_W_mK, **cell)
        for name in ("bearing_length_m", "nut_length_m"):  # heat sources per cell (Eq. 18-19)
            require_representable(f"dx / {name[:-2]}", self.cell_length_m / getattr(self, name),
                                  **{name: getattr(self, name)}, cell_length_m=self.cell_length_m)

    @property
    def n_cells(self):
        """N = L / dx (Eq. 4)."""
        return int(round(self.length_m / self.cell_length_m))

    @property
    def area_m2(self):
        """Cross-section A_s = πD²/4 (Eq. 5); inf, not OverflowError, beyond a float."""
        return np.pi * self.diameter_m * self.diameter_m / 4.0

    @property
    def cell_heat_capacity_J_K(self):
        """C = ρ·c·A_s·dx of one cell (Eq. 8)."""
        return self.density_kg_m3 * self.specific_heat_J_kgK * self.area_m2 * self.cell_length_m

    @cached_property
    def cells(self):
        """:class:`CellTerms`, computed once per parameter set (the instance is frozen)."""
        n = self.n_cells
        lower_m = np.arange(n) * self.cell_length_m
        upper_m = lower_m + self.cell_length_m
        bearing = _overlap(lower_m, upper_m, self.cell_length_m, 0.0, self.bearing_length_m)
        conductance_W_K = self.conductivity_W_mK * self.area_m2 / self.cell_length_m
        neighbours_W_K = np.full(n, 2.0 * conductance_W_K)
        neighbours_W_K[[0, -1]] = conductance_W_K
        return CellTerms(lower_m, upper_m, bearing, neighbours_W_K,
                         np.pi * self.diameter_m * self.cell_length_m * (1.0 - bearing),
                         self.cell_length_m / self.bearing_length_m * bearing, conductance_W_K,
                         self.area_m2, self.cell_heat_capacity_J_K, self.length_m,
                         self.cell_length_m, self.nut_length_m, self.time_step_s,
                         self.k1_W_m2K_per_mm_min, self.k2_W_m2K, self.k3_W_per_mm_min,
                         self.k4_W_per_mm_min, self.expansion_per_K, self.fixed_end_mm,
                         self.ambient_reference_offset_mm)


def convection_W_m2K(cells, feed_mm_min):
    """h = k1·v + k2 (Eq. 17); ``cells``: :class:`CellTerms`."""
    return cells.k1_W_m2K_per_mm_min * abs(feed_mm_min) + cells.k2_W_m2K


def bearing_heat_W(cells, feed_mm_min):
    """Q_B = k3·v (Eq. 18)."""
    return cells.k3_W_per_mm_min * abs(feed_mm_min)


def nut_heat_W(cells, feed_mm_min):
    """Q_N = k4·v (Eq. 19)."""
    return cells.k4_W_per_mm_min * abs(feed_mm_min)


def bearing_cells(params):
    """Fraction of each cell under the fixed-end bearing, 0 ≤ x ≤ L_B (Eq. 10, second case)."""
    return params.cells.bearing_fraction


def nut_cells(cells, nut_screw_m):
    """Fraction of each cell under the nut centred at ``nut_screw_m`` from the fixed end;
    ``cells``: :class:`CellTerms` (``params.cells``)."""
    half_m = cells.nut_length_m / 2.0
    return _overlap(cells.lower_m, cells.upper_m, cells.cell_length_m, nut_screw_m - half_m,
                    nut_screw_m + half_m)


def averaged_nut_cells(params, from_screw_m, to_screw_m):
    """Time average of :func:`nut_cells` for a nut running back and forth between two points.

    A back-and-forth run at constant speed spends equal time at every point of its path, so
    the average is the mean of the overlap over the path, integrated exactly: the overlap of
    the nut [x - L_N/2, x + L_N/2] with cell [a, b] is g(x + L_N/2) - g(x - L_N/2) with
    g(z) = clip(z - a, 0, b - a), whose antiderivative is (r(z - a)² - r(z - b)²)/2,
    r = max(·, 0).
    """
    if np.isclose(from_screw_m, to_screw_m):
        return nut_cells(params.cells, from_screw_m)
    lower_m, upper_m = params.cells.lower_m, params.cells.upper_m

    def antiderivative(z_m):
        return (np.maximum(z_m - lower_m, 0.0) ** 2 - np.maximum(z_m - upper_m, 0.0) ** 2) / 2.0

    half_m = params.nut_length_m / 2.0
    integral = (antiderivative(to_screw_m + half_m) - antiderivative(from_screw_m + half_m)
                - antiderivative(to_screw_m - half_m) + antiderivative(from_screw_m - half_m))
    return integral / ((to_screw_m - from_screw_m) * params.cell_length_m)


def _overlap(lower_m, upper_m, cell_length_m, start_m, stop_m):
    """Fraction of each cell [lower, upper] inside [start, stop]."""
    overlap_m = np.minimum(upper_m, stop_m) - np.maximum(lower_m, start_m)
    return (overlap_m / cell_length_m).clip(0.0, 1.0)  # the method: half np.clip's cost


def rate_matrix(params, feed_mm_min, nut_fraction):
    """System matrix A (1/s) of dθ/dt = A θ + s, from Eq. 5-10.

    Conduction between neighbours and the convective loss of :func:`convective_loss_W_K`
    on the diagonal. A is symmetric.
    """
    coupling = np.full(params.n_cells - 1, params.cells.conductance_W_K)
    diagonal = (-convective_loss_W_K(params.cells, feed_mm_min, nut_fraction)
                - np.concatenate((coupling, [0.0])) - np.concatenate(([0.0], coupling)))
    return ((np.diag(diagonal) + np.diag(coupling, 1) + np.diag(coupling, -1))
            / params.cell_heat_capacity_J_K)


def convective_loss_W_K(cells, feed_mm_min, nut_fraction):
    """Conductance to ambient per cell (W/K): h on the lateral surface not under the bearing
    or the nut (Eq. 7), plus the free-end face (Eq. 6, n = N); ``cells``: :class:`CellTerms`.

    ``feed_mm_min`` may be an array of steps, ``nut_fraction`` then one row per step.
    """
    h_W_m2K = convection_W_m2K(cells, values(feed_mm_min))
    loss_W_K = trailing_axis(h_W_m2K) * cells.exposed_area_m2 * (1.0 - nut_fraction)
    loss_W_K[..., -1] += h_W_m2K * cells.area_m2
    return loss_W_K


def source_rate(cells, feed_mm_min, nut_fraction):
    """Source vector s (K/s): Q_B/L_B and Q_N/L_N per cell length (Eq. 7, 10, 18, 19);
    one row per step for an array of feeds; ``cells``: :class:`CellTerms`."""
    feed_mm_min = values(feed_mm_min)
    return (trailing_axis(bearing_heat_W(cells, feed_mm_min)) * cells.bearing_share
            + trailing_axis(nut_heat_W(cells, feed_mm_min)) * cells.cell_length_m
            / cells.nut_length_m * nut_fraction) / cells.cell_heat_capacity_J_K


def unit_source_rates(params, feed_mm_min, nut_fraction):
    """Source vectors (K/s) of the bearing and of the nut per unit k3 and k4 (W per mm/min),
    stacked on the first axis: s = k3·s_B + k4·s_N (Eq. 7, 10, 18, 19)."""
    per_cell_W = np.abs(np.asarray(feed_mm_min, dtype=float))[..., None] * params.cell_length_m
    per_unit = np.broadcast_arrays(bearing_cells(params) / params.bearing_length_m,
                                   nut_fraction / params.nut_length_m)
    return np.stack(per_unit) * (per_cell_W / params.cell_heat_capacity_J_K)


def stable_time_step_s(cells, loss_W_K):
    """Largest explicit step keeping every update a convex combination (no overshoot).

    dt ≤ 1 / max|A_nn| = C / max(loss + conduction to the neighbours) for the convective
    loss ``loss_W_K`` (:func:`convective_loss_W_K`), capped by ``cells.time_step_s``
    (``cells``: :class:`CellTerms`).
    """
    return min(cells.time_step_s, cells.cell_heat_capacity_J_K
               / float((loss_W_K + cells.neighbours_W_K).max()))


def euler_step(cells, rise_K, loss_W_K, rate_step_K_J, heat_step_K):
    """One explicit Euler update θ + dt·(A θ + s) of Eq. 10 on the tridiagonal A.

    Parameters
    ----------
    cells : CellTerms
        ``params.cells``.
    rise_K : ndarray
        θ per cell (K).
    loss_W_K : ndarray
        :func:`convective_loss_W_K`.
    rate_step_K_J : float
        dt / C (K/J).
    heat_step_K : ndarray
        dt·s, the source over the step (K).
    """
    flow_W = cells.conductance_W_K * (rise_K[1:] - rise_K[:-1])
    net_W = -loss_W_K * rise_K
    net_W[:-1] += flow_W
    net_W[1:] -= flow_W
    return rise_K + rate_step_K_J * net_W + heat_step_K


# Above this many sub-steps, advance() takes them as one matrix power (bounded cost).
EULER_LOOP_LIMIT = 64


def advance(params, rise_K, duration_s, nut_position_mm, feed_mm_min):
    """Advance the temperature rise over ``duration_s`` with the nut held at one position.

    Explicit Euler updates of Eq. 10, θ ← θ + dt (A θ + s) (:func:`euler_step`, A
    tridiagonal), in equal sub-steps of at most :func:`stable_time_step_s`, so any
    communication step is stable and dt = 0.1 s at Table 1 values is the paper's scheme.

    Parameters
    ----------
    params : ThermalScrewParams
    rise_K : ndarray
        θ_n = T_n - T_a per cell (K).
    duration_s : float
        Time to advance (s), ≥ 0.
    nut_position_mm : float
        Axis coordinate of the nut (mm), mapped through P_f (Eq. 15-16).
    feed_mm_min : float
        Feed speed v (mm/min); its magnitude drives Eq. 17-19.
    """
    require_non_negative("duration_s", duration_s)
    require_finite("nut_position_mm", nut_position_mm)
    require_finite("feed_mm_min", feed_mm_min)
    if duration_s == 0.0:
        return rise_K
    cells = params.cells
    nut_fraction, loss_W_K, sources_K_s, sub_step_s = held_nut_terms(cells, nut_position_mm,
                                                                     feed_mm_min)
    n_sub = sub_steps(duration_s, sub_step_s)
    if n_sub == 0:
        raise ParameterError(f"a step of {duration_s} s needs {duration_s / sub_step_s:.3g} "
                             f"sub-steps of {sub_step_s:.3g} s (time_step_s or the stability "
                             f"limit C / (loss + conduction)), at most {MAX_SUB_STEPS:.0e}",
                             "time_step_s")
    dt_s = duration_s / n_sub
    if n_sub > EULER_LOOP_LIMIT:
        return _euler_steps_by_powers(rate_matrix(params, feed_mm_min, nut_fraction),
                                      sources_K_s, rise_K, dt_s, n_sub)
    return euler_steps(cells, rise_K, loss_W_K, sources_K_s, dt_s, n_sub)


def held_nut_terms(cells, nut_position_mm, feed_mm_min):
    """What :func:`advance` steps with, the nut held at ``nut_position_mm`` (axis, mm) at
    ``feed_mm_min``: (the nut's fraction of each cell, :func:`convective_loss_W_K` (W/K),
    :func:`source_rate` (K/s), :func:`stable_time_step_s` (s)); ``cells``:
    :class:`CellTerms`."""
    nut_fraction = nut_cells(cells, screw_coordinate_m(nut_position_mm, cells.fixed_end_mm))
    loss_W_K = convective_loss_W_K(cells, feed_mm_min, nut_fraction)
    return (nut_fraction, loss_W_K, source_rate(cells, feed_mm_min, nut_fraction),
            stable_time_step_s(cells, loss_W_K))


def sub_steps(duration_s, sub_step_s):
    """How many equal sub-steps of at most ``sub_step_s`` (s) :func:`advance` takes over
    ``duration_s`` (s) > 0: at least one; 0 where more than :data:`MAX_SUB_STEPS` (or no
    finite number) would be needed."""
    if not duration_s / sub_step_s <= MAX_SUB_STEPS:
        return 0
    return max(1, math.ceil(duration_s / sub_step_s - 1e-9))


def euler_steps(cells, rise_K, loss_W_K, sources_K_s, dt_s, n_steps):
    """``n_steps`` explicit Euler updates of ``dt_s`` (s) (:func:`euler_step`) with the
    loss (W/K) and the sources (K/s) held; ``cells``: :class:`CellTerms`."""
    rate_step_K_J, heat_step_K = dt_s / cells.cell_heat_capacity_J_K, dt_s * sources_K_s
    for _ in range(n_steps):
        rise_K = euler_step(cells, rise_K, loss_W_K, rate_step_K_J, heat_step_K)
    return rise_K


def _euler_steps_by_powers(rates, sources, rise_K, dt_s, n_steps):
    """``n_steps`` explicit Euler steps at once: the same recursion as the loop in
    :func:`advance`, as the ``n_steps``-th power of its affine map (repeated squaring, so
    the cost grows with log2(n_steps), not n_steps). Agrees with the loop to rounding."""
    size = rise_K.size
    step_map = np.eye(size + 1)
    step_map[:size, :size] += dt_s * rates
    step_map[:size, size] = dt_s * sources
    return (np.linalg.matrix_power(step_map, n_steps) @ np.append(rise_K, 1.0))[:size]


def _cumulative_elongation_um(params, rise_K):
    """TE_m at the cell boundaries, Σ α θ_i dx from the fixed end (Eq. 11-14), per row (µm)."""
    rise_K = np.atleast_2d(rise_K)
    per_cell_um = params.expansion_per_K * rise_K * params.cell_length_m * 1e6
    return np.concatenate((np.zeros((rise_K.shape[0], 1)), np.cumsum(per_cell_um, axis=1)),
                          axis=1)


def screw_elongation_um(params, rise_K, screw_coord_m):
    """TE_m(x) = Σ α θ_i dx up to x, linear within a cell (Eq. 11-14), in µm.

    ``rise_K`` may be 2-D (time × cells); the result then has one row per time.
    """
    if is_scalar(screw_coord_m) and np.ndim(rise_K) == 1:
        return elongation_at_um(params, rise_K, screw_coord_m)
    cumulative_um = _cumulative_elongation_um(params, rise_K)
    nodes_m = np.arange(params.n_cells + 1) * params.cell_length_m
    x = np.clip(np.asarray(screw_coord_m, dtype=float), 0.0, params.length_m)
    result = np.array([np.interp(x, nodes_m, row) for row in cumulative_um])
    return result[0] if result.shape[0] == 1 else result


def elongation_at_um(params, rise_K, screw_m):
    """:func:`screw_elongation_um` of one field at one point, without arrays: the cells
    below the point in full, the one it is in by its fraction (Eq. 11-14), in µm;
    ``params``: ThermalScrewParams or its :class:`CellTerms`."""
    cells = min(max(screw_m, 0.0), params.length_m) / params.cell_length_m
    lower = min(int(cells), rise_K.size - 1)
    within_K = float(rise_K[:lower].sum()) + min(cells - lower, 1.0) * float(rise_K[lower])
    return params.expansion_per_K * params.cell_length_m * 1e6 * within_K


def sample_elongation_um(params, rise_K, screw_coord_m):
    """TE_m of sample k at ``screw_coord_m[k]`` in field ``rise_K[k]`` (µm), as
    :func:`screw_elongation_um` row by row, vectorised for many samples."""
    cumulative_um = _cumulative_elongation_um(params, rise_K)
    cells = np.clip(np.asarray(screw_coord_m, dtype=float), 0.0, params.length_m) \
        / params.cell_length_m
    lower = np.minimum(np.floor(cells).astype(int), params.n_cells - 1)
    rows = np.arange(cumulative_um.shape[0])
    return (cumulative_um[rows, lower] + (cells - lower)
            * (cumulative_um[rows, lower + 1] - cumulative_um[rows, lower]))


def ambient_error_um(params, position_mm, ambient_delta_K):
    """TE_a = α·ΔT_a·(X - X_ref) in axis coordinates (µm), X_ref = P_f + offset.

    Rong et al. 2023 Eq. 1 writes TE_a = α·ΔT_a·X_N with X_N the axis position: a machine whose
    zero is the screw's fixed end. A screw held in its fixed bearing grows from there, so
    the nut moves by α·ΔT_a·(X - P_f) on either side of it (P_f of either sign, the same
    s = ±(X - P_f) of Eq. 15-16); ``ambient_reference_offset_mm`` moves the reference
    (a scale or a mount that grows too). ``params``: ThermalScrewParams or its
    :class:`CellTerms`.
    """
    reference_mm = params.fixed_end_mm + params.ambient_reference_offset_mm
    return (params.expansion_per_K * values(ambient_delta_K)
            * (values(position_mm) - reference_mm) * 1e3)


def thermal_error_um(params, rise_K, position_mm, ambient_delta_K=0.0):
    """Positioning thermal error TE(P_x) = ±TE_m + TE_a (Rong et al. 2023 Eq. 2, 15, 16), in µm;
    TE_a (:func:`ambient_error_um`) is already in axis coordinates.

    With a 1-D ``rise_K`` (one field) the error at every position; with a 2-D ``rise_K``
    holding one field per sample, the error of sample k at ``position_mm[k]``.
    """
    screw_m = screw_coordinate_m(position_mm, params.fixed_end_mm)
    rise_K = np.asarray(rise_K, dtype=float)
    elongation = (screw_elongation_um if rise_K.ndim == 1 else sample_elongation_um)
    return positioning_error_um(params, elongation(params, rise_K, screw_m), position_mm,
                                ambient_delta_K)


def positioning_error_um(params, elongation_um, position_mm, ambient_delta_K):
    """TE(P_x) = ±TE_m + TE_a (Rong et al. 2023 Eq. 2, 15, 16), in µm, from the screw's
    elongation TE_m at the nut (µm); ``params``: ThermalScrewParams or its
    :class:`CellTerms`."""
    return (axis_sign(params.fixed_end_mm) * elongation_um
            + ambient_error_um(params, position_mm, ambient_delta_K))


@dataclass(frozen=True)
class DutySegment:
    """One row of duty.csv: back-and-forth travel between two points at a feed speed."""

    start_s: float
    duration_s: float
    feed_mm_min: float
    from_mm: float
    to_mm: float

    @property
    def end_s(self):
        return self.start_s + self.duration_s

    def nut_position_mm(self, time_s):
        """Axis position at ``time_s`` for a triangle-wave run starting at ``from_mm``."""
        stroke_mm = self.to_mm - self.from_mm
        speed_mm_s = abs(self.feed_mm_min) / 60.0
        if stroke_mm == 0.0 or speed_mm_s == 0.0:
            return np.full_like(np.asarray(time_s, dtype=float), self.from_mm)
        travelled = speed_mm_s * (np.asarray(time_s, dtype=float) - self.start_s) / abs(stroke_mm)
        fold = np.abs((travelled + 1.0) % 2.0 - 1.0)
        return self.from_mm + stroke_mm * fold


def table2_cycle(feed_mm_min, from_mm=0.0, to_mm=500.0):
    """Rong et al. 2023 Table 2 loading: warm 84 min, cool 42 min, warm 42 min at one feed speed.

    The stroke is not published; 0 to 500 mm is an assumption.
    """
    return [DutySegment(0.0, 84 * 60.0, feed_mm_min, from_mm, to_mm),
            DutySegment(84 * 60.0, 42 * 60.0, 0.0, from_mm, from_mm),
            DutySegment(126 * 60.0, 42 * 60.0, feed_mm_min, from_mm, to_mm)]


@one_blas_thread
def simulate_duty(params, segments, times_s):
    """Temperature rise at ``times_s`` for a duty cycle, in closed form per segment.

    k3·Θ_B + k4·Θ_N from :func:`duty_unit_fields`: the field is linear in Q_B and Q_N
    (Eq. 10, 18, 19).

    Returns
    -------
    ndarray, shape (len(times_s), n_cells)
        θ per cell (K) at each sample time.
    """
    unit_K = duty_unit_fields(params, segments, times_s)
    return params.k3_W_per_mm_min * unit_K[0] + params.k4_W_per_mm_min * unit_K[1]


@one_blas_thread
def duty_unit_fields(params, segments, times_s):
    """Temperature rise per unit k3 and per unit k4 at ``times_s``, in closed form per run.

    Within a segment the nut's heat and shading are averaged over its path
    (:func:`averaged_nut_cells`), which makes the system time-invariant; the explicit
    scheme of Eq. 10 is then evaluated exactly for any number of steps through the
    eigen-decomposition of the symmetric A: θ_k = V (1 + dt·μ)^k Vᵀ (θ_0 - θ*) + θ*.
    Consecutive segments of one feed and one path share A and θ*, so a run of them is one
    such step (the steps of its segments added; :class:`Segments`): the cost follows the
    number of runs, not of segments, and the field is formed at ``times_s`` only.
    Heat enters only through the sources, so the field is k3·Θ_B + k4·Θ_N for any
    k3, k4 (W per mm/min) at fixed k1, k2, λ and P_f.

    Parameters
    ----------
    params : ThermalScrewParams
        k3 and k4 are ignored.
    segments : Segments or sequence of DutySegment
        Consecutive segments starting at t = 0.
    times_s : array_like
        Sample times (s), within the duty span.

    Returns
    -------
    ndarray, shape (2, len(times_s), n_cells)
        Θ_B and Θ_N (K per W/(mm/min)) at each sample time.
    """
    duty = Segments.of(segments)
    times_s = np.asarray(times_s, dtype=float)
    modes = [_path_modes(params, *key) for key in duty.keys]
    alternation = _alternation(duty, modes)
    samples = duty.locate(times_s)
    run_start = _run_start_modes(duty, modes, alternation, np.unique(samples.run))
    sample_key = duty.run_key[samples.run]
    dt_s = np.array([mode.dt_s for mode in modes])[sample_key]
    sign = (_range_reduce(np.multiply, alternation, duty.run_first[samples.run], samples.segment)
            * np.cos(np.pi * samples.elapsed_s / dt_s))
    steps = (samples.before_s + samples.elapsed_s) / dt_s
    unit_K = np.zeros((2, times_s.size, params.n_cells))
    for key in np.unique(sample_key):
        mine = np.flatnonzero(sample_key == key)
        mode = modes[key]
        start = np.stack([run_start[r] for r in samples.run[mine]], axis=1)
        unit_K[:, samples.inside[mine]] = (
            (start * _decay(mode, steps[mine], sign[mine])[None]) @ mode.vectors.T
            + mode.steady_K[:, None])
    return unit_K


class PathModes(NamedTuple):
    """Eq. 10 with the nut's heat and shading averaged over one path at one feed, in the
    eigenbasis of its symmetric A: A = V diag(μ) Vᵀ, one explicit step multiplies mode i
    by growth_i = 1 + dt·μ_i, and the field tends to θ* (one row per unit source)."""

    vectors: np.ndarray
    growth: np.ndarray
    steady_K: np.ndarray
    dt_s: float

    @property
    def alternating(self):
        """Modes whose growth is negative (the fastest, zigzag ones, near the stable limit)."""
        return self.growth < 0.0


def _path_modes(params, feed_mm_min, from_mm, to_mm):
    """:class:`PathModes` of a nut running between two axis positions at a feed."""
    path_m = screw_coordinate_m(np.array([from_mm, to_mm]), params.fixed_end_mm)
    nut_fraction = averaged_nut_cells(params, path_m[0], path_m[1])
    rates, vectors = np.linalg.eigh(rate_matrix(params, feed_mm_min, nut_fraction))
    steady_K = -((unit_source_rates(params, feed_mm_min, nut_fraction) @ vectors) / rates) \
        @ vectors.T
    dt_s = stable_time_step_s(params.cells,
                              convective_loss_W_K(params.cells, feed_mm_min, nut_fraction))
    return PathModes(vectors, 1.0 + dt_s * rates, steady_K, dt_s)


def _alternation(duty, modes):
    """cos(π k) of each segment's k = duration / dt steps, the factor :func:`_decay` gives
    the alternating modes over it (1 where its path has none)."""
    cosines = np.ones(len(duty))
    alternating = np.array([mode.alternating.any() for mode in modes])
    segment_key = duty.segment_key
    chosen = np.flatnonzero(alternating[segment_key])
    if chosen.size:
        dt_s = np.array([mode.dt_s for mode in modes])[segment_key[chosen]]
        cosines[chosen] = np.cos(np.pi * duty.duration_s[chosen] / dt_s)
    return cosines


def _run_start_modes(duty, modes, alternation, wanted, block=4096):
    """{run: modal field at its start, (θ_0 - θ*) V per unit source} for the ``wanted``
    runs, advancing the field run by run (one decay per run, :func:`_decay`)."""
    state_K = np.zeros_like(modes[0].steady_K)
    wanted_set, last = set(wanted.tolist()), int(wanted.max(initial=-1))
    run_sign = np.multiply.reduceat(alternation, duty.run_first)
    starts = {}
    for first in range(0, last + 1, block):
        runs = np.arange(first, min(first + block, last + 1))
        decays = _run_decays(duty, modes, run_sign, runs)
        for run, key, decay in zip(runs.tolist(), duty.run_key[runs].tolist(), decays):
            mode = modes[key]
            start = (state_K - mode.steady_K) @ mode.vectors
            if run in wanted_set:
                starts[run] = start
            state_K = (start * decay) @ mode.vectors.T + mode.steady_K
    return starts


def _run_decays(duty, modes, run_sign, runs):
    """Each run's decay of every mode over its whole length (rows of ``runs``)."""
    decays = np.empty((runs.size, modes[0].growth.size))
    keys = duty.run_key[runs]
    for key in np.unique(keys):
        mine = keys == key
        mode = modes[key]
        decays[mine] = _decay(mode, duty.run_duration_s[runs[mine]] / mode.dt_s,
                              run_sign[runs[mine]])
    return decays


def _decay(mode, steps, sign):
    """growth^steps per (span, mode): |growth|^steps, times ``sign`` on the alternating
    modes.

    The stable scheme keeps growth in [-1, 1]; a negative growth (the fastest, zigzag
    modes) alternates in sign, (-1)^k = cos(πk) at whole steps, continued smoothly between
    them so the field stays smooth in the parameters that set dt; over a span of segments
    ``sign`` is the product of their cos(πk) (:func:`_alternation`).
    """
    decay = np.abs(mode.growth)[None, :] ** np.asarray(steps, dtype=float)[:, None]
    decay[:, mode.alternating] *= np.asarray(sign, dtype=float)[:, None]
    return decay


def _range_reduce(ufunc, values, first, stop):
    """``ufunc`` over ``values[first:stop]`` for each pair, its identity where empty;
    ``first <= stop < len(values)``."""
    if first.size == 0:
        return np.zeros(0)
    reduced = ufunc.reduceat(values, np.column_stack((first, stop)).ravel())[::2]
    reduced[first == stop] = ufunc.identity
    return reduced


class SampleSpans(NamedTuple):
    """Where each sample time falls in a duty: the samples ``inside`` a segment, and for
    those their segment, its run, the duration of the run's segments before it (s) and the
    time since the segment's start (s)."""

    inside: np.ndarray
    segment: np.ndarray
    run: np.ndarray
    before_s: np.ndarray
    elapsed_s: np.ndarray


@dataclass(frozen=True, eq=False)
class Segments(Sequence):
    """duty.csv's segments as columns (no object per row); ``segments[i]`` is a
    :class:`DutySegment`. Consecutive segments of the same path at the same speed form a
    run: Eq. 10 advances them as one (:func:`duty_unit_fields`)."""

    start_s: np.ndarray
    duration_s: np.ndarray
    feed_mm_min: np.ndarray
    from_mm: np.ndarray
    to_mm: np.ndarray

    @classmethod
    def of(cls, segments):
        """``segments`` (a sequence of DutySegment) as columns; Segments pass through."""
        if isinstance(segments, cls):
            return segments
        rows = np.array([(s.start_s, s.duration_s, s.feed_mm_min, s.from_mm, s.to_mm)
                         for s in segments], dtype=float).reshape(-1, 5)
        return cls(*(np.ascontiguousarray(column) for column in rows.T))

    def __len__(self):
        return self.start_s.size

    def __getitem__(self, index):
        if isinstance(index, slice):
            return [self[i] for i in range(*index.indices(len(self)))]
        return DutySegment(float(self.start_s[index]), float(self.duration_s[index]),
                           float(self.feed_mm_min[index]), float(self.from_mm[index]),
                           float(self.to_mm[index]))

    @property
    def end_s(self):
        """Where each segment ends (s)."""
        return self.start_s + self.duration_s

    @cached_property
    def _runs(self):
        paths = np.column_stack((np.abs(self.feed_mm_min), self.from_mm, self.to_mm))
        first = np.flatnonzero(np.append(True, (paths[1:] != paths[:-1]).any(axis=1)))
        keys, run_key = np.unique(paths[first], axis=0, return_inverse=True)
        return keys, run_key.ravel(), first

    @property
    def segment_key(self):
        """Each segment's row of :attr:`keys`."""
        return self.run_key[self.segment_run]

    @property
    def keys(self):
        """The distinct (|feed| mm/min, from mm, to mm) of the duty, one row each."""
        return self._runs[0]

    @property
    def run_key(self):
        """Each run's row of :attr:`keys`."""
        return self._runs[1]

    @property
    def run_first(self):
        """Each run's first segment."""
        return self._runs[2]

    @cached_property
    def segment_run(self):
        """The run of each segment."""
        return np.repeat(np.arange(self.run_first.size),
                         np.diff(np.append(self.run_first, len(self))))

    @cached_property
    def run_duration_s(self):
        """Each run's length (s): the sum of its segments' durations."""
        return np.add.reduceat(self.duration_s, self.run_first)

    def locate(self, times_s):
        """:class:`SampleSpans` of ``times_s``: a time belongs to the last segment that
        starts at or before it, if it has not ended by then."""
        segment = np.clip(np.searchsorted(self.start_s, times_s, side="right") - 1, 0, None)
        inside = np.flatnonzero((times_s >= self.start_s[segment])
                                & (times_s <= self.end_s[segment]))
        segment = segment[inside]
        run = self.segment_run[segment]
        return SampleSpans(inside, segment, run,
                           _range_reduce(np.add, self.duration_s, self.run_first[run], segment),
                           times_s[inside] - self.start_s[segment])


@one_blas_thread
def explicit_duty(params, segments, times_s, block=4096):
    """Temperature rise at ``times_s`` by stepping Eq. 10 explicitly with the nut moving.

    The paper's scheme as written: every dt (``params.time_step_s``, reduced if unstable)
    the nut sits where the triangle-wave run of its segment puts it, heats the cells under
    it and shades them from convection. Each sample takes the field of the nearest step.
    A reference for :func:`simulate_duty` and the baseline of the identification benchmark.

    Returns
    -------
    ndarray, shape (len(times_s), n_cells)
    """
    times_s = np.asarray(times_s, dtype=float)
    fastest = max(abs(s.feed_mm_min) for s in segments)
    cells = params.cells
    dt_s = stable_time_step_s(cells, convective_loss_W_K(cells, fastest, np.zeros(params.n_cells)))
    step_times_s = np.arange(int(np.ceil(segments[-1].end_s / dt_s)) + 1) * dt_s
    owner = np.clip(np.searchsorted([s.end_s for s in segments], step_times_s, side="right"),
                    0, len(segments) - 1)
    nut_m = np.empty_like(step_times_s)
    for index, segment in enumerate(segments):
        mine = owner == index
        nut_m[mine] = screw_coordinate_m(segment.nut_position_mm(step_times_s[mine]),
                                         params.fixed_end_mm)
    wanted = np.rint(times_s / dt_s).astype(int)
    samples_at = {k: np.flatnonzero(wanted == k) for k in np.unique(wanted)}
    feed = np.array([segments[i].feed_mm_min for i in owner])
    rate_step_K_J = dt_s / params.cell_heat_capacity_J_K
    rise_K = np.zeros(params.n_cells)
    fields_K = np.zeros((times_s.size, params.n_cells))
    last_step = wanted.max(initial=0)
    for first in range(0, last_step + 1, block):
        steps = np.arange(first, min(first + block, last_step + 1))
        loss_W_K, heat_K_s = _explicit_terms(cells, feed[steps], nut_m[steps])
        for k, loss, heat in zip(steps, loss_W_K, heat_K_s):
            if k in samples_at:
                fields_K[samples_at[k]] = rise_K
            rise_K = euler_step(cells, rise_K, loss, rate_step_K_J, dt_s * heat)
    return fields_K


def _explicit_terms(cells, feed_mm_min, nut_m):
    """Convective loss (W/K) and source rate (K/s) per cell for a block of steps (Eq. 5-10)."""
    nut = nut_cells(cells, nut_m[:, None])
    return convective_loss_W_K(cells, feed_mm_min, nut), source_rate(cells, feed_mm_min, nut)
