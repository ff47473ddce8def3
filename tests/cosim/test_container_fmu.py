"""The axis as one FMU (fmpy container): valid, runs in fmpy and libcosim, equals the master;
in FMI 3.0 too (``export-fmu --fmi 3``), equal to the FMI 2.0 container; each carries and
declares Linux x86-64 alone, the one platform of the FMUs inside.

The container steps all four FMUs at its one step, Jacobi: the servo's outputs are the
master's, the error FMUs see the servo one step late. Both are asserted exactly (1e-9).
"""
import shutil

import numpy as np
import pytest
from fmpy.validation import validate_fmu

from feedaxis.cli import main
from feedaxis.cosim.fmu_runner import run_fmu
from feedaxis.cosim.master import Master
from feedaxis.cosim.system import default_axis
from feedaxis.fmu_build import binaries_platform
from libcosim_driver import simulate_with_libcosim
from test_fmus import assert_carries_one_platform
from test_ssp import ERRORS, PARAMETERS, assert_same

SETS = ("--set", "NpidServo.nonlinear=true", "--set", "GeometricError.backlash_um=2.0",
        "--set", "StepperError.error_period_steps=4")
OUTPUTS = ("NpidServo.position_mm",) + ERRORS + ("ThermalScrew.error_um",)


def export(fmu_paths, folder, *options):
    """``export-fmu`` of the FMUs ``fmu_paths`` with :data:`SETS`; the container's path."""
    path = folder / "axis.fmu"
    fmu_dir = str(next(iter(fmu_paths.values())).parent)
    assert main(["export-fmu", str(path), "--fmus", fmu_dir, *SETS, *options]) == 0
    return path


@pytest.fixture(scope="module")
def container_path(fmu_paths, tmp_path_factory):
    return export(fmu_paths, tmp_path_factory.mktemp("container"))


@pytest.fixture(scope="module")
def fmi3_container_path(fmi3_paths, tmp_path_factory):
    return export(fmi3_paths, tmp_path_factory.mktemp("container3"), "--fmi", "3")


@pytest.mark.parametrize("fmi", (2, 3))
def test_container_fmu_passes_fmpy_validation_and_carries_one_platform(request, fmi):
    """fmpy packs its container binary for Linux, macOS and Windows; the FMUs inside run on
    Linux x86-64 only, and so the container keeps that platform's binary alone."""
    from fmpy import read_model_description

    path = request.getfixturevalue("container_path" if fmi == 2 else "fmi3_container_path")
    assert validate_fmu(str(path)) == []
    assert read_model_description(str(path)).fmiVersion == f"{fmi}.0"
    assert_carries_one_platform(path, binaries_platform(fmi))


def test_fmi3_container_runs_as_the_fmi2_one(container_path, fmi3_container_path):
    """The FMI 3.0 container of the FMI 3.0 FMUs, through fmpy's FMI 3 API: every output the
    FMI 2.0 container gives, to 1e-12."""
    h, n_steps = 1e-3, 300
    inputs = {"position_ref_mm": 40.0 * np.sin(2 * np.pi * 0.5 * np.arange(n_steps) * h),
              "ambient_C": np.full(n_steps, 25.0)}
    runs = [run_fmu(path, h, n_steps, inputs, {}, OUTPUTS)
            for path in (container_path, fmi3_container_path)]
    for name in OUTPUTS:
        np.testing.assert_allclose(runs[1][name], runs[0][name], rtol=0, atol=1e-12)
        assert np.ptp(runs[1][name]) > 0, name


def test_container_variables_keep_the_components_units_and_descriptions(container_path,
                                                                          fmu_paths):
    """Each mapped variable carries the unit and description of the component variable it
    maps to; every unit used is defined."""
    from fmpy import read_model_description

    container = read_model_description(str(container_path))
    components = {name: {v.name: v for v in read_model_description(str(path)).modelVariables}
                  for name, path in fmu_paths.items()}
    defined = {unit.name for unit in container.unitDefinitions}
    checked = 0
    for variable in container.modelVariables:
        component, _, name = variable.name.partition(".")
        declared = components.get(component, {}).get(name)
        if declared is None:
            continue
        assert (variable.unit, variable.description) == (declared.unit, declared.description)
        assert variable.unit is None or variable.unit in defined
        checked += 1
    assert checked == sum(v.causality in ("parameter", "output")
                          for v in container.modelVariables) > 10
    inputs = [v for v in container.modelVariables if v.causality == "input"]
    assert inputs and all(v.unit and v.description for v in inputs)


def test_container_runs_in_fmpy_and_libcosim_like_the_master(container_path, fmu_paths):
    h, n_steps = 1e-3, 600
    inputs = {"position_ref_mm": 40.0 * np.sin(2 * np.pi * 0.5 * np.arange(n_steps) * h),
              "ambient_C": np.full(n_steps, 25.0)}
    in_fmpy = run_fmu(container_path, h, n_steps, inputs, {}, OUTPUTS)
    in_libcosim = simulate_with_libcosim(container_path, h, n_steps, inputs, {}, OUTPUTS)
    system = default_axis().with_parameters(PARAMETERS).with_steps(ThermalScrew=h)
    with Master(system, fmu_paths) as master:
        expected = master.run(n_steps * h, {"position_ref_mm": inputs["position_ref_mm"],
                                            "ambient_C": 25.0})
    for name in OUTPUTS:
        assert_same(in_libcosim[name], in_fmpy[name], name)
    assert_same(in_fmpy["NpidServo.position_mm"], expected["NpidServo.position_mm"][1:],
                "position")
    for name in OUTPUTS[1:]:
        assert_same(in_fmpy[name][1:], expected[name][1:-1], name)


def test_bad_parameter_is_refused_before_writing(fmu_paths, tmp_path, capsys):
    fmu_dir = str(next(iter(fmu_paths.values())).parent)
    assert main(["export-fmu", str(tmp_path / "axis.fmu"), "--fmus", fmu_dir,
                 "--set", "NpidServo.nonlinear=3.5"]) == 2
    assert "NpidServo.nonlinear: Boolean parameter, got 3.5" in capsys.readouterr().err
    assert not list(tmp_path.iterdir())


def test_fmus_of_two_fmi_versions_are_refused_before_writing(fmu_paths, fmi3_paths, tmp_path,
                                                             capsys):
    folder = tmp_path / "mixed"
    folder.mkdir()
    for name, path in fmu_paths.items():
        shutil.copy2(fmi3_paths[name] if name == "ThermalScrew" else path, folder)
    assert main(["export-fmu", str(tmp_path / "axis.fmu"), "--fmus", str(folder)]) == 2
    assert "ThermalScrew.fmu: an FMI 3.0 FMU, and --fmi 2" in capsys.readouterr().err
    assert not (tmp_path / "axis.fmu").exists()


@pytest.mark.parametrize("fmi", ["2", "3"])
def test_fmus_of_another_fmi_version_than_asked_are_refused_before_writing(
        fmu_paths, fmi3_paths, tmp_path, capsys, fmi):
    given = fmi3_paths if fmi == "2" else fmu_paths
    folder = str(next(iter(given.values())).parent)
    assert main(["export-fmu", str(tmp_path / "axis.fmu"), "--fmus", folder, "--fmi", fmi]) == 2
    other = "3.0" if fmi == "2" else "2.0"
    assert f"an FMI {other} FMU, and --fmi {fmi} asks for FMI {fmi}.0" in capsys.readouterr().err
    assert not (tmp_path / "axis.fmu").exists()
