"""Two axes on a circle, stepped by a plain fmpy loop (docs/circular.md).

Run: ``python examples/two_axis_circle.py``. The machine's system description
(``feedaxis.cosim.machine``: two axes X and Y, each a servo and its geometric error, 50
µrad out of square, 3 µm of backlash on Y) is run with fmpy's ``FMU2Slave`` alone: each
component instantiated with its parameter values, then every 1 ms macro step the
components step in dependency order, each servo's reference the circle at the next
instant. It prints the ballbar's circular deviation of the measured turn.
"""
import numpy as np
from fmpy import extract, read_model_description
from fmpy.fmi2 import FMU2Slave

from feedaxis.case import Axis
from feedaxis.circular_case import CircularTest, Machine
from feedaxis.cosim.fmu_cache import cached_fmus
from feedaxis.cosim.machine import machine_from_case_axes
from feedaxis.physics.circle import CircleInterpolator

H_S = 1e-3


def run(system, fmu_paths, path):
    """Step ``system`` along the circle ``path`` (a CircleInterpolator) with fmpy alone;
    {"Component.output": values after each macro step, "time": ...}.

    As the project's master does: a servo's reference k is the circle at t_{k+1} (held over
    the step, also at initialisation), and the components step in dependency order, each
    seeing its sources' outputs of the same step.
    """
    signals = {variable.name: variable.start for variable in system.inputs}
    slaves, columns = [], {"time": []}
    for component in system.ordered_components():
        description = read_model_description(fmu_paths[component.fmu])
        vrs = {v.name: v.valueReference for v in description.modelVariables}
        slave = FMU2Slave(guid=description.guid, unzipDirectory=extract(fmu_paths[component.fmu]),
                          modelIdentifier=description.coSimulation.modelIdentifier,
                          instanceName=component.name)
        slave.instantiate()
        for name, value in component.parameters.items():
            setter = {bool: slave.setBoolean, int: slave.setInteger, str: slave.setString}.get(
                type(value), slave.setReal)
            setter([vrs[name]], [value])
        outputs = [v.name for v in description.modelVariables
                   if v.causality == "output" and v.type == "Real"]
        entry = (component, slave, vrs, outputs)
        slave.setupExperiment(startTime=0.0)
        slave.enterInitializationMode()
        _exchange(system, entry, signals, _references(path, 0))
        slave.exitInitializationMode()
        signals.update(zip((f"{component.name}.{n}" for n in outputs),
                           slave.getReal([vrs[n] for n in outputs])))
        slaves.append(entry)
        columns.update({f"{component.name}.{name}": [] for name in outputs})
    for k in range(int(round(path.duration_s / H_S))):
        for entry in slaves:
            component, slave, vrs, outputs = entry
            _exchange(system, entry, signals, _references(path, k))
            slave.doStep(currentCommunicationPoint=k * H_S, communicationStepSize=H_S)
            for name, value in zip(outputs, slave.getReal([vrs[n] for n in outputs])):
                signals[f"{component.name}.{name}"] = value
                columns[f"{component.name}.{name}"].append(value)
        columns["time"].append((k + 1) * H_S)
    for _, slave, _, _ in slaves:
        slave.terminate()
        slave.freeInstance()
    return {name: np.array(values) for name, values in columns.items()}


def _references(path, k):
    """Each axis's reference during step k: the circle at t_{k+1}."""
    return {f"{axis}_position_ref_mm": float(path.position_mm((k + 1) * H_S, index))
            for index, axis in enumerate(("X", "Y"))}


def _exchange(system, entry, signals, references):
    """Set the component's connected inputs from the signals (the references updated)."""
    component, slave, vrs, _ = entry
    signals.update(references)
    for connection in system.inputs_of(component.name):
        slave.setReal([vrs[connection.target.split(".", 1)[1]]], [signals[connection.source]])


def main():
    machine = Machine("XY", CircularTest(("X", "Y"), 20.0, 1000.0, (60.0, 40.0)),
                      {"X": Axis("X", {"lead_mm": 10.0}), "Y": Axis("Y", {"lead_mm": 5.0})})
    system = machine_from_case_axes(machine, squareness_urad=50.0).with_parameters(
        {"Y_GeometricError": {"backlash_um": 3.0}})
    path = CircleInterpolator(20.0, 1000.0, (60.0, 40.0))
    columns = run(system, cached_fmus(), path)
    table = system.output_values(columns)
    radius_um = (np.hypot(table["X_table_position_mm"] - 60.0,
                          table["Y_table_position_mm"] - 40.0) - 20.0) * 1e3
    start_s, end_s = path.measured_s
    turn = (columns["time"] >= start_s) & (columns["time"] < end_s)
    print(f"{turn.sum()} steps on the measured turn; radial deviation "
          f"{radius_um[turn].min():.3f} to {radius_um[turn].max():.3f} µm")


if __name__ == "__main__":
    main()
