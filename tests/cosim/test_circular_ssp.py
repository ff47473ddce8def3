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
one macro step. With that accounted for every table position (mm) and the ballbar's radial
trace agree within 1e-9 mm.
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
from conftest import unavailable
from feedaxis.cosim.circular import run_path
from feedaxis.cosim.machine import (INTERPOLATOR_OUTPUTS, interpolator_parameters,
                                    machine_from_case_axes, with_interpolator)
from feedaxis.cosim.master import Master
from feedaxis.cosim.ssp import export_ssp, fmpy_parameter_set
from feedaxis.physics.circle import CircleInterpolator
from libcosim_driver import simulate_ssp_with_libcosim

ROOT = Path(__file__).resolve().parents[2]
OMS_DIR = ROOT.parent / "shared" / "tools" / "fmi" / "omsimulator"
H_S = 1e-3
PATH = CircleInterpolator(2.0, 1000.0, (60.0, 40.0), lead_in_deg=30.0, lead_out_deg=10.0)
# the same circle clockwise, its first reference (the circle at t_1) at the machine's origin:
# fmpy's simulate_ssp starts every connector at 0 (see test_fmpy_simulate_ssp_...)
_FIRST_DEG = np.radians(CircleInterpolator(2.0, 1000.0, (0.0, 0.0), -1, 0.0, 30.0,
                                           10.0).angle_deg(H_S))
AT_ORIGIN = CircleInterpolator(2.0, 1000.0, (-2.0 * np.cos(_FIRST_DEG), -2.0 * np.sin(_FIRST_DEG)),
                               -1, 0.0, 30.0, 10.0)
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


def master_trace(system, fmu_paths, path):
    """What ``feedaxis simulate circular`` runs for ``path``: the rows of every macro step."""
    with Master(system, fmu_paths) as master:
        return run_path(master, path, ["X", "Y"])[0]


@pytest.fixture(scope="module")
def driven_ssp(system, fmu_paths, tmp_path_factory):
    """``export-ssp --machine``'s system: the CircleInterpolator FMU drives the servos."""
    return export_ssp(tmp_path_factory.mktemp("driven") / "machine.ssp",
                      with_interpolator(system, PATH), fmu_paths)


def table_positions(system, columns):
    outputs = system.output_values(columns)
    return np.column_stack([outputs["X_table_position_mm"], outputs["Y_table_position_mm"]])


def assert_same_trace(system, host, master_rows, lagging_errors):
    """``host`` columns (value k after step k) against the master's rows after each step;
    a Jacobi host's error outputs trail the servos' by one step."""
    expected = {name: master_rows[name][1:] for name in SERVOS + ERRORS}
    got = dict(host)
    if lagging_errors:  # the host's error after step k + 1 is the master's after step k
        expected = {name: values[1:] if name in SERVOS else values[:-1]
                    for name, values in expected.items()}
        got = {name: values[1:] for name, values in got.items()}
    moved = np.ptp(master_rows["Y_GeometricError.error_um"])
    assert moved > 1.0, "the backlash never shows: the comparison tests nothing"
    got_mm, expected_mm = table_positions(system, got), table_positions(system, expected)
    np.testing.assert_allclose(got_mm, expected_mm, rtol=0, atol=TOLERANCE_MM)
    return got_mm, expected_mm


def assert_same_radial_trace(system, host, master_rows, path):
    """The Jacobi host's table positions as the master's, and the ballbar's radius from
    them (distance from the centre less R, mm) within 1e-9 mm."""
    got_mm, expected_mm = assert_same_trace(system, host, master_rows, lagging_errors=True)
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
    t its outputs are that function at t + ahead_s, to the last bit, and at initialisation
    at the start time + ahead_s."""
    loaded = loaded_fmus["CircleInterpolator"]
    slave = loaded.instantiate("bitwise")
    loaded.set_values(slave, interpolator_parameters(PATH, H_S))
    loaded.enter_initialisation(slave)
    slave.exitInitializationMode()
    got, expected = [loaded.get_reals(slave, INTERPOLATOR_OUTPUTS)], [H_S]
    for k in range(int(round(PATH.duration_s / H_S)) + 20):  # and standing after the end
        slave.doStep(currentCommunicationPoint=k * H_S, communicationStepSize=H_S)
        got.append(loaded.get_reals(slave, INTERPOLATOR_OUTPUTS))
        expected.append(k * H_S + H_S + H_S)
    slave.freeInstance()
    for index in (0, 1):
        values = [float(PATH.position_mm(t_s, index)) for t_s in expected]
        assert [row[index] for row in got] == values


def test_libcosim_runs_the_machine_ssp_like_simulate_circular(system, fmu_paths, driven_ssp):
    """OSP libcosim passes the interpolator's outputs on at initialisation, so the servos
    start at the first reference as the master's do."""
    rows = master_trace(system, fmu_paths, PATH)
    result = simulate_ssp_with_libcosim(driven_ssp, rows.size - 1, outputs=SERVOS + ERRORS)
    assert_same_radial_trace(system, result, rows, PATH)


def test_omsimulator_program_runs_the_machine_ssp_like_simulate_circular(system, fmu_paths,
                                                                         driven_ssp, tmp_path):
    """The OMSimulator program (a host that is not a Python process) on the .ssp as written:
    its CSV result (12 significant digits: 5e-11 mm at 60 mm) after every macro step."""
    program = OMS_DIR / "bin" / "OMSimulator"
    if not program.exists():
        unavailable(f"{program} is missing (the FMI tools of ../shared/tools/fmi)")
    rows = master_trace(system, fmu_paths, PATH)
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
    assert_same_radial_trace(system, columns, rows, PATH)


def test_fmpy_simulate_ssp_runs_the_machine_ssp_like_simulate_circular(system, fmu_paths,
                                                                       tmp_path):
    """fmpy's simulate_ssp (0.3) sets every connector to 0 before the first step and passes
    outputs on only after each step, and initialises the FMUs without passing any value
    between them: the servos start at their position_ref_mm start value (0 mm) and step the
    first macro step towards 0 mm. It gives the master's trace on a circle whose first
    reference (the circle at t_1, where the master's servos start) is the origin; anywhere
    else its first step pulls the axes towards 0 mm."""
    rows = master_trace(system, fmu_paths, AT_ORIGIN)
    ssp_path = export_ssp(tmp_path / "machine.ssp", with_interpolator(system, AT_ORIGIN),
                          fmu_paths)
    result = simulate_ssp(str(ssp_path), stop_time=(rows.size - 1) * H_S, step_size=H_S,
                          parameter_set=fmpy_parameter_set(ssp_path))
    assert_same_radial_trace(system, {name: result[name][:rows.size - 1]
                                      for name in SERVOS + ERRORS}, rows, AT_ORIGIN)


def test_omsimulator_runs_the_machine_ssp_like_the_master(system, ssp_path, master_rows, steps):
    if not (OMS_DIR / "lib").exists():
        unavailable(f"{OMS_DIR} is missing (the FMI tools of ../shared/tools/fmi)")
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
    assert payload["interpolator"] == interpolator_parameters(path, H_S)
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
