"""The contract every catalog effect keeps, checked over the whole catalog.

1. ``linear`` columns reproduce ``prepare``: the fit's variable projection splits the error
   into ``base_um + columns_um @ linear values``; that split must give what ``prepare``
   gives, for every positioning effect, at values drawn inside the bounds.
2. One map of FMU names (``feedaxis.fmu_map``) used both ways: axis.toml -> FMU -> axis.toml
   gives the axis back, and effects/ imports without a cycle.
3. Every FMU parameter an effect writes (and every neutral value of the model's FMU map)
   exists in the built FMU, and each effect parameter reaches its FMU variable as the same
   physical quantity: the units, converted to SI by the FMU's own ``BaseUnit`` on one side
   and by :func:`si` on the other, agree in dimension, and a change of the effect parameter
   changes the FMU variable by the same amount in SI.
"""
import re
import subprocess
import sys

import numpy as np
import pytest
from fmpy import read_model_description

from feedaxis.case import Axis
from feedaxis.cosim.scenarios.base import axis_table
from feedaxis.effects import CATALOG, Model
from feedaxis.fmu_map import AXIS_KEYS, servo_from_fmu, servo_to_fmu
from synthetic import ISO_AXIS, LONG_AXIS, MICRO_AXIS, in_memory_case, iso_layout, thermal_case

# SI dimension exponents (kg, m, s, A, K) and factor of each unit name the catalog uses
BASE = {"kg": ((1, 0, 0, 0, 0), 1.0), "m": ((0, 1, 0, 0, 0), 1.0),
        "mm": ((0, 1, 0, 0, 0), 1e-3), "um": ((0, 1, 0, 0, 0), 1e-6),
        "s": ((0, 0, 1, 0, 0), 1.0), "min": ((0, 0, 1, 0, 0), 60.0),
        "K": ((0, 0, 0, 0, 1), 1.0), "N": ((1, 1, -2, 0, 0), 1.0),
        "W": ((1, 2, -3, 0, 0), 1.0), "J": ((1, 2, -2, 0, 0), 1.0),
        "V": ((1, 2, -3, -1, 0), 1.0), "1": ((0, 0, 0, 0, 0), 1.0)}
TOKEN = re.compile(r"\s*([A-Za-z]+\d*|1|[./()])")


def si(unit):
    """(dimension exponents (kg, m, s, A, K), factor to SI) of a unit such as
    ``W/(m2.K)/(mm/min)``: ``.`` multiplies, ``/`` divides (left to right), a trailing
    integer is an exponent."""
    tokens = TOKEN.findall(unit)
    assert "".join(tokens) == unit.replace(" ", ""), f"cannot read unit {unit!r}"
    position = 0

    def atom():
        nonlocal position
        token = tokens[position]
        position += 1
        if token == "(":
            value = product()
            position += 1  # ")"
            return value
        name, power = re.fullmatch(r"([A-Za-z]+|1)(\d*)", token).groups()
        dims, factor = BASE[name]
        power = int(power or 1)
        return np.array(dims) * power, factor ** power

    def product():
        nonlocal position
        dims, factor = atom()
        while position < len(tokens) and tokens[position] in "./":
            operator = tokens[position]
            position += 1
            other_dims, other_factor = atom()
            sign = 1 if operator == "." else -1
            dims, factor = dims + sign * other_dims, factor * other_factor ** sign
        return dims, factor

    return product()


def test_si_reads_compound_units():
    dims, factor = si("W/(m2.K)/(mm/min)")
    assert list(dims) == [1, -1, -2, 0, -1] and factor == pytest.approx(60000.0)
    assert si("N.s/mm")[1] == pytest.approx(1000.0) and list(si("1/s2")[0]) == [0, 0, -2, 0, 0]


def effect_case(name, tmp_path):
    """A case on which the effect ``name`` is available."""
    target_mm, direction, run = iso_layout(n_targets=11, n_runs=2)
    ones = np.ones_like(target_mm)
    if name in ("lead_error", "assembly_eccentricity", "motor_step_error"):
        position_mm = np.linspace(0.0, 5.0, 251)
        return in_memory_case(MICRO_AXIS, target_mm=position_mm, error_um=0 * position_mm)
    if name == "gravity_sag":
        return in_memory_case(LONG_AXIS, target_mm=target_mm, error_um=0 * ones)
    if name == "thermal_screw":
        from feedaxis.case import read_case
        return read_case(thermal_case(tmp_path / "thermal", seed=0))
    return in_memory_case(ISO_AXIS, target_mm=target_mm, error_um=0 * ones, direction=direction,
                          run=run, ambient_C=20.0 + 3.0 * np.linspace(0.0, 1.0, ones.size))


