"""The machine of two axes as one SSP, run in FMI importers like ``feedaxis simulate circular``.

The machine (two axes X and Y, each a servo and its geometric error, 50 µrad out of square,
a lead slope on X, backlash on Y) goes round a circle: by the project's master (what
``feedaxis simulate circular`` runs, :func:`feedaxis.cosim.circular.run_path`), by a plain
fmpy loop over the same FMUs (examples/two_axis_circle.py, stepping in dependency order as
the master does), and as the exported .ssp: driven by its CircleInterpolator FMU (what
``export-ssp --machine`` writes) in OSP libcosim, the OMSimulator program and fmpy's
``simulate_ssp``, and with the references left open in OMSimulator's API. The importers step
Jacobi: the interpolator's outputs are one macro step ahead, so the servos get the master's
references; the error FMUs see the servos' outputs of the step before, so their outputs lag
one macro step. The exported machine counts its position connectors from the circle's first
reference (each FMU rebuilds machine positions from its position_offset_mm), so a host that
starts every connector at 0 (fmpy) runs it as one that passes values on at initialisation.
With that accounted for every table position (mm) and the ballbar's radial trace agree
within 1e-9 mm, on a circle about (60, 40) mm.
"""
import csv
import importlib.util
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from fmpy.ssp.simulation import simulate_ssp

from circular_cases import machine
from conftest import FMI_TOOLS, require_tool
from feedaxis.cosim.circular import run_path
from feedaxis.cosim.machine import (INTERPOLATOR_OUTPUTS, first_reference_mm,
                                    interpolator_parameters, machine_from_case_axes,
                                    with_interpolator)
from feedaxis.cosim.master import Master
from feedaxis.cosim.ssp import export_ssp, fmpy_parameter_set
from feedaxis.physics.circle import CircleInterpolator
from libcosim_driver import simulate_ssp_with_libcosim

ROOT = Path(__file__).resolve().parents[2]
OMS_DIR = FMI_TOOLS / "omsimulator"
H_S = 1e-3
# its first reference (the circle at t_1) is (61.74, 39.45) mm, far from the machine's origin
PATH = CircleInterpolator(2.0, 1000.0, (60.0, 40.0), lead_in_deg=30.0, lead_out_deg=10.0)
SERVOS = ("X_NpidServo.position_mm", "Y_NpidServo.position_mm")
ERRORS = ("X_GeometricError.error_um", "Y_GeometricError.error_um")
TOLERANCE_MM = 1e-9


@pytest.fixture(scope="module")
def system():
    return machine_from_case_axes(machine(), squareness_urad=50.0).with_parameters(
        {"X_GeometricError": {"slope_um_per_mm": 0.2},
         "Y_GeometricError": {"backlash_um": 3.0}})


@pytest.fixture(scope="module")
def steps():
    return int(round(PATH.duration_s / H_S))


def references(steps):
    """Each axis's reference, value k held over step k: the circle at t_{k+1}."""
    t_next = (np.arange(steps) + 1) * H_S
    return {axis: PATH.position_mm(t_next, index) for index, axis in enumerate(("X", "Y"))}


@pytest.fixture(scope="module")
def master_rows(system, fmu_paths, steps):
    reference = references(steps)
    with Master(system, fmu_paths) as master:
        return master.run(steps * H_S, {f"{axis}_position_ref_mm": values
                                        for axis, values in reference.items()})


@pytest.fixture(scope="module")
def ssp_path(system, fmu_paths, tmp_path_factory):
    return export_ssp(tmp_path_factory.mktemp("machine") / "machine.ssp", system, fmu_paths)


@pytest.fixture(scope="module")
def driven(system):
    """``export-ssp --machine``'s system: the CircleInterpolator FMU drives the servos."""
    return with_interpolator(system, PATH)


@pytest.fixture(scope="module")
def driven_ssp(driven, fmu_paths, tmp_path_factory):
    return export_ssp(tmp_path_factory.mktemp("driven") / "machine.ssp", driven, fmu_paths)


def table_positions(system, columns):
    outputs = system.output_values(columns)
    return np.column_stack([outputs["X_table_position_mm"], outputs["Y_table_position_mm"]])


def assert_same_trace(system, host, master_rows, lagging_errors, host_system=None):
    """``host`` columns (value k after step k) of ``host_system`` (default ``system``, the
    master's) against the master's rows after each step; a Jacobi host's error outputs
    trail the servos' by one step."""
    expected = {name: master_rows[name][1:] for name in SERVOS + ERRORS}
    got = dict(host)
    if lagging_errors:  # the host's error after step k + 1 is the master's after step k
        expected = {name: values[1:] if name in SERVOS else values[:-1]
                    for name, values in expected.items()}
        got = {name: values[1:] for name, values in got.items()}
    moved = np.ptp(master_rows["Y_GeometricError.error_um"])
    assert moved > 1.0, "the backlash never shows: the comparison tests nothing"
    got_mm = table_positions(host_system or system, got)
    expected_mm = table_positions(system, expected)
    np.testing.assert_allclose(got_mm, expected_mm, rtol=0, atol=TOLERANCE_MM)
    return got_mm, expected_mm


