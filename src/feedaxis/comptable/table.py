"""The pitch-error table a controller compensates with: table points and, per approach
direction, the deviation (measured − target, µm, ISO 230-2 sign) it removes there.

A controller interpolates linearly between table points and holds the end values beyond
them; :meth:`CompTable.error_um` does the same. The table comes from the fitted model
(:func:`from_model`, only the effects a position table can remove) or from the measured
means at the targets (:func:`from_measurement`, the classical table).
"""
from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ..case import Case
from ..effects import Model
from ..errors import InputError
from ..iso230 import per_target

POSITION_TABLE_EFFECTS = ("lead_error", "assembly_eccentricity", "motor_step_error",
                          "gravity_sag")
DIRECTIONAL_EFFECTS = ("backlash",)
NEVER_IN_TABLE = {
    "thermal_screw": "thermal: it changes with the duty and time, a position table is fixed",
    "ambient_expansion": "thermal: it changes with the ambient temperature, a position "
                         "table is fixed",
}
POINTS_PER_WAVELENGTH = 8
GRID_DECIMALS = 3
DENSE_PER_SPACING = 16
# A model's table has the fewest points whose linear interpolation stays within this of the
# model between them (both directions; before the controller rounds to its unit): a tenth
# of a micrometre, under what laser calibrations resolve (0.4 µm repeatability on the
# shipped example) and a tenth of the finest controller unit of 1 µm
TABLE_TOLERANCE_UM = 0.1
DENSE_CHECK_POINTS = 4001  # positions the lean table is checked at, over its span


@dataclass(frozen=True)
class CompTable:
    """Table points (mm, ascending) and the deviation to remove per direction (µm).

    ``included`` names the model effects in the table, ``excluded`` maps each left-out
    effect to the reason.
    """

    position_mm: np.ndarray
    forward_um: np.ndarray
    reverse_um: np.ndarray
    source: str = "model"
    included: tuple = ()
    excluded: dict = field(default_factory=dict)

    @property
    def size(self):
        return self.position_mm.size

    @property
    def spacing_mm(self):
        """The mean distance between table points (mm)."""
        return _spacing(self.position_mm)

    @property
    def bidirectional(self):
        """True when the two directions differ (a direction-dependent table is needed)."""
        return not np.allclose(self.forward_um, self.reverse_um, atol=1e-9)

    def error_um(self, position_mm, direction):
        """The deviation the table removes at ``position_mm`` approached in ``direction``:
        linear interpolation between points per direction, end values held beyond them."""
        position_mm = np.asarray(position_mm, dtype=float)
        forward = np.interp(position_mm, self.position_mm, self.forward_um)
        reverse = np.interp(position_mm, self.position_mm, self.reverse_um)
        return np.where(np.asarray(direction) < 0, reverse, forward)


def grid_mm(first_mm, last_mm, spacing_mm):
    """Equidistant table points from ``first_mm`` covering ``last_mm`` (rounded to 1 µm)."""
    spacing_mm = round(float(spacing_mm), GRID_DECIMALS)
    if not spacing_mm > 0:
        raise InputError("must be > 0 (and at least 0.001 mm)", parameter="--spacing-mm")
    count = int(np.ceil(round((last_mm - first_mm) / spacing_mm, 9))) + 1
    return np.round(round(first_mm, GRID_DECIMALS) + spacing_mm * np.arange(max(count, 2)),
                    GRID_DECIMALS)


def default_spacing_mm(case, max_points, span_mm=None):
    """Lead / 8 (a once-per-revolution error followed between points), widened to fit
    ``max_points`` over ``span_mm`` (default: the measured travel)."""
    span_mm = np.ptp(case.positioning.target_mm) if span_mm is None else span_mm
    spacing_mm = case.axis.lead_mm / POINTS_PER_WAVELENGTH
    if max_points:
        spacing_mm = max(spacing_mm, span_mm / (max_points - 2))
    return float(np.ceil(spacing_mm * 10**GRID_DECIMALS) / 10**GRID_DECIMALS)


@dataclass(frozen=True)
class LeanTable:
    """The fewest-point table of a model within a tolerance (:func:`lean_table`)."""

    table: CompTable
    tolerance_um: float
    deviation_um: float  # the largest |model − table| between the points, both directions
    reached: bool  # False: the point limit stopped the search above the tolerance


def interpolation_deviation_um(case, model, table, dense_mm):
    """The largest |model − table| (µm) at ``dense_mm``, both directions, over the
    position effects of ``model`` (what the table is meant to reproduce)."""
    return max(float(np.max(np.abs(position_error_um(case, model, dense_mm, direction)
                                   - table.error_um(dense_mm, direction))))
               for direction in (1.0, -1.0))


def lean_table(case, model, grid, max_count, span_mm, tolerance_um=TABLE_TOLERANCE_UM):
    """The table of ``model`` with the fewest points (``grid(count)`` gives the points for a
    count, under the controller's grid rules) whose linear interpolation reproduces it within
    ``tolerance_um`` over ``span_mm`` (first, last), over the effects the densest table
    allowed (``max_count`` points) holds.

    The count is found by doubling from 2, then halving the interval; a linear model needs
    the controller's minimum. When even ``max_count`` points leave more, that table is
    returned with ``reached`` False.
    """
    densest = from_model(case, model, grid(max_count))
    wanted = Model([e for e in model.effects if e.name in densest.included], model.values)
    dense_mm = np.linspace(*span_mm, DENSE_CHECK_POINTS)
    tried = {}

    def within(count):
        table = from_model(case, wanted, grid(count))
        tried[count] = (table, interpolation_deviation_um(case, wanted, table, dense_mm))
        return tried[count][1] <= tolerance_um

    low, high = 1, 2
    while high < max_count and not within(high):
        low, high = high, min(2 * high, max_count)
    if high == max_count and not within(max_count):
        table, deviation = tried[max_count]
        return LeanTable(replace(table, excluded={**densest.excluded, **table.excluded}),
                         tolerance_um, deviation, False)
    while high - low > 1:
        middle = (low + high) // 2
        low, high = (low, middle) if within(middle) else (middle, high)
    table, deviation = tried[high]
    return LeanTable(replace(table, excluded={**densest.excluded, **table.excluded}),
                     tolerance_um, deviation, True)


