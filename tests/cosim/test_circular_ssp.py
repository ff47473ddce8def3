"""The machine of two axes as one SSP, run in three FMI importers like the project's master.

The machine (two axes X and Y, each a servo and its geometric error, 50 µrad out of square,
a lead slope on X, backlash on Y) is driven round a circle: by the project's master (what
``feedaxis simulate circular`` runs), by a plain fmpy loop over the same FMUs
(examples/two_axis_circle.py, stepping in dependency order as the master does), by OSP
libcosim and by OMSimulator's API on the exported .ssp. The importers step Jacobi: the error
FMUs see the servos' outputs of the step before, so their outputs lag one macro step; with
that accounted for every table position (mm) agrees within 1e-9 mm, and so does the
ballbar's trace.
"""
import importlib.util
import sys
from pathlib import Path

import numpy as np
import pytest

from circular_cases import machine
from conftest import unavailable
from feedaxis.cosim.machine import CircleInterpolator, machine_from_case_axes
from feedaxis.cosim.master import Master
from feedaxis.cosim.ssp import export_ssp
from libcosim_driver import simulate_ssp_with_libcosim

ROOT = Path(__file__).resolve().parents[2]
OMS_DIR = ROOT.parent / "shared" / "tools" / "fmi" / "omsimulator"
H_S = 1e-3
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
    np.testing.assert_allclose(table_positions(system, got), table_positions(system, expected),
                               rtol=0, atol=TOLERANCE_MM)


def test_plain_fmpy_loop_equals_the_master(system, fmu_paths, master_rows):
    spec = importlib.util.spec_from_file_location("two_axis_circle",
                                                  ROOT / "examples" / "two_axis_circle.py")
    example = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(example)
    columns = example.run(system, fmu_paths, PATH)
    assert_same_trace(system, {name: columns[name] for name in SERVOS + ERRORS}, master_rows,
                      lagging_errors=False)


def test_libcosim_runs_the_machine_ssp_like_the_master(system, ssp_path, master_rows, steps):
    reference = references(steps)
    inputs = {f"{axis}_NpidServo.position_ref_mm": values for axis, values in reference.items()}
    result = simulate_ssp_with_libcosim(
        ssp_path, steps, inputs, {name: values[0] for name, values in inputs.items()},
        SERVOS + ERRORS)
    assert_same_trace(system, result, master_rows, lagging_errors=True)


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
