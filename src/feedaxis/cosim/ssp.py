"""SSP 1.0 export of the co-simulated axis: SystemStructure.ssd, parameter values, FMUs.

The .ssd is generated from the :class:`~feedaxis.cosim.system.AxisSystem`: one Component per
FMU with its connectors, the component-to-component connections, a parameter binding to
the component's ``resources/<Component>.ssv`` and OSP annotations (``osp:StepSizeHint`` per
component, ``osp:FixedStepAlgorithm`` with the macro step in DefaultExperiment).

Two importers shape it (both found by trying):

- OSP libcosim accepts only connections between components (a Connection without
  ``startElement``, i.e. from a system-level connector, makes it refuse the whole file) and
  ignores a binding's ``prefix``, so each component binds its own .ssv with plain names.
  The axis's system inputs (``NpidServo.position_ref_mm``, ``NpidServo.disturbance_N``,
  ``ThermalScrew.ambient_C``) are therefore left unconnected, for the importing tool to
  drive (libcosim: an override manipulator; a wider model: its own connections).
- ``fmpy.ssp.simulate_ssp`` ignores parameter bindings (pass :func:`fmpy_parameter_set`),
  feeds its ``input=`` only to system-level connectors (so here inputs keep the start values
  the parameter set gives them), converts an ssv Boolean "false" to True, and cannot set
  String parameters; :func:`fmpy_parameter_set` converts Booleans and refuses Strings.
"""
from __future__ import annotations

import io
import math
import zipfile
import xml.etree.ElementTree as ET
from pathlib import Path

from ..errors import InputError
from ..fmu_build import SI_UNITS
from ..output import write_atomically
from .fmu_runner import LoadedFmu
from .system import check_parameter_values, fmi_text

NAMESPACES = {
    "ssd": "http://ssp-standard.org/SSP1/SystemStructureDescription",
    "ssc": "http://ssp-standard.org/SSP1/SystemStructureCommon",
    "ssv": "http://ssp-standard.org/SSP1/SystemStructureParameterValues",
    "osp": "http://opensimulationplatform.com/SSP/OSPAnnotations",
    "oms": "https://raw.githubusercontent.com/OpenModelica/OMSimulator/master/schema/oms.xsd",
}
OSP_ANNOTATION = "com.opensimulationplatform"
OMS_ANNOTATION = "org.openmodelica"

for _prefix, _uri in NAMESPACES.items():
    ET.register_namespace(_prefix, _uri)


def _tag(qualified):
    prefix, name = qualified.split(":")
    return f"{{{NAMESPACES[prefix]}}}{name}"


def _element(parent, qualified, **attributes):
    return ET.SubElement(parent, _tag(qualified), {k: str(v) for k, v in attributes.items()})


def export_ssp(out, system, fmu_paths, stop_time_s=1.0, step_size_hints=False):
    """Write ``out`` (.ssp): SystemStructure.ssd, resources/<Component>.ssv and <FMU>.fmu.

    Parameter names are checked against the FMUs' model descriptions first, so a bad
    ``--set`` is refused before anything is written. The DefaultExperiment runs from 0 to
    ``stop_time_s`` (s). ``step_size_hints`` adds an ``osp:StepSizeHint`` per component, the
    multi-rate schedule for libcosim, which OMSimulator refuses ("Unexpected tag
    ssd:Annotations" in a Component); without them every importer steps every component at
    the macro step. Returns the path.
    """
    if not (math.isfinite(stop_time_s) and stop_time_s > 0):
        raise InputError(f"the stop time must be finite and > 0 s, got {stop_time_s!r}",
                         parameter="--stop-time")
    out = Path(out)
    if out.suffix != ".ssp":
        raise InputError("the SSP file name must end in .ssp", path=out)
    descriptions = {}
    for component in system.components:
        loaded = LoadedFmu(fmu_paths[component.fmu])
        loaded.close()
        descriptions[component.fmu] = loaded.variables
        check_parameter_values(component, loaded.variables)
    buffer = io.BytesIO()
    with zipfile.ZipFile(buffer, "w", zipfile.ZIP_DEFLATED) as archive:
        archive.writestr("SystemStructure.ssd",
                         _xml(system_structure(system, descriptions, stop_time_s,
                                               step_size_hints)))
        for component in system.components:
            archive.writestr(f"resources/{component.name}.ssv",
                             _xml(parameter_values(component, system.name,
                                                   descriptions[component.fmu])))
        for fmu in sorted({c.fmu for c in system.components}):  # zips already: stored
            archive.write(fmu_paths[fmu], f"resources/{fmu}.fmu", zipfile.ZIP_STORED)
    return write_atomically(out, buffer.getvalue())


def open_inputs(system):
    """[(connector, system input)] the SSP leaves unconnected: the axis's system inputs
    (libcosim refuses system-level connectors). An importing tool must drive them, else
    they keep their start values: ``NpidServo.position_ref_mm`` at 0 mm, a standing axis."""
    inputs = {variable.name: variable for variable in system.inputs}
    return [(connection.target, inputs[connection.source]) for connection in system.connections
            if connection.source_component is None]


def _xml(root):
    ET.indent(root)
    return ET.tostring(root, encoding="utf-8", xml_declaration=True)


