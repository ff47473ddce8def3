"""FMI 3.0 co-simulation FMUs from the FMI 2.0 build (``feedaxis build-fmus --fmi 3``).

The same slave, physics and host layer as the FMI 2.0 FMU: the host layer is compiled with
``FEEDAXIS_FMI3``, so the model-identifier library exports the fmi3 functions (checked
against the FMI 3.0 state table, fmus/common/host/fmi3_states.c) over the layer's own fmi2
functions, which it no longer exports; modelDescription.xml is written in FMI 3.0's schema
from the completed FMI 2.0 one (same variables, value references, units, limits and
descriptions: Real becomes Float64, Integer Int32); the binaries move to FMI 3.0's platform
folder ``binaries/x86_64-linux``, the only one the FMU carries. Why not pythonfmu3:
docs/fmus.md, "FMI 3.0".
"""
from __future__ import annotations

import xml.etree.ElementTree as ET

PLATFORM = "x86_64-linux"
FMI2_PLATFORM = "linux64"
TYPES = {"Real": "Float64", "Integer": "Int32", "Boolean": "Boolean", "String": "String"}
CAPABILITIES = ("modelIdentifier", "needsExecutionTool", "canHandleVariableCommunicationStepSize",
                "canBeInstantiatedOnlyOncePerProcess")


def description_fmi3(fmi2_xml):
    """FMI 3.0 modelDescription.xml (bytes) of the FMU whose FMI 2.0 one is ``fmi2_xml``."""
    old = ET.fromstring(fmi2_xml)
    root = ET.Element("fmiModelDescription", fmiVersion="3.0")
    for key in ("modelName", "description", "author", "license", "generationTool",
                "generationDateAndTime", "variableNamingConvention"):
        if old.get(key) is not None:
            root.set(key, old.get(key))
    root.set("instantiationToken", old.get("guid"))
    root.set("generationTool", f"feedaxis over {old.get('generationTool')}")
    co_simulation = old.find("CoSimulation")
    ET.SubElement(root, "CoSimulation",
                  {**{k: co_simulation.get(k) for k in CAPABILITIES if co_simulation.get(k)},
                   "canGetAndSetFMUState": "true", "canSerializeFMUState": "true",
                   "hasEventMode": "false", "providesIntermediateUpdate": "false"})
    root.append(_with_seconds(old.find("UnitDefinitions")))
    root.append(_log_categories(old.find("LogCategories")))
    root.append(old.find("DefaultExperiment"))
    variables = ET.SubElement(root, "ModelVariables")
    scalars = list(old.iter("ScalarVariable"))
    ET.SubElement(variables, "Float64", name="time", valueReference=str(time_value_reference(
        int(scalar.get("valueReference")) for scalar in scalars)), causality="independent",
        variability="continuous", unit="s", description="Simulation time")
    outputs = [_variable(variables, scalar) for scalar in scalars]
    structure = ET.SubElement(root, "ModelStructure")
    for tag in ("Output", "InitialUnknown"):
        for vr in filter(None, outputs):
            ET.SubElement(structure, tag, valueReference=vr, dependencies="")
    ET.indent(root)
    return ET.tostring(root, encoding="utf-8", xml_declaration=True)


def time_value_reference(value_references):
    """The value reference of the independent variable ``time``: after every other one."""
    return max(value_references) + 1


def _with_seconds(units):
    """``units`` with the second, time's unit."""
    if not any(unit.get("name") == "s" for unit in units):
        ET.SubElement(ET.SubElement(units, "Unit", name="s"), "BaseUnit", s="1")
    return units


def _log_categories(categories):
    for category in categories:
        category.set("description", category.get("description").replace("fmi2", "fmi3"))
    return categories


def _variable(parent, scalar):
    """Append FMI 3.0's element of FMI 2.0 ``scalar``; its value reference if an output."""
    typed = scalar[0]
    element = ET.SubElement(parent, TYPES[typed.tag],
                            {k: scalar.get(k) for k in ("name", "valueReference", "description",
                                                        "causality", "variability", "initial")
                             if scalar.get(k) is not None})
    for key in ("unit", "min", "max"):
        if typed.get(key) is not None:
            element.set(key, typed.get(key))
    start = typed.get("start")
    if start is not None and typed.tag == "String":
        ET.SubElement(element, "Start", value=start)
    elif start is not None:
        element.set("start", start)
    return scalar.get("valueReference") if scalar.get("causality") == "output" else None


def repackage(entries, name, host_library, pythonfmu_library):
    """The FMI 3.0 FMU's entries from the FMI 2.0 build's ``entries`` (name -> bytes), its
    host layer ``host_library`` (bytes) and pythonfmu's library beside it, named
    ``pythonfmu_library``."""
    fmi2_binaries = f"binaries/{FMI2_PLATFORM}/"
    moved = {key.replace(fmi2_binaries, f"binaries/{PLATFORM}/", 1): data
             for key, data in entries.items() if key.startswith(fmi2_binaries)}
    kept = {key: data for key, data in entries.items() if not key.startswith("binaries/")}
    moved[f"binaries/{PLATFORM}/{pythonfmu_library}"] = entries[f"{fmi2_binaries}{name}.so"]
    moved[f"binaries/{PLATFORM}/{name}.so"] = host_library
    kept["modelDescription.xml"] = description_fmi3(entries["modelDescription.xml"])
    return {**kept, **moved}
