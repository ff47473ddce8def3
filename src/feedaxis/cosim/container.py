"""The whole axis as one FMU: fmpy's container FMU around the four FMUs, in their FMI version
(FMI 2.0, or FMI 3.0 around the FMI 3.0 FMUs: the container's binary hosts both).

Generated from the :class:`~feedaxis.cosim.system.AxisSystem`: the system inputs become
container inputs, every component output a container output (``NpidServo.position_mm``, ...;
a container cannot sum, so ``positioning_error_um`` is the sum of the three ``error_um``
outputs), the system's parameter values become fixed container parameters
(``NpidServo.nonlinear``, ...) mapped onto the components, and the component-to-component
connections are the container's connections. Each container variable keeps the unit and the
description of the component variable it maps to (the components' unit definitions are
carried over).

What the container is, found by running it (fmpy 0.3.32):

- one fixed step for all four FMUs (the container's ``fixedInternalStepSize``, the macro
  step): no multi-rate, so ThermalScrew steps every macro step too;
- Jacobi: each FMU steps with the inputs of the previous step, so the error FMUs lag the
  servo by one step (as in fmpy.ssp.simulate_ssp);
- the container binary takes value reference 0 as the time (an independent variable first);
- ``fmpy.container_fmu.write_configuration`` writes the type of a connection as the FMI 2
  name "Real", which the bundled container binary refuses ("unknown variant `Real`,
  expected one of `Float32`, `Float64`, ..."); :func:`export_container_fmu` writes
  "Float64" instead;
- fmpy packs the container's binary for Linux, macOS and Windows; the four FMUs inside run
  on Linux x86-64 only, so the container keeps that one platform's binary and declares no
  other.
"""
from __future__ import annotations

import json
import tempfile
import zipfile
from pathlib import Path

from ..fmu_build import binaries_platform
from ..output import write_atomically
from ..errors import InputError
from .fmu_runner import FMI2_TYPES, fmi2_variables
from .system import check_parameter_values, fmi_text

CONTAINER_TYPES = {"Real": "Float64"}
FMI3_TYPES = {fmi2: fmi3 for fmi3, fmi2 in FMI2_TYPES.items()}


def export_container_fmu(out, system, fmu_paths):
    """Write the axis as one co-simulation FMU ``out`` (.fmu) of the FMI version of the FMUs
    ``fmu_paths`` (2.0 or 3.0); return its path."""
    from fmpy.container_fmu.cli import create_container_fmu

    out = Path(out)
    if out.suffix != ".fmu":
        raise InputError("the FMU file name must end in .fmu", path=out)
    configuration = container_configuration(system, fmu_paths)
    with tempfile.TemporaryDirectory(prefix="feedaxis_container_") as folder:
        unzip_dir, built = Path(folder) / "unzip", Path(folder) / "built.fmu"
        unzip_dir.mkdir()
        create_container_fmu(configuration, unzip_dir, built)
        platform = binaries_platform(configuration.modelDescription.fmiMajorVersion)
        return write_atomically(out, _finished(built, platform))


def fmi_version(descriptions):
    """The one FMI version ("2.0" or "3.0") of the model ``descriptions`` ({FMU path: fmpy
    description}); FMUs of both are bad input."""
    versions = {d.fmiVersion for d in descriptions.values()}
    if len(versions) > 1:
        raise InputError("the FMUs are of different FMI versions ("
                         + ", ".join(f"{Path(path).name} {d.fmiVersion}"
                                     for path, d in sorted(descriptions.items()))
                         + "): one container holds FMUs of one version", parameter="--fmus")
    return versions.pop()


