"""Build the four feedaxis FMUs with pythonfmu and complete their modelDescription.xml.

Each FMU carries its slave script, the shared adapter ``feedaxis_slave`` and a copy of
``feedaxis.physics``, both renamed with the FMU's name (``feedaxis_fmu_physics_ThermalScrew``)
so that FMUs sharing one Python process never import each other's modules; it runs
without feedaxis installed (numpy and scipy in the host's Python suffice). pythonfmu cannot declare units
or limits, so they are added to modelDescription.xml after the build.
"""
from __future__ import annotations

import importlib
import math
import shutil
import sys
import tempfile
import zipfile
import xml.etree.ElementTree as ET
from pathlib import Path

FMU_NAMES = ("NpidServo", "StepperError", "GeometricError", "ThermalScrew")
PHYSICS_PACKAGE = "feedaxis_fmu_physics"
ADAPTER_MODULE = "feedaxis_slave"
SOURCE_DIR = Path(__file__).resolve().parent

# unit -> (factor, SI base-unit exponents) with value_SI = factor * value (degC: offset)
SI_UNITS = {
    "m": (1.0, {"m": 1}), "mm": (1e-3, {"m": 1}), "um": (1e-6, {"m": 1}),
    "mm/s": (1e-3, {"m": 1, "s": -1}), "s": (1.0, {"s": 1}), "K": (1.0, {"K": 1}),
    "degC": (1.0, {"K": 1}), "deg": (math.pi / 180.0, {"rad": 1}),
    "N": (1.0, {"kg": 1, "m": 1, "s": -2}), "Pa": (1.0, {"kg": 1, "m": -1, "s": -2}),
    "kg/m3": (1.0, {"kg": 1, "m": -3}), "um/mm": (1e-3, {}), "1/K": (1.0, {"K": -1}),
    "J/(kg.K)": (1.0, {"m": 2, "s": -2, "K": -1}),
    "W/(m.K)": (1.0, {"kg": 1, "m": 1, "s": -3, "K": -1}),
    "W/(m2.K)": (1.0, {"kg": 1, "s": -3, "K": -1}),
    "W.min/(m3.K)": (6e4, {"kg": 1, "m": -1, "s": -2, "K": -1}),
    "W.min/mm": (6e4, {"kg": 1, "m": 1, "s": -2}),
    "mm/(V.s2)": (1e-3, {"kg": -1, "m": -1, "s": 1, "A": 1}),
    "1/s": (1.0, {"s": -1}), "1/s2": (1.0, {"s": -2}),
    "V/mm": (1e3, {"kg": 1, "m": 1, "s": -3, "A": -1}),
    "V/(mm.s)": (1e3, {"kg": 1, "m": 1, "s": -4, "A": -1}),
    "V.s/mm": (1e3, {"kg": 1, "m": 1, "s": -2, "A": -1}),
    "1/mm": (1e3, {"m": -1}), "N/V": (1.0, {"m": -1, "s": 1, "A": 1}),
    "N.s/mm": (1e3, {"kg": 1, "s": -1}),
}


def build_fmus(out_dir, names=FMU_NAMES):
    """Build the named FMUs into ``out_dir``; return their paths."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    return [build_fmu(name, out_dir) for name in names]


def build_fmu(name, out_dir):
    """Build one FMU ``<out_dir>/<name>.fmu`` and add units and limits to its description."""
    from pythonfmu.builder import FmuBuilder

    physics, adapter = f"{PHYSICS_PACKAGE}_{name}", f"{ADAPTER_MODULE}_{name}"
    with tempfile.TemporaryDirectory(prefix="feedaxis_fmu_") as staging:
        staging = Path(staging)
        shutil.copytree(SOURCE_DIR / "physics", staging / physics,
                        ignore=shutil.ignore_patterns("__pycache__"))
        shutil.copy2(SOURCE_DIR / "fmus" / f"{ADAPTER_MODULE}.py", staging / f"{adapter}.py")
        script = staging / f"{name}.py"
        source = (SOURCE_DIR / "fmus" / f"{name}.py").read_text(encoding="utf-8")
        script.write_text(source.replace(f"from {PHYSICS_PACKAGE} ", f"from {physics} ")
                          .replace(f"from {ADAPTER_MODULE} ", f"from {adapter} "), encoding="utf-8")
        try:
            fmu_path = FmuBuilder.build_FMU(
                script, dest=out_dir, project_files=[staging / physics, staging / f"{adapter}.py"],
                canGetAndSetFMUstate=True, canSerializeFMUstate=True)
            slave = getattr(importlib.import_module(name), name)(instance_name="describe")
        finally:
            _forget_modules(staging, (name, adapter, physics))
    _complete_model_description(Path(fmu_path), slave.units, slave.limits)
    return Path(fmu_path)


def _forget_modules(staging, module_names):
    """Drop the staged modules and path so a later build imports its own copies."""
    while str(staging) in sys.path:
        sys.path.remove(str(staging))
    for module in list(sys.modules):
        if module.split(".")[0] in module_names:
            del sys.modules[module]


def _complete_model_description(fmu_path, units, limits):
    with zipfile.ZipFile(fmu_path) as archive:
        entries = {info: archive.read(info) for info in archive.infolist()}
    description_info = next(i for i in entries if i.filename == "modelDescription.xml")
    root = ET.fromstring(entries[description_info])
    _add_unit_definitions(root, sorted(set(units.values())))
    for variable in root.iter("ScalarVariable"):
        name = variable.get("name")
        type_element = variable[0]
        if name in units:
            type_element.set("unit", units[name])
        lower, upper = limits.get(name, (None, None))
        if lower is not None:
            type_element.set("min", repr(lower))
        if upper is not None:
            type_element.set("max", repr(upper))
    ET.indent(root)
    entries[description_info] = ET.tostring(root, encoding="utf-8", xml_declaration=True)
    with zipfile.ZipFile(fmu_path, "w", zipfile.ZIP_DEFLATED) as archive:
        for info, data in entries.items():
            archive.writestr(info, data)


def _add_unit_definitions(root, unit_names):
    definitions = ET.Element("UnitDefinitions")
    for unit_name in unit_names:
        factor, exponents = SI_UNITS[unit_name]
        unit = ET.SubElement(definitions, "Unit", name=unit_name)
        base = ET.SubElement(unit, "BaseUnit", {k: str(v) for k, v in exponents.items()})
        if factor != 1.0:
            base.set("factor", repr(factor))
        if unit_name == "degC":
            base.set("offset", "273.15")
    position = list(root).index(root.find("CoSimulation")) + 1
    root.insert(position, definitions)
