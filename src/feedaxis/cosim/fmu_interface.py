"""What feedaxis needs of each of its FMUs, checked before one is used: an FMU of
``--fmus DIR`` or of the cache whose model description cannot be read, or that lacks a
variable the axis connects, records or sets (a renamed one), is refused naming the FMU and
the variable, never a failure half-way through a simulation.
"""
from __future__ import annotations

import zipfile
import zlib
from functools import lru_cache

from ..errors import InputError
from ..fmu_map import AXIS_KEYS, NEUTRAL, SERVO_KEYS
from .fmu_runner import check_fmu_archive


@lru_cache(maxsize=1)
def expected_interface():
    """{FMU name: {variable: causality}}: the inputs and outputs the axis connects and
    records, the parameters the axis, the effects and axis.toml set, and what a machine's
    SSP connects and sets of the circle interpolator and of each axis FMU (its
    ``position_offset_mm``)."""
    from ..physics.circle import CircleInterpolator
    from .machine import (AXIS_PARTS, INTERPOLATOR, INTERPOLATOR_OUTPUTS, POSITION_OFFSET,
                          interpolator_parameters)
    from .system import default_axis

    system = default_axis()
    needed = {component.fmu: {name: "parameter" for name in component.parameters}
              for component in system.components}
    fmu_of = {component.name: component.fmu for component in system.components}

    def add(reference, causality):
        component, name = reference.split(".", 1)
        needed[fmu_of[component]][name] = causality

    for connection in system.connections:
        add(connection.target, "input")
        if connection.source_component:
            add(connection.source, "output")
    for output in system.outputs:
        for term, _ in output.terms:
            add(term, "output")
    for fmu, values in NEUTRAL.items():
        needed[fmu].update(dict.fromkeys(values, "parameter"))
    for table in AXIS_KEYS.values():
        for fmu, keys in table.items():
            needed[fmu].update(dict.fromkeys(keys, "parameter"))
    needed["NpidServo"].update(dict.fromkeys(SERVO_KEYS.values(), "parameter"))
    for part in AXIS_PARTS:
        needed[part][POSITION_OFFSET] = "parameter"
    needed[INTERPOLATOR] = {**dict.fromkeys(INTERPOLATOR_OUTPUTS, "output"),
                            **dict.fromkeys(interpolator_parameters(
                                CircleInterpolator(1.0, 1.0, (0.0, 0.0)), 0.0), "parameter")}
    return needed


def check_fmu(path, name):
    """The fmpy model description of ``path``; :class:`InputError` naming ``path`` unless it
    is a safe FMU archive whose model description reads and declares every variable
    :func:`expected_interface` gives FMU ``name``, with its causality."""
    from fmpy import read_model_description

    check_fmu_archive(path)
    try:
        description = read_model_description(str(path))
    except Exception as error:  # fmpy raises whatever lxml or its own checks raise
        raise InputError(f"its modelDescription.xml cannot be read: {error}",
                         path=path) from None
    declared = {v.name: v.causality for v in description.modelVariables}
    for variable, causality in expected_interface()[name].items():
        if declared.get(variable) != causality:
            found = (f"declares it as {declared[variable]}" if variable in declared
                     else "does not declare it")
            raise InputError(f"not a {name} FMU of feedaxis: the axis needs the {causality} "
                             f"{variable}, and the FMU {found}", path=path)
    return description


def intact(paths):
    """Whether every FMU of ``paths`` ({name: path}) exists, passes :func:`check_fmu` and
    holds no member whose CRC fails (a flipped byte anywhere; some 0.1 s for the four)."""
    try:
        for name, path in paths.items():
            check_fmu(path, name)
            with zipfile.ZipFile(path) as archive:
                if archive.testzip() is not None:
                    return False
    except (InputError, OSError, zipfile.BadZipFile, zlib.error):
        return False
    return True