def assert_same_radial_trace(system, host, master_rows, path, host_system):
    """The Jacobi host's table positions (its columns of ``host_system``) as the master's,
    and the ballbar's radius from them (distance from the centre less R, mm) within 1e-9
    mm."""
    got_mm, expected_mm = assert_same_trace(system, host, master_rows, True, host_system)
    radius = [np.hypot(*(table - np.array(path.center_mm)).T) - path.radius_mm
              for table in (got_mm, expected_mm)]
    assert np.ptp(radius[1]) > 1e-3  # the trace is not flat: it shows the machine's errors
    np.testing.assert_allclose(radius[0], radius[1], rtol=0, atol=TOLERANCE_MM)


def test_plain_fmpy_loop_equals_the_master(system, fmu_paths, master_rows):
    spec = importlib.util.spec_from_file_location("two_axis_circle",
                                                  ROOT / "examples" / "two_axis_circle.py")
    example = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(example)
    columns = example.run(system, fmu_paths, PATH)
    assert_same_trace(system, {name: columns[name] for name in SERVOS + ERRORS}, master_rows,
                      lagging_errors=False)


def test_interpolator_fmu_gives_the_masters_circle_bitwise(loaded_fmus):
    """The FMU is an adapter over physics.circle.CircleInterpolator: after the step ending at
    t its outputs are that function at t + ahead_s less the origin, to the last bit, and at
    initialisation at the start time + ahead_s: 0 where the origin is that first reference,
    as export-ssp --machine sets it."""
    loaded = loaded_fmus["CircleInterpolator"]
    origin_mm = first_reference_mm(PATH, H_S)
    assert min(np.abs(origin_mm)) > 39.0  # far from the machine's origin
    slave = loaded.instantiate("bitwise")
    loaded.set_values(slave, interpolator_parameters(PATH, H_S, origin_mm))
    loaded.enter_initialisation(slave)
    slave.exitInitializationMode()
    got, expected = [loaded.get_reals(slave, INTERPOLATOR_OUTPUTS)], [H_S]
    for k in range(int(round(PATH.duration_s / H_S)) + 20):  # and standing after the end
        slave.doStep(currentCommunicationPoint=k * H_S, communicationStepSize=H_S)
        got.append(loaded.get_reals(slave, INTERPOLATOR_OUTPUTS))
        expected.append(k * H_S + H_S + H_S)
    slave.freeInstance()
    assert list(got[0]) == [0.0, 0.0]
    for index in (0, 1):
        values = [float(PATH.position_mm(t_s, index)) - origin_mm[index] for t_s in expected]
        assert [row[index] for row in got] == values


@pytest.fixture(scope="module")
def circle_rows(system, fmu_paths):
    """What ``feedaxis simulate circular`` runs for PATH: the rows of every macro step."""
    with Master(system, fmu_paths) as master:
        return run_path(master, PATH, ["X", "Y"])[0]


def test_machine_ssp_counts_positions_from_the_first_reference(driven, system):
    """Every FMU of an axis gets that axis's first reference as position_offset_mm, the
    interpolator the same origin, and the table positions add it back (the squareness's
    share of the second axis's included)."""
    origin_mm = first_reference_mm(PATH, H_S)
    axis_fmus = [c for c in driven.components if c.name != "CircleInterpolator"]
    assert len(axis_fmus) == len(system.components) >= 4
    for component in axis_fmus:
        origin = origin_mm["XY".index(component.name[0])]
        assert component.parameters["position_offset_mm"] == origin
    interpolator = driven.component("CircleInterpolator").parameters
    assert (interpolator["origin_first_mm"], interpolator["origin_second_mm"]) == origin_mm
    at_start = {term: np.zeros(1) for output in system.outputs for term, _ in output.terms}
    start_mm = table_positions(driven, at_start)[0]
    assert start_mm == pytest.approx([origin_mm[0] + 50e-6 * origin_mm[1], origin_mm[1]],
                                     abs=1e-12)
    assert table_positions(system, at_start)[0] == pytest.approx([0.0, 0.0], abs=0)


def test_libcosim_runs_the_machine_ssp_like_simulate_circular(system, driven, driven_ssp,
                                                              circle_rows):
    """OSP libcosim passes the interpolator's outputs on at initialisation."""
    result = simulate_ssp_with_libcosim(driven_ssp, circle_rows.size - 1,
                                        outputs=SERVOS + ERRORS)
    assert_same_radial_trace(system, result, circle_rows, PATH, driven)