def container_configuration(system, fmu_paths):
    """The fmpy container Configuration of ``system`` (parameters checked by name and type),
    in the FMI version of the FMUs ``fmu_paths``."""
    from fmpy import read_model_description
    from fmpy.container_fmu.config import Component, Configuration, Connection
    from fmpy.model_description import (CoSimulation, DefaultExperiment, ModelDescription,
                                        ModelVariable, Unknown)

    descriptions = {str(fmu_paths[c.fmu]): read_model_description(str(fmu_paths[c.fmu]))
                    for c in system.components}
    version = fmi_version(descriptions)
    typed = FMI3_TYPES.get if version.startswith("3.") else str

    components, variables, units = {}, {}, {}
    for c in system.components:
        description = descriptions[str(fmu_paths[c.fmu])]
        components[c.name] = Component(name=c.name, filename=Path(fmu_paths[c.fmu]),
                                       modelDescription=description)
        variables[c.name] = fmi2_variables(description)
        units.update({unit.name: unit for unit in description.unitDefinitions})
    mappings = {}

    def add(variable, component, name):
        mappings[variable] = [(components[component], variables[component][name])]

    for connection in system.connections:
        if connection.source_component is None:
            declared = next(v for v in system.inputs if v.name == connection.source)
            component, name = connection.target.split(".", 1)
            add(ModelVariable(type=typed("Real"), variability="continuous", causality="input",
                              name=connection.source, start=repr(float(declared.start)),
                              description=declared.description,
                              unit=variables[component][name].unit),
                component, name)
    for c in system.components:
        check_parameter_values(c, variables[c.name])
        for name, value in c.parameters.items():
            declared = variables[c.name][name]
            add(ModelVariable(type=typed(declared.type), variability="fixed",
                              causality="parameter",
                              initial="exact", name=f"{c.name}.{name}", start=fmi_text(value),
                              description=declared.description, unit=declared.unit),
                c.name, name)
        for name, declared in variables[c.name].items():
            if declared.causality == "output":
                add(ModelVariable(type=typed("Real"), variability="continuous",
                                  causality="output",
                                  initial="calculated", name=f"{c.name}.{name}",
                                  description=declared.description, unit=declared.unit),
                    c.name, name)
    connections = []
    for connection in system.connections:
        if connection.source_component is not None:
            (source, output), (target, input_) = (connection.source.split(".", 1),
                                                  connection.target.split(".", 1))
            connections.append(Connection(components[source], [variables[source][output]],
                                          components[target], [variables[target][input_]]))
    # The container binary reads value reference 0 as the time, so the mapped variables
    # start at 1 behind an independent "time" variable, as in fmpy's own container tests.
    model_variables = [ModelVariable(type=typed("Real"), variability="continuous",
                                     causality="independent", name="time"), *mappings]
    outputs = [Unknown(variable=v) for v in model_variables if v.causality == "output"]
    description = ModelDescription(
        fmiVersion=version, modelName=system.name, instantiationToken=_guid(system),
        description="feedaxis: ball-screw feed axis, four FMUs in an fmpy container",
        defaultExperiment=DefaultExperiment(stepSize=repr(system.macro_step_s)),
        coSimulation=CoSimulation(fixedInternalStepSize=system.macro_step_s),
        modelVariables=model_variables, outputs=outputs, initialUnknowns=list(outputs),
        unitDefinitions=[units[name] for name in sorted(units)])
    return Configuration(parallelDoStep=False, modelDescription=description,
                         components=list(components.values()), connections=connections,
                         variableMappings=mappings)


def _guid(system):
    """A GUID that changes with the system (its description's text)."""
    import uuid

    return "{" + str(uuid.uuid5(uuid.NAMESPACE_URL, f"feedaxis:{system!r}")) + "}"


def _finished(fmu_path, platform):
    """The FMU's bytes with the container.json connection types the binary accepts and the
    binaries of ``platform`` alone (the folder of the FMUs it holds)."""
    with zipfile.ZipFile(fmu_path) as archive:
        entries = {info: archive.read(info) for info in archive.infolist()
                   if not info.filename.startswith("binaries/")
                   or info.filename.startswith(f"binaries/{platform}/")}
    for info in entries:
        if info.filename == "resources/container.json":
            configuration = json.loads(entries[info])
            for connection in configuration["connections"]:
                connection["variableType"] = CONTAINER_TYPES.get(connection["variableType"],
                                                                 connection["variableType"])
            entries[info] = json.dumps(configuration, indent=4).encode()
    with tempfile.SpooledTemporaryFile() as buffer:
        with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as archive:
            for info, data in entries.items():
                archive.writestr(info, data)
        buffer.seek(0)
        return buffer.read()
