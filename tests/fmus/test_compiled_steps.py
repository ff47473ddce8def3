"""The compiled steps (physics/fmu_steps.py, called by the host layer without Python) against
the slaves' Python steps: the same FMU through fmpy, once as built and once with its slave
offering no compiled step, on seeded inputs, in every controller mode of the servo, and the
thermal screw's field over steps its compiled step takes and steps it leaves to Python."""
import json
import math
import subprocess
import sys
import zipfile

import numpy as np
import pytest

from feedaxis.physics import fmu_steps
from feedaxis.physics.kernel import shipped_kernel

# One run of an FMU in a fresh process (an FMU's package is imported once per process, so
# the two builds of one FMU cannot share one): parameters set before initialisation, the
# inputs stepped (each step its size), a tunable parameter changed, a state saved halfway,
# serialised and restored, and a last step with a NaN input; prints the outputs, statuses
# and log.
RUN = """
import json, math, sys
import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave
plan = json.loads(sys.argv[2])
description = read_model_description(sys.argv[1])
refs = {v.name: v for v in description.modelVariables}
slave = FMU2Slave(guid=description.guid, unzipDirectory=extract(sys.argv[1]),
                  modelIdentifier=description.coSimulation.modelIdentifier,
                  instanceName="compiled", fmiCallLogger=None)
slave.instantiate(loggingOn=True, callbacks=None)
def set_values(values):
    for name, value in values.items():
        variable = refs[name]
        if variable.type == "Real":
            slave.setReal([variable.valueReference], [float(value)])
        elif variable.type == "Boolean":
            slave.setBoolean([variable.valueReference], [bool(value)])
        elif variable.type == "Integer":
            slave.setInteger([variable.valueReference], [int(value)])
        else:
            slave.setString([variable.valueReference], [str(value)])
set_values(plan["parameters"])
slave.setupExperiment(startTime=0.0)
slave.enterInitializationMode()
slave.exitInitializationMode()
outputs = [refs[name].valueReference for name in plan["outputs"]]
n = len(next(iter(plan["inputs"].values())))
sizes = plan.get("step_sizes_s") or [plan["step_size_s"]] * n
times = [sum(sizes[:k]) for k in range(n + 1)]
rows = []
def advance(first, last):
    for k in range(first, last):
        if k == plan["tune_at"]:
            set_values(plan["tuned"])
        set_values({name: values[k] for name, values in plan["inputs"].items()})
        slave.doStep(times[k], sizes[k])
        rows.append(slave.getReal(outputs))
exchanges = []  # the slave's exchange function entered (Python stepping)
sys.setprofile(lambda frame, event, arg: exchanges.append(1) if event == "call"
               and frame.f_code.co_filename.endswith(" exchange>") else None)
advance(0, n // 2)
saved = slave.getFMUstate()
advance(n // 2, n)
slave.setFMUstate(slave.deSerializeFMUstate(slave.serializeFMUstate(saved)))
advance(n // 2, n)
def refused(call, *args):
    try:
        call(*args)
    except Exception as error:
        return str(error)
    return "OK"
sys.setprofile(None)
statuses = [refused(slave.doStep, times[n], 0.0)]
slave.setFMUstate(saved)  # out of the error state
statuses.append(refused(set_values, {name: math.nan for name in plan["inputs"]}))
print(json.dumps({"rows": rows, "statuses": statuses, "exchanges": len(exchanges)}))
"""

SERVO_MODES = {"PID": {}, "NPID": {"nonlinear": True}, "friction": {"friction_N": 20.0},
               "Stribeck": {"coulomb_N": 10.0, "static_N": 25.0, "damping_N_s_per_mm": 0.02},
               "cascade": {"controller": "cascade"}}
OUTPUTS = {"NpidServo": ["position_mm", "velocity_mm_s", "tracking_error_mm", "control_V"],
           "StepperError": ["error_um"], "GeometricError": ["error_um"],
           "ThermalScrew": ["error_um", "elongation_um", "peak_rise_K"]}


