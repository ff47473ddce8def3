"""The exported .ssp runs unchanged in fmpy.ssp.simulate_ssp and OSP libcosim, like the master.

Both importers use a Jacobi scheme (every FMU steps with the inputs of the previous step);
the master steps in dependency order. The differences are therefore exact shifts, which
the tests assert to 1e-9: see each test.
"""
import zipfile
import xml.etree.ElementTree as ET

import numpy as np
import pytest
from fmpy.ssp.simulation import simulate_ssp

from feedaxis.cosim.master import Master
from feedaxis.cosim.ssp import export_ssp, fmpy_parameter_set
from feedaxis.cosim.system import default_axis
from libcosim_driver import simulate_ssp_with_libcosim

# Non-default values of each type, so the tests see whether the .ssv reached the FMUs.
PARAMETERS = {"NpidServo": {"nonlinear": True}, "GeometricError": {"backlash_um": 2.0},
              "StepperError": {"error_period_steps": 4}}
ERRORS = ("StepperError.error_um", "GeometricError.error_um")
SSC = "http://ssp-standard.org/SSP1/SystemStructureCommon"


@pytest.fixture(scope="module")
def system():
    return default_axis().with_parameters(PARAMETERS)


@pytest.fixture(scope="module")
def ssp_path(system, fmu_paths, tmp_path_factory):
    return export_ssp(tmp_path_factory.mktemp("ssp") / "axis.ssp", system, fmu_paths,
                      step_size_hints=True)


def assert_same(actual, expected, name):
    scale = np.max(np.abs(expected))
    assert scale > 0, f"{name} never moves: the comparison tests nothing"
    np.testing.assert_allclose(actual, expected, rtol=1e-9, atol=1e-9 * scale, err_msg=name)


def test_ssp_holds_structure_parameter_values_and_fmus(ssp_path, system):
    with zipfile.ZipFile(ssp_path) as archive:
        names = set(archive.namelist())
        ssd = archive.read("SystemStructure.ssd").decode()
        servo_values = archive.read("resources/NpidServo.ssv").decode()
    assert names == {"SystemStructure.ssd"} | {f"resources/{c.name}.ssv" for c in system.components} \
        | {f"resources/{c.fmu}.fmu" for c in system.components}
    assert 'xmlns:osp="http://opensimulationplatform.com/SSP/OSPAnnotations"' in ssd
    assert '<osp:FixedStepAlgorithm baseStepSize="0.001"' in ssd
    assert '<osp:StepSizeHint value="0.1"' in ssd
    assert '<ssv:Boolean value="true"' in servo_values
    assert f'name="{system.name}"' in servo_values  # one ParameterSet name for all
    assert '<ssd:DefaultExperiment startTime="0.0" stopTime="1.0"' in ssd
    root = ET.fromstring(ssd)
    declared = {u.get("name") for u in root.iter(f"{{{SSC}}}Unit")}
    used = {r.get("unit") for r in root.iter(f"{{{SSC}}}Real") if r.get("unit")}
    assert used and used <= declared


def test_ssv_value_types_follow_the_fmu(fmu_paths, tmp_path):
    path = export_ssp(tmp_path / "typed.ssp", default_axis().with_parameters(
        {"NpidServo": {"plant_stiffness_per_s2": 0}}), fmu_paths)
    with zipfile.ZipFile(path) as archive:
        values = archive.read("resources/NpidServo.ssv").decode()
    assert '<ssv:Real value="0.0"' in values and "ssv:Integer" not in values


def test_fmpy_simulate_ssp_agrees_with_the_master(ssp_path, system, fmu_paths):
    """fmpy: single rate; the error FMUs lag the servo by one step (Jacobi).

    simulate_ssp drives only system-level connectors, which libcosim refuses, so the inputs
    are constant start values: a 300 N force step at t = 0 moves the axis. Its rows are
    labelled with the step's start time but hold the values at the step's end.
    """
    start_values = {"NpidServo.disturbance_N": 300.0, "ThermalScrew.ambient_C": 25.0}
    result = simulate_ssp(str(ssp_path), stop_time=0.5, step_size=1e-3,
                          parameter_set=fmpy_parameter_set(ssp_path, start_values))
    with Master(system.with_steps(ThermalScrew=1e-3), fmu_paths) as master:
        expected = master.run(0.5, {"disturbance_N": 300.0, "ambient_C": 25.0})
    assert_same(result["NpidServo.position_mm"], expected["NpidServo.position_mm"][1:],
                "position")
    for name in ERRORS + ("ThermalScrew.error_um", "ThermalScrew.elongation_um"):
        assert_same(result[name], expected[name][:-1], name)


def test_libcosim_runs_the_ssp_like_the_master(ssp_path, system, fmu_paths):
    """libcosim: multi-rate from osp:StepSizeHint; error FMUs lag one macro step, the
    thermal screw one of its own steps (100 macro steps): it steps at the start of its
    0.1 s window with the inputs of that instant, the master at the end of the window."""
    h, n_steps = 1e-3, 600
    reference = 40.0 * np.sin(2 * np.pi * 0.5 * np.arange(n_steps) * h)
    result = simulate_ssp_with_libcosim(
        ssp_path, n_steps, {"NpidServo.position_ref_mm": reference,
                            "ThermalScrew.ambient_C": np.full(n_steps, 25.0)}, {},
        ("NpidServo.position_mm",) + ERRORS + ("ThermalScrew.error_um",))
    with Master(system, fmu_paths) as master:
        expected = master.run(n_steps * h, {"position_ref_mm": reference, "ambient_C": 25.0})
    assert_same(result["NpidServo.position_mm"], expected["NpidServo.position_mm"][1:],
                "position")
    for name in ERRORS:
        assert_same(result[name][1:], expected[name][1:-1], name)
    assert_same(result["ThermalScrew.error_um"][199:], expected["ThermalScrew.error_um"][100:-100],
                "thermal error")


def test_fmpy_parameter_set_refuses_string_parameters(system, fmu_paths, tmp_path):
    path = export_ssp(tmp_path / "fixed.ssp",
                      system.with_parameters({"GeometricError": {"support": "fixed-fixed"}}),
                      fmu_paths)
    with pytest.raises(ValueError, match="GeometricError.support: fmpy.ssp.simulate_ssp cannot"):
        fmpy_parameter_set(path)


@pytest.mark.parametrize("parameters, message", [
    ({"NpidServo": {"gain": 1.0}}, "NpidServo: no parameter gain"),
    ({"NpidServo": {"nonlinear": 1.0}}, "NpidServo.nonlinear: Boolean parameter, got 1.0"),
])
def test_bad_parameters_are_refused_before_writing(fmu_paths, tmp_path, parameters, message):
    with pytest.raises(ValueError, match=message):
        export_ssp(tmp_path / "bad.ssp", default_axis().with_parameters(parameters), fmu_paths)
    assert not list(tmp_path.iterdir())