def drawn_values(effect, case, rng):
    """Values inside the bounds: linear ones anywhere within ±10 of their unit, the others
    within ±20 % of the effect's own start from the data."""
    start = effect.guess(case, np.zeros(case.positioning.size))
    values = {}
    for name, (lower, upper) in effect.bounds(case.axis).items():
        if name in effect.linear:
            value = rng.uniform(max(lower, -10.0), min(upper, 10.0))
        else:
            value = start[name] * rng.uniform(0.8, 1.2)
        values[name] = float(np.clip(value, lower, upper))
    return values


POSITIONING = [name for name, e in CATALOG.items() if e.fmu != "NpidServo"]
TRACKING = [name for name, e in CATALOG.items() if e.fmu == "NpidServo"]


@pytest.mark.parametrize("name", POSITIONING)
def test_linear_columns_reproduce_prepare(name, tmp_path):
    effect, rng = CATALOG[name], np.random.default_rng(14)
    case = effect_case(name, tmp_path)
    assert effect.unavailable(case) is None
    evaluate, separate = effect.prepare(case), effect.prepare_separable(case)
    for _ in range(3):
        values = drawn_values(effect, case, rng)
        columns_um = np.full((case.positioning.size, len(effect.linear)), np.nan)
        base_um = separate(values, columns_um)
        base_um = np.zeros(case.positioning.size) if base_um is None else base_um
        linear = np.array([values[p] for p in effect.linear])
        np.testing.assert_allclose(base_um + columns_um @ linear, evaluate(values),
                                   rtol=1e-9, atol=1e-9)
        other = {**values, **{p: values[p] + 1.0 for p in effect.linear}}
        other_base_um = separate(other, np.empty_like(columns_um))
        other_base_um = (np.zeros(case.positioning.size) if other_base_um is None
                         else other_base_um)
        np.testing.assert_allclose(other_base_um, base_um, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("name", TRACKING)
def test_tracking_effects_have_no_linear_parameters(name):
    """The closed loop is not linear in any servo parameter: nothing to project out."""
    assert CATALOG[name].linear == ()


@pytest.fixture(scope="module")
def fmu_variables(fmu_paths):
    """FMU name -> {parameter name: (SI dimensions (kg, m, s, A, K), SI factor) or None}."""
    variables = {}
    for fmu, path in fmu_paths.items():
        description = read_model_description(str(path))
        units = {u.name: u.baseUnit for u in description.unitDefinitions}
        variables[fmu] = {}
        for v in description.modelVariables:
            if v.causality != "parameter":
                continue
            unit = units.get(v.unit or (v.declaredType.unit if v.declaredType else None))
            variables[fmu][v.name] = None if unit is None else (
                np.array([unit.kg, unit.m, unit.s, unit.A, unit.K]), unit.factor)
    return variables


@pytest.mark.parametrize("name", list(CATALOG))
def test_effect_parameters_reach_their_fmu_as_the_same_quantity(name, fmu_variables, tmp_path):
    effect, rng = CATALOG[name], np.random.default_rng(3)
    case = effect_case(name, tmp_path) if name in POSITIONING else None
    axis = case.axis if case else in_memory_case(ISO_AXIS, target_mm=np.zeros(2),
                                                 error_um=np.zeros(2)).axis
    values = drawn_values(effect, case, rng) if case else dict(effect.neutral)
    written = effect.fmu_parameters(axis, values)
    assert set(written) <= {effect.fmu}
    for variable in written.get(effect.fmu, {}):
        assert variable in fmu_variables[effect.fmu], f"{effect.fmu} has no {variable}"
    for parameter in effect.parameters:
        changed = {**values, parameter.name: values[parameter.name] * 1.5 + 0.25}
        after = effect.fmu_parameters(axis, changed)[effect.fmu]
        moved = [v for v in after if after[v] != written[effect.fmu][v]]
        assert moved, f"{name}.{parameter.name} reaches no {effect.fmu} parameter"
        dims, factor = si(parameter.unit)
        for variable in moved:
            fmu_dims, fmu_factor = fmu_variables[effect.fmu][variable]
            assert list(fmu_dims) == list(dims), \
                f"{name}.{parameter.name} [{parameter.unit}] -> {effect.fmu}.{variable}: dimensions"
            delta_si = (changed[parameter.name] - values[parameter.name]) * factor
            assert (after[variable] - written[effect.fmu][variable]) * fmu_factor == \
                pytest.approx(delta_si, rel=1e-12), f"{name}.{parameter.name} -> {variable}: scale"


def test_neutral_fmu_values_exist_in_the_fmus(fmu_variables, tmp_path):
    axes = [effect_case(name, tmp_path).axis for name in ("lead_error", "gravity_sag")]
    axes.append(effect_case("thermal_screw", tmp_path).axis)
    for axis in axes:
        for fmu, parameters in Model().fmu_parameters(axis).items():
            missing = set(parameters) - set(fmu_variables[fmu])
            assert not missing, f"{fmu} lacks {sorted(missing)}"


FULL_AXIS = Axis("full", {"lead_mm": 5.0, "length_m": 0.8, "diameter_m": 0.025,
                          "density_kg_m3": 7850.0, "youngs_modulus_Pa": 2.1e11,
                          "support": "fixed-free", "fixed_end_mm": -120.0,
                          "specific_heat_J_kgK": 460.0, "expansion_per_K": 11.7e-6,
                          "nut_length_m": 0.06, "bearing_length_m": 0.03},
                 {"step_angle_deg": 1.8, "error_period_steps": 4},
                 {"controller": "npid", "kp_V_per_mm": 0.9, "ki_V_per_mm_s": 6e-4,
                  "kd_V_s_per_mm": 0.0, "ko_per_mm": 6.0, "e_max_mm": 0.3,
                  "force_constant_N_per_V": 100.0, "loop_step_s": 1e-4})


def test_the_fmu_map_gives_the_axis_back():
    """axis.toml -> FMU parameters (the model's direction) -> axis.toml (the scenarios')."""
    parameters = Model().fmu_parameters(FULL_AXIS)
    tables = {table: axis_table(table, lambda fmu, keys: {k: parameters[fmu][k] for k in keys})
              for table in AXIS_KEYS}
    assert tables == {"screw": FULL_AXIS.screw, "motor": FULL_AXIS.motor}
    assert servo_from_fmu(servo_to_fmu(FULL_AXIS.servo)) == FULL_AXIS.servo


def test_the_fmu_map_refuses_two_screws():
    parameters = Model().fmu_parameters(FULL_AXIS)
    parameters["StepperError"]["lead_mm"] = 4.0
    with pytest.raises(Exception, match="GeometricError and StepperError disagree on lead_mm"):
        axis_table("screw", lambda fmu, keys: {k: parameters[fmu][k] for k in keys})


@pytest.mark.parametrize("module", ["feedaxis.effects.base", "feedaxis.effects.catalog",
                                    "feedaxis.fmu_map", "feedaxis.measurement.tracking",
                                    "feedaxis.measurement.positioning", "feedaxis.stats.noise"])
def test_modules_import_first_without_a_cycle(module):
    done = subprocess.run([sys.executable, "-c", f"import {module}"], capture_output=True,
                          text=True)
    assert done.returncode == 0, done.stderr



@pytest.mark.parametrize("name", ["lead_error", "backlash", "assembly_eccentricity"])
def test_columns_written_in_place_are_those_of_evaluating_the_error(name, tmp_path):
    """An effect that writes its columns itself (no sample-sized temporaries) gives, to
    the bit, the columns the default split takes from evaluating its error (at 0 and at 1
    of each linear parameter), and a zero base."""
    from feedaxis.effects.base import Effect

    effect, rng = CATALOG[name], np.random.default_rng(15)
    case = effect_case(name, tmp_path)
    values = drawn_values(effect, case, rng)
    shape = (case.positioning.size, len(effect.linear))
    own, evaluated = np.full(shape, np.nan), np.full(shape, np.nan)
    assert effect.prepare_separable(case)(values, own) is None
    base_um = Effect.prepare_separable(effect, case)(values, evaluated)
    np.testing.assert_array_equal(own, evaluated)
    np.testing.assert_array_equal(base_um, 0.0)