def seeded_inputs(name, n, seed=35):
    """Random but reproducible inputs for FMU ``name`` over ``n`` steps."""
    rng = np.random.default_rng(seed)
    walk = np.cumsum(rng.normal(0.0, 0.05, n))
    if name == "NpidServo":
        return {"position_ref_mm": 3.0 * np.sin(np.arange(n) * 0.01) + walk,
                "disturbance_N": rng.normal(0.0, 30.0, n)}
    if name == "StepperError":
        return {"position_mm": 40.0 + walk}
    if name == "ThermalScrew":  # a nut running back and forth at up to 150 mm/s
        position_mm = 250.0 + 240.0 * np.sin(np.arange(n) * 0.05) + 20.0 * walk
        return {"position_mm": position_mm, "velocity_mm_s": 150.0 * np.cos(np.arange(n) * 0.05),
                "ambient_C": 20.0 + 2.0 * np.sin(np.arange(n) * 0.01) + walk}
    return {"position_mm": 60.0 + walk, "velocity_mm_s": np.gradient(walk) / 1e-3}


def python_stepping(fmu_path, name, folder):
    """A copy of the FMU whose slave offers no compiled step (the host layer then steps it
    through the slave's exchange function, as where the compiled module is missing)."""
    copy = folder / f"{name}.fmu"
    slave_file = f"resources/feedaxis_fmu_{name}/{name}.py"
    with zipfile.ZipFile(fmu_path) as source, zipfile.ZipFile(copy, "w") as target:
        for entry in source.infolist():
            data = source.read(entry)
            if entry.filename == slave_file:
                text = data.decode()
                offered = f'return fmu_steps.native_step("{name}")'
                assert offered in text
                data = text.replace(offered, "return None, None").encode()
            target.writestr(entry, data)
    return copy


def run(fmu_path, plan):
    result = subprocess.run([sys.executable, "-c", RUN, str(fmu_path), json.dumps(plan)],
                            capture_output=True, text=True)
    assert result.returncode == 0, result.stderr[-3000:]
    *log, outputs = result.stdout.strip().splitlines()
    return {**json.loads(outputs), "log": log}


CASES = [("NpidServo", mode, parameters, {}) for mode, parameters in SERVO_MODES.items()] + [
    ("StepperError", "harmonics", {"harmonic2_cos_um": 0.03, "error_period_steps": 4,
                                   "position_offset_mm": 12.5}, {"harmonic1_cos_um": 0.2}),
    ("GeometricError", "fixed-fixed", {"backlash_um": 1.5, "support": "fixed-fixed"},
     {"offset_um": 0.7}),
    ("GeometricError", "fixed end at +", {"backlash_um": 0.0, "fixed_end_mm": 300.0,
                                          "position_offset_mm": -20.0},
     {"eccentricity_sin_um": -0.4}),
    ("ThermalScrew", "Table 1", {}, {"reference_ambient_C": 21.5}),
    ("ThermalScrew", "fixed end at +", {"fixed_end_mm": 650.0, "position_offset_mm": 30.0,
                                        "ambient_reference_offset_mm": -12.0,
                                        "k1_W_m2K_per_mm_min": 0.0},
     {"reference_ambient_C": 18.0})]
# the thermal screw's macro step, and a long step every 25 steps at λ = 4000 W/(m.K) (a
# stability limit of 0.044 s): 69 sub-steps, beyond the compiled step's Euler loop, which
# leaves it to the Python step (a matrix power)
STEP_SIZE_S = {"ThermalScrew": 0.1}
LONG_STEP_S, LONG_EVERY = 3.0, 25


@pytest.mark.parametrize("name, mode, parameters, tuned", CASES,
                         ids=[f"{case[0]}-{case[1]}" for case in CASES])