def test_omsimulator_program_runs_the_machine_ssp_like_simulate_circular(
        system, driven, driven_ssp, circle_rows, tmp_path):
    """The OMSimulator program (a host that is not a Python process) on the .ssp as written:
    its CSV result (12 significant digits: 5e-11 mm at 60 mm) after every macro step."""
    program = OMS_DIR / "bin" / "OMSimulator"
    require_tool(program)
    rows = circle_rows
    stop_s = (rows.size - 1) * H_S
    run = subprocess.run([str(program), f"--stopTime={stop_s!r}", "--resultFile=result.csv",
                          str(driven_ssp)], cwd=tmp_path, capture_output=True, text=True,
                         timeout=300)
    assert run.returncode == 0 and "0 errors" in run.stdout, (run.stdout + run.stderr)[-3000:]
    lines = list(csv.reader((tmp_path / "result.csv").read_text().splitlines()))
    names = [name.strip().strip('"') for name in lines[0]]
    after = {}  # the last row of each time: after its step (it writes one before it too)
    for line in lines[1:]:
        after[round(float(line[0]) / H_S)] = [float(field) for field in line[:len(names)]]
    assert sorted(after) == list(range(rows.size))
    columns = {name: np.array([after[k][names.index(f"{system.name}.{system.name}.{name}")]
                               for k in range(1, rows.size)]) for name in SERVOS + ERRORS}
    assert_same_radial_trace(system, columns, rows, PATH, driven)


def test_fmpy_simulate_ssp_runs_the_machine_ssp_like_simulate_circular(system, driven,
                                                                       driven_ssp, circle_rows):
    """fmpy's simulate_ssp (0.3) sets every connector to 0 before the first step, passes
    outputs on only after each step and initialises each FMU alone, with the values of
    :func:`fmpy_parameter_set` (the .ssv's, position_offset_mm among them). Every position
    connector of the exported machine is 0 at the start, so the servos start at rest at the
    circle's first reference, (61.74, 39.45) mm, as the master's do."""
    result = simulate_ssp(str(driven_ssp), stop_time=(circle_rows.size - 1) * H_S,
                          step_size=H_S, parameter_set=fmpy_parameter_set(driven_ssp))
    assert_same_radial_trace(system, {name: result[name][:circle_rows.size - 1]
                                      for name in SERVOS + ERRORS}, circle_rows, PATH, driven)


def test_omsimulator_runs_the_machine_ssp_like_the_master(system, ssp_path, master_rows, steps):
    require_tool(OMS_DIR / "lib")
    sys.path.insert(0, str(OMS_DIR / "lib" / "x86_64-linux-gnu"))
    try:
        from OMSimulator import SSP, CRef
    finally:
        sys.path.pop(0)
    instance = SSP(str(ssp_path)).instantiate()
    instance.setResultFile("")
    reference = references(steps)
    for axis in ("X", "Y"):
        instance.setValue(CRef(system.name, f"{axis}_NpidServo", "position_ref_mm"),
                          float(reference[axis][0]))
    instance.initialize()
    columns = {name: [] for name in SERVOS + ERRORS}
    time_s = 0.0
    for k in range(steps):
        for axis in ("X", "Y"):
            instance.setValue(CRef(system.name, f"{axis}_NpidServo", "position_ref_mm"),
                              float(reference[axis][k]))
        time_s += H_S  # cumulative targets (the tools' README)
        instance.stepUntil(time_s)
        for name in columns:
            component, variable = name.split(".")
            columns[name].append(instance.getValue(CRef(system.name, component, variable)))
    instance.terminate()
    instance.delete()
    assert_same_trace(system, {k: np.array(v) for k, v in columns.items()}, master_rows,
                      lagging_errors=True)


def test_export_ssp_machine_connects_the_interpolator_to_both_servos(user_fmu_cache, tmp_path,
                                                                       capsys):
    """``export-ssp --machine CASE --direction cw`` writes the case's circle into the
    CircleInterpolator's parameters (one macro step ahead), connects its outputs to both
    servos' references and stops the experiment at the end of the lead-out arc."""
    import json
    import xml.etree.ElementTree as ET
    import zipfile

    from fmpy.ssp.ssd import read_ssd

    from circular_cases import circle_columns, synthetic_case
    from feedaxis.cli import main

    case = synthetic_case(tmp_path / "c", np.zeros(720), circle_columns()).folder
    out = tmp_path / "m.ssp"
    assert main(["export-ssp", str(out), "--machine", str(case), "--direction", "cw",
                 "--json"]) == 0
    payload = json.loads(capsys.readouterr().out)
    path = CircleInterpolator(20.0, 1000.0, (60.0, 40.0), -1)
    assert payload["interpolator"] == interpolator_parameters(path, H_S,
                                                              first_reference_mm(path, H_S))
    assert "X_NpidServo.position_ref_mm" not in {i["input"] for i in payload["open_inputs"]}
    ssd = read_ssd(str(out))
    connections = {(c.startElement, c.startConnector, c.endElement, c.endConnector)
                   for c in ssd.system.connections}
    assert {("CircleInterpolator", output, f"{axis}_NpidServo", "position_ref_mm")
            for axis, output in zip("XY", INTERPOLATOR_OUTPUTS)} <= connections
    with zipfile.ZipFile(out) as archive:
        root = ET.fromstring(archive.read("SystemStructure.ssd"))
    experiment = next(e for e in root.iter() if e.tag.endswith("DefaultExperiment"))
    assert float(experiment.get("stopTime")) == pytest.approx(
        np.ceil(path.duration_s / H_S - 1e-9) * H_S, abs=1e-12)