def _grid_case(case, position_mm, direction):
    """A case at ``position_mm`` (one direction) on ``case``'s axis, for model evaluation."""
    direction = np.full(position_mm.size, float(direction))
    samples = replace(case.positioning, target_mm=position_mm,
                      error_um=np.zeros(position_mm.size), direction=direction, run=None,
                      time_s=None, ambient_C=None, has_direction=True)
    return Case(case.folder, case.axis, {"positioning": samples})


def _effect_on(effect, values, case, position_mm, direction):
    return Model((effect,), {effect.name: values}).predict_um(
        _grid_case(case, position_mm, direction))


def _table_helps(effect, values, case, position_mm):
    """True when linear interpolation between the table points leaves no more of the effect
    (RMS over a dense grid, both directions) than not compensating it at all."""
    dense_mm = np.linspace(position_mm[0], position_mm[-1],
                           (position_mm.size - 1) * DENSE_PER_SPACING + 1)
    before, after = 0.0, 0.0
    for direction in (1.0, -1.0):
        truth_um = _effect_on(effect, values, case, dense_mm, direction)
        at_points_um = _effect_on(effect, values, case, position_mm, direction)
        before += float(np.sum(truth_um ** 2))
        after += float(np.sum((truth_um - np.interp(dense_mm, position_mm, at_points_um)) ** 2))
    return after <= before


def from_model(case, model, position_mm):
    """The table of ``model``'s position-dependent effects at ``position_mm``.

    Lead, eccentricity, motor and sag go into both directions, backlash into the
    direction-dependent part; thermal effects never. A periodic effect whose wavelength the
    table points cannot follow (interpolating it would leave more than it removes) is left
    out and said.
    """
    included, excluded = [], {}
    forward_um = np.zeros(position_mm.size)
    reverse_um = np.zeros(position_mm.size)
    for effect in model.effects:
        values = model.values[effect.name]
        if effect.name in NEVER_IN_TABLE:
            excluded[effect.name] = NEVER_IN_TABLE[effect.name]
            continue
        if effect.name not in POSITION_TABLE_EFFECTS + DIRECTIONAL_EFFECTS:
            excluded[effect.name] = "not a catalog position effect: its dependence on " \
                                    "position alone is unknown"
            continue
        missing = (case.axis.missing("screw", effect.needs.screw_keys)
                   + case.axis.missing("motor", effect.needs.motor_keys))
        if missing:
            raise InputError(f"the model's {effect.name} needs {', '.join(missing)}",
                             path=case.folder / "axis.toml")
        wavelength_mm = effect.wavelength_mm(case.axis)
        if wavelength_mm and not _table_helps(effect, values, case, position_mm):
            excluded[effect.name] = (f"its {wavelength_mm:.4g} mm wavelength is too short for "
                                     f"{_spacing(position_mm):.4g} mm between table points: "
                                     "interpolated, it would add error")
            continue
        forward_um += _effect_on(effect, values, case, position_mm, 1.0)
        reverse_um += _effect_on(effect, values, case, position_mm, -1.0)
        included.append(effect.name)
    return CompTable(position_mm, forward_um, reverse_um, "model", tuple(included), excluded)


def position_error_um(case, model, position_mm, direction):
    """The deviation (µm) at ``position_mm`` in ``direction`` of ``model``'s effects that a
    position table could remove (every catalog position effect and backlash, none left out)."""
    effects = [e for e in model.effects
               if e.name in POSITION_TABLE_EFFECTS + DIRECTIONAL_EFFECTS]
    return Model(effects, model.values).predict_um(_grid_case(case, position_mm, direction))


def _spacing(position_mm):
    """The mean distance between ``position_mm`` (mm)."""
    return float(np.ptp(position_mm) / max(position_mm.size - 1, 1))


def measured_means(positioning):
    """Targets and the mean deviation per direction (µm); one direction measured → both."""
    sides = {}
    for sign in (1.0, -1.0):
        if np.any(positioning.direction == sign):
            target_mm, mean_um, _, _ = per_target(positioning.target_mm, positioning.error_um,
                                                  positioning.direction, sign)
            sides[sign] = (target_mm, mean_um)
    forward = sides.get(1.0, sides.get(-1.0))
    reverse = sides.get(-1.0, forward)
    return forward, reverse


def from_measurement(case, position_mm=None):
    """The classical table: the measured mean deviation per direction, linearly
    interpolated onto ``position_mm`` (default: the measured targets themselves)."""
    (forward_mm, forward_mean), (reverse_mm, reverse_mean) = measured_means(case.positioning)
    if position_mm is None:
        if not np.array_equal(forward_mm, reverse_mm):
            raise InputError("the + and - runs visit different targets; give --spacing-mm "
                             "for a common table", path=case.folder)
        position_mm = forward_mm
    return CompTable(np.asarray(position_mm, dtype=float),
                     np.interp(position_mm, forward_mm, forward_mean),
                     np.interp(position_mm, reverse_mm, reverse_mean), "measurement",
                     ("measured means",), {})