def test_compiled_step_equals_the_python_step_through_fmpy(fmu_paths, tmp_path, name, mode,
                                                           parameters, tuned):
    n = 400
    plan = {"parameters": parameters, "outputs": OUTPUTS[name],
            "step_size_s": STEP_SIZE_S.get(name, 1e-3),
            "inputs": {k: v.tolist() for k, v in seeded_inputs(name, n).items()},
            "tune_at": n // 4, "tuned": tuned}
    compiled = run(fmu_paths[name], plan)
    python = run(python_stepping(fmu_paths[name], name, tmp_path), plan)
    rows, expected = np.array(compiled["rows"]), np.array(python["rows"])
    assert rows.shape == (n + n // 2, len(OUTPUTS[name]))
    assert compiled["exchanges"] == 0 and python["exchanges"] == len(rows)
    assert_same_rows(rows, expected)
    if tuned:  # the tuned parameter reached the compiled step
        half = n // 4
        assert not np.allclose(rows[half:n // 2], run_untuned(fmu_paths[name], plan)[half:n // 2])
    # a step size of 0 (declined by the compiled step, named by the Python one), then, from
    # a restored state, a NaN input (refused where it is set): the same errors from both
    assert compiled["statuses"] == python["statuses"]
    assert all("failed with status 3 (error)" in status for status in compiled["statuses"])
    assert compiled["log"] == python["log"]
    assert any("step size must be finite and > 0" in line for line in compiled["log"])
    assert "must be finite" in compiled["log"][-1]


@pytest.mark.parametrize("name", ["StepperError", "GeometricError", "ThermalScrew"])
def test_a_module_that_does_not_load_is_a_warning_and_the_python_step(fmu_paths, tmp_path,
                                                                       name):
    """An FMU moved to a Python whose ABI its compiled module does not fit: the import
    fails, the FMU says so once (logStatusWarning) and steps in Python, same results."""
    broken = tmp_path / f"{name}.fmu"
    with zipfile.ZipFile(fmu_paths[name]) as source, zipfile.ZipFile(broken, "w") as fmu:
        for entry in source.infolist():
            data = source.read(entry)
            fmu.writestr(entry, b"not a library" if "step_kernel" in entry.filename else data)
    plan = {"parameters": {}, "outputs": OUTPUTS[name],
            "step_size_s": STEP_SIZE_S.get(name, 1e-3), "tune_at": -1,
            "tuned": {}, "inputs": {k: v.tolist() for k, v in seeded_inputs(name, 100).items()}}
    python, compiled = run(broken, plan), run(fmu_paths[name], plan)
    assert python["exchanges"] == len(python["rows"]) and compiled["exchanges"] == 0
    np.testing.assert_allclose(python["rows"], compiled["rows"], rtol=1e-12, atol=1e-15)
    warnings = [line for line in python["log"] if "the compiled step does not load" in line]
    assert len(warnings) == 1 and warnings[0].startswith("[WARNING]")


def assert_same_rows(rows, expected):
    """The outputs within 1e-12 of each other (relative, or of the output's largest value)."""
    scale = np.abs(expected).max(axis=0)
    assert (scale > 0).all(), "an output never moves: the case tests nothing"
    np.testing.assert_allclose(rows, expected, rtol=1e-12, atol=1e-12 * scale.max())


def test_thermal_steps_the_compiled_step_leaves_go_through_python(fmu_paths, tmp_path):
    """Steps needing more sub-steps than the compiled Euler loop takes are declined and taken
    by the Python step (from the same field); the compiled steps after them go on from its
    field: the same outputs as Python alone."""
    n = 400
    sizes = [LONG_STEP_S if k % LONG_EVERY == LONG_EVERY - 1 else 0.1 for k in range(n)]
    plan = {"parameters": {"conductivity_W_mK": 4000.0}, "outputs": OUTPUTS["ThermalScrew"],
            "step_sizes_s": sizes, "tune_at": n // 4, "tuned": {"reference_ambient_C": 23.0},
            "inputs": {k: v.tolist() for k, v in seeded_inputs("ThermalScrew", n).items()}}
    compiled = run(fmu_paths["ThermalScrew"], plan)
    python = run(python_stepping(fmu_paths["ThermalScrew"], "ThermalScrew", tmp_path), plan)
    long_steps = [k for k in [*range(n), *range(n // 2, n)] if sizes[k] == LONG_STEP_S]
    assert compiled["exchanges"] == len(long_steps) == 24
    assert python["exchanges"] == len(python["rows"])
    assert_same_rows(np.array(compiled["rows"]), np.array(python["rows"]))
    assert compiled["log"] == python["log"] and compiled["statuses"] == python["statuses"]


def run_untuned(fmu_path, plan):
    return np.array(run(fmu_path, {**plan, "tuned": {}})["rows"])


def test_feedaxis_own_physics_has_no_compiled_module():
    """Only an FMU's copy of the physics carries the module: feedaxis's own reports none
    (absent, not failed), so the fit and the CLI never depend on it."""
    assert shipped_kernel() == (None, None)
    assert fmu_steps.native_step("NpidServo") == (None, None)


def test_every_compiled_step_is_in_the_fmus_module(fmu_paths):
    """The four FMUs of the axis carry the compiled module with their C
    step exported under its symbol."""
    for name, symbol in fmu_steps.STEPS.items():
        with zipfile.ZipFile(fmu_paths[name]) as archive:
            kernels = [n for n in archive.namelist() if "/physics/step_kernel" in n]
            assert len(kernels) == 1
            assert symbol.encode() in archive.read(kernels[0])


@pytest.fixture(scope="module")
def kernel_library(compiled_servo_loop):
    """The compiled module as a C library (its steps' symbols)."""
    import ctypes

    from feedaxis import kernel_build
    from feedaxis.toolchain import cache_root

    return ctypes.CDLL(str(kernel_build.cached_kernel(cache_root())))


def block_call(library, symbol, block, step_size_s, inputs, n_outputs):
    """(returned value, block after, outputs) of the C step ``symbol``."""
    import ctypes

    function = getattr(library, symbol)
    function.restype = ctypes.c_int32
    numbers = (ctypes.c_double * len(block))(*block)
    given = (ctypes.c_double * len(inputs))(*inputs)
    outputs = (ctypes.c_double * n_outputs)()
    done = function(numbers, ctypes.c_double(step_size_s), given, outputs)
    return done, list(numbers), list(outputs)


def servo_block(**parameters):
    from feedaxis.physics import servo

    params = servo.ServoParams(**parameters)
    loop = servo.Servo(params, initial_reference_mm=1.0)
    loop.advance(0.05, 2.0, 10.0)  # a state away from rest
    return fmu_steps.npid_servo_block(0.5, params, 1000, servo.loop_coefficients(params),
                                      loop.state()), loop


@pytest.mark.parametrize("step_size_s, inputs", [(1e-3, [math.nan, 0.0]),
                                                  (1e-3, [0.0, math.inf]), (0.0, [1.0, 0.0]),
                                                  (-1e-3, [1.0, 0.0]), (math.inf, [1.0, 0.0]),
                                                  (2.0, [1.0, 0.0])])
def test_a_declined_servo_step_leaves_its_block_as_it_was(kernel_library, step_size_s, inputs):
    """Declined (an input not finite, a step size not > 0 and finite, more internal steps
    than allowed): 0 and the block unchanged, for the Python step to take from there."""
    block, _ = servo_block(nonlinear=True)
    done, after, _ = block_call(kernel_library, fmu_steps.STEPS["NpidServo"], block,
                                step_size_s, inputs, 4)
    assert done == 0 and after == block


def test_the_compiled_servo_step_advances_as_the_servo(kernel_library):
    """Step by step, the compiled step's outputs and state equal Servo.advance's (the loop
    compiled ahead of time there too) and Servo.state after it."""
    block, loop = servo_block(friction_N=15.0)
    rng = np.random.default_rng(7)
    for h in rng.uniform(2e-4, 3e-3, 50):  # whole internal steps and carried remainders
        reference, force = rng.normal(2.0, 1.0), rng.normal(0.0, 20.0)
        done, block, outputs = block_call(kernel_library, fmu_steps.STEPS["NpidServo"], block,
                                          h, [reference - 0.5, force], 4)
        loop.advance(h, reference, force)
        position, velocity, error, control = loop.outputs()
        assert done == 1
        assert outputs == [position - 0.5, velocity, error, control]
    assert fmu_steps.npid_servo_state(block) == loop.state()


def test_the_compiled_geometric_step_keeps_the_engagement_when_it_declines(kernel_library):
    from feedaxis.physics import geometry

    table = geometry.gravity_sag_table(0.8, 0.034, 7800.0, 2.1e11, "fixed-free")
    block = fmu_steps.geometric_error_block(0.25, 0.0, 1.0, 0.2, -0.5, 0.2, 0.15, 2.0, True,
                                            -141.0, table)
    symbol = fmu_steps.STEPS["GeometricError"]
    assert block_call(kernel_library, symbol, block, 1e-3, [10.0, math.nan], 1)[:2] == (0, block)
    done, after, _ = block_call(kernel_library, symbol, block, 1e-3, [10.0, -100.0], 1)
    assert done == 1 and after[0] == geometry.play_engagement(0.25, -0.1, 2.0)


def thermal_block(**parameters):
    """ThermalScrew's block at a seeded field, its parameters and the field (K)."""
    from feedaxis.physics import thermal

    params = thermal.ThermalScrewParams(**parameters)
    rise_K = np.random.default_rng(3).uniform(0.0, 4.0, params.n_cells)
    return fmu_steps.thermal_screw_block(2.5, 21.0, params.cells, rise_K), params, rise_K


def test_the_thermal_block_holds_the_cell_terms_and_the_field():
    """What the compiled step reads back from the block (the same function, run in Python
    here) is the parameters' CellTerms and the field, number for number."""
    block, params, rise_K = thermal_block(fixed_end_mm=300.0)
    cells, field_K = fmu_steps.thermal_screw_cells(np.array(block), params.n_cells)
    for name, value in params.cells._asdict().items():
        assert np.array_equal(getattr(cells, name), value), name
    assert field_K.tolist() == rise_K.tolist() == fmu_steps.thermal_screw_rise_K(block)


@pytest.mark.parametrize("step_size_s, inputs", [(0.1, [math.nan, 50.0, 20.0]),
                                                  (0.1, [0.0, math.inf, 20.0]),
                                                  (0.1, [0.0, 50.0, -math.inf]),
                                                  (0.1, [1e308, 50.0, 20.0]),
                                                  (0.0, [1.0, 50.0, 20.0]),
                                                  (-0.1, [1.0, 50.0, 20.0]),
                                                  (math.inf, [1.0, 50.0, 20.0]),
                                                  (6.5, [1.0, 50.0, 20.0])])
def test_a_declined_thermal_step_leaves_its_block_as_it_was(kernel_library, step_size_s,
                                                            inputs):
    """Declined (an input or the nut position not finite, a step size not > 0 and finite,
    more than 64 sub-steps of 0.1 s): 0 and the block unchanged."""
    block, _, _ = thermal_block()
    if inputs[0] == 1e308:  # a finite position and offset, an infinite nut position
        block[1] = 1e308
    done, after, _ = block_call(kernel_library, fmu_steps.STEPS["ThermalScrew"], block,
                                step_size_s, inputs, 3)
    assert done == 0 and after == block


def test_the_compiled_thermal_step_advances_as_the_physics(kernel_library):
    """Step by step, the compiled step's field equals thermal.advance's to the bit, and its
    outputs the slave's (thermal_error_um, screw_elongation_um, the peak rise) within 1e-12
    (the elongation's sum: NumPy's pairwise order against a running sum)."""
    from feedaxis.physics import thermal

    block, params, rise_K = thermal_block(conductivity_W_mK=4000.0, fixed_end_mm=641.0)
    rng = np.random.default_rng(11)
    for h in rng.choice([0.02, 0.1, 0.37, 1.0, 2.5], 200):  # 1 to 58 sub-steps of 0.044 s
        position_mm, velocity_mm_s = rng.uniform(-200.0, 900.0), rng.normal(0.0, 80.0)
        ambient_C = rng.normal(21.0, 1.0)
        done, block, outputs = block_call(kernel_library, fmu_steps.STEPS["ThermalScrew"], block,
                                          h, [position_mm, velocity_mm_s, ambient_C], 3)
        rise_K = thermal.advance(params, rise_K, h, 2.5 + position_mm, velocity_mm_s * 60.0)
        expected = [thermal.thermal_error_um(params, rise_K, 2.5 + position_mm, ambient_C - 21.0),
                    thermal.screw_elongation_um(params, rise_K, params.length_m), rise_K.max()]
        assert done == 1
        assert fmu_steps.thermal_screw_rise_K(block) == rise_K.tolist()
        np.testing.assert_allclose(outputs, expected, rtol=1e-12, atol=1e-12 * abs(expected[1]))
