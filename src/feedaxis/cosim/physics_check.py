"""Parameter values checked by the physics each FMU is built on, before any FMU runs.

An FMU refuses bad parameter values only at initialisation, after it was instantiated,
and a pythonfmu slave that raises there can leave the host unstable; so every component's
values (the FMU's start values under the system's) first go through the same physics
constructors the FMU adapters' ``build`` calls, here, in-process.
"""
from __future__ import annotations

from dataclasses import fields

from ..errors import ParameterError
from ..physics import geometry, motor, servo, thermal
from .system import check_parameter_values


def _servo(values):
    servo.ServoParams(**{f.name: values[f.name] for f in fields(servo.ServoParams)})


def _stepper(values):
    motor.motor_error_period_mm(values["lead_mm"], values["step_angle_deg"],
                                values["error_period_steps"])


def _geometric(values):
    if values["support"] not in geometry.SUPPORTS:
        raise ParameterError(f"must be one of {', '.join(geometry.SUPPORTS)}, got "
                             f"{values['support']!r}", "support")
    geometry.gravity_sag_table(values["length_m"], values["diameter_m"],
                               values["density_kg_m3"], values["youngs_modulus_Pa"],
                               values["support"], n_grid=3)


def _thermal(values):
    thermal.ThermalScrewParams(**{f.name: values[f.name]
                                  for f in fields(thermal.ThermalScrewParams)})


BUILDERS = {"NpidServo": _servo, "StepperError": _stepper, "GeometricError": _geometric,
            "ThermalScrew": _thermal}


def start_value(variable):
    """The declared start value of an FMU variable as a Python value."""
    convert = {"Real": float, "Integer": int, "String": str,
               "Boolean": lambda text: text in ("true", "1")}[variable.type]
    return convert(variable.start)


def check_physics(component, variables):
    """Raise :class:`ParameterError` naming ``Component.parameter`` when the physics of the
    component's FMU refuses its values (``variables``: the FMU's, name -> model variable)."""
    build = BUILDERS.get(component.fmu)
    if build is None:
        return
    values = {name: start_value(v) for name, v in variables.items()
              if v.causality == "parameter" and v.start is not None}
    try:
        build({**values, **component.parameters})
    except ParameterError as error:
        raise ParameterError(error.message, f"{component.name}.{error.parameter}") from None


def check_parameters(system, fmu_paths, variables=None):
    """Raise :class:`ParameterError` unless every component's parameter values name its
    FMU's parameters, have their types, lie within their bounds and pass the physics.

    ``variables`` ({component: {name: model variable}}, :func:`fmu_variables`) saves
    reading the FMUs' model descriptions again.
    """
    variables = variables or fmu_variables(system, fmu_paths)
    for component in system.components:
        check_parameter_values(component, variables[component.name])
        check_physics(component, variables[component.name])


def fmu_variables(system, fmu_paths):
    """{component: {name: model variable}} from each component's FMU."""
    from fmpy import read_model_description

    from .fmu_runner import fmi2_variables

    return {c.name: fmi2_variables(read_model_description(str(fmu_paths[c.fmu])))
            for c in system.components}