def system_structure(system, variables, stop_time_s=1.0, step_size_hints=False):
    """The SystemStructure.ssd element tree of ``system``.

    ``variables`` maps each FMU name to its model variables by name (units, causality);
    every connector unit is defined in ``ssd:Units`` (as the SSP schema requires).
    """
    root = ET.Element(_tag("ssd:SystemStructureDescription"),
                      {"version": "1.0", "name": system.name})
    ssd_system = _element(root, "ssd:System", name=system.name,
                          description="feedaxis: ball-screw feed axis from four FMUs")
    elements = _element(ssd_system, "ssd:Elements")
    for component in system.components:
        _component(elements, component, system, variables[component.fmu], step_size_hints)
    connections = _element(ssd_system, "ssd:Connections")
    for connection in system.connections:
        if connection.source_component is None:
            continue
        start_element, start_connector = connection.source.split(".", 1)
        end_element, end_connector = connection.target.split(".", 1)
        _element(connections, "ssd:Connection", startElement=start_element,
                 startConnector=start_connector, endElement=end_element,
                 endConnector=end_connector)
    _oms_master(ssd_system, system.macro_step_s)
    units = _element(root, "ssd:Units")
    for unit_name in sorted({u.get("unit") for u in root.iter(_tag("ssc:Real")) if u.get("unit")}):
        factor, exponents = SI_UNITS[unit_name]
        base = _element(_element(units, "ssc:Unit", name=unit_name), "ssc:BaseUnit",
                        **exponents)
        if factor != 1.0:
            base.set("factor", repr(factor))
    experiment = _element(root, "ssd:DefaultExperiment", startTime=0.0, stopTime=stop_time_s)
    annotation = _osp_annotation(experiment)
    _element(_element(annotation, "osp:Algorithm"), "osp:FixedStepAlgorithm",
             baseStepSize=repr(system.macro_step_s))
    return root


def _component(elements, component, system, variables, step_size_hint):
    element = _element(elements, "ssd:Component", name=component.name,
                       type="application/x-fmu-sharedlibrary",
                       source=f"resources/{component.fmu}.fmu")
    connectors = _element(element, "ssd:Connectors")
    names = [c.target.split(".", 1)[1] for c in system.inputs_of(component.name)
             if c.source_component is not None]
    names += [v.name for v in variables.values() if v.causality == "output"]
    for name in names:
        variable = variables[name]
        connector = _element(connectors, "ssd:Connector", name=name, kind=variable.causality)
        real = _element(connector, "ssc:Real")
        if variable.unit:
            real.set("unit", variable.unit)
    bindings = _element(element, "ssd:ParameterBindings")
    _element(bindings, "ssd:ParameterBinding", source=f"resources/{component.name}.ssv")
    if step_size_hint:
        _element(_osp_annotation(element), "osp:StepSizeHint", value=repr(component.step_s))


def _oms_master(ssd_system, macro_step_s):
    """OMSimulator's system type: a fixed-step co-simulation master at the macro step
    (without it OMSimulator cannot create the system: "[NewSystem] internal error")."""
    annotation = _element(_element(ssd_system, "ssd:Annotations"), "ssc:Annotation",
                          type=OMS_ANNOTATION)
    information = _element(_element(annotation, "oms:Annotations"), "oms:SimulationInformation")
    _element(information, "oms:FixedStepMaster", description="oms-ma",
             stepSize=repr(macro_step_s), absoluteTolerance=1e-4, relativeTolerance=1e-4)


def _osp_annotation(parent):
    annotations = _element(parent, "ssd:Annotations")
    return _element(annotations, "ssc:Annotation", type=OSP_ANNOTATION)


def parameter_values(component, set_name, variables):
    """The component's .ssv ParameterSet ``set_name``: every parameter value the system sets.

    All components' sets share one name (an importer such as ecos applies one set name);
    each value's type is the FMU's declared type (``variables``: name -> model variable),
    so an integer literal for a Real parameter is written as an ``ssv:Real``.
    """
    root = ET.Element(_tag("ssv:ParameterSet"), {"version": "1.0", "name": set_name})
    parameters = _element(root, "ssv:Parameters")
    for name, value in component.parameters.items():
        kind = variables[name].type
        _element(_element(parameters, "ssv:Parameter", name=name), f"ssv:{kind}",
                 value=fmi_text(float(value) if kind == "Real" else value))
    return root


def fmpy_parameter_set(ssp_path, start_values=None):
    """The .ssp's parameter values as the ``parameter_set`` of ``fmpy.ssp.simulate_ssp``.

    Parameters
    ----------
    ssp_path : path
    start_values : dict, optional
        Extra ``"Component.variable": value`` start values, e.g. a constant
        ``"NpidServo.disturbance_N": 300.0`` (simulate_ssp cannot drive these inputs).

    Returns
    -------
    fmpy.ssp.ssd.ParameterSet
        Names ``Component.parameter``; Booleans as 1.0/0.0 (fmpy's setter tests
        ``value != 0.0``, which is True for the text "false").
    """
    from fmpy.ssp.ssd import Parameter, ParameterSet, read_ssd

    parameter_set = ParameterSet(name="feedaxis")
    for component in read_ssd(str(ssp_path)).system.elements:
        for binding in component.parameterBindings:
            for values in binding.parameterValues:
                for p in values.parameters:
                    name = f"{component.name}.{p.name}"
                    if p.type == "String":
                        raise ValueError(f"{name}: fmpy.ssp.simulate_ssp cannot set String "
                                         "parameters; run this axis with feedaxis's master "
                                         "or libcosim")
                    value = float(p.value == "true") if p.type == "Boolean" else p.value
                    parameter_set.parameters.append(Parameter(name=name, value=value))
    for name, value in (start_values or {}).items():
        parameter_set.parameters.append(Parameter(name=name, value=value))
    return parameter_set
