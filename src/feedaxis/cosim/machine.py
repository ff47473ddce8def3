"""Two co-simulated axes in one machine, and the interpolator that drives them on a circle.

:func:`machine_system` builds one :class:`~feedaxis.cosim.system.AxisSystem` (so the fmpy
master, the SSP export and the system tables work on it unchanged) from two copies of the
one-axis signal flow, each component named after its axis (``X_NpidServo``,
``Y_GeometricError``), plus the machine's own geometry: the out-of-squareness α of the
second axis towards the first, which moves the table α·y along the first axis as the
second travels y (a term of the first axis's table position)::

    X_position_ref_mm -> X_NpidServo -> X_StepperError, X_GeometricError, X_ThermalScrew
    Y_position_ref_mm -> Y_NpidServo -> Y_StepperError, Y_GeometricError, Y_ThermalScrew
    X_table_position_mm = X_NpidServo.position_mm + X errors / 1000 + α · Y_NpidServo.position_mm
    Y_table_position_mm = Y_NpidServo.position_mm + Y errors / 1000

An axis has StepperError only where its motor is known and ThermalScrew only where the
screw's thermal keys are (:func:`machine_from_case_axes`); the default machine has both on
both axes. :class:`CircleInterpolator` commands the circle at the programmed feed, with a
lead-in arc before the measured turn and a lead-out arc after it; driven by its FMU
(:func:`with_interpolator`, ``export-ssp --machine``) the machine counts its position
connectors from the circle's first reference, each FMU rebuilding machine positions from its
``position_offset_mm``.
"""
from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

from ..fmu_map import AXIS_KEYS, neutral_fmu_parameters, servo_to_fmu
from ..physics.circle import MACHINE_PLANT, CircleInterpolator
from ..errors import InputError
from .system import (DEFAULT_THERMAL_STEP_S, AxisSystem, Component, Connection, Output,
                     Variable, axis_overrides, default_axis, option_steps)

AXIS_PARTS = ("NpidServo", "StepperError", "GeometricError", "ThermalScrew")
INTERPOLATOR = "CircleInterpolator"
# the interpolator FMU's outputs, the first and the second axis's reference
INTERPOLATOR_OUTPUTS = ("first_position_ref_mm", "second_position_ref_mm")
REFERENCE_INPUT = "_position_ref_mm"
ERROR_PARTS = ("StepperError", "GeometricError", "ThermalScrew")
# each axis FMU's machine position of 0 mm on its position connectors
POSITION_OFFSET = "position_offset_mm"


def component_name(axis, part):
    """The machine's name for one axis's component: ``X_NpidServo``."""
    return f"{axis}_{part}"


def machine_system(axes=("X", "Y"), parts=None, squareness_urad=0.0, macro_step_s=1e-3,
                   thermal_step_s=DEFAULT_THERMAL_STEP_S):
    """Two axes and their squareness as one system.

    Parameters
    ----------
    axes : (str, str)
        The axis names, first and second axis of the plane.
    parts : dict, optional
        Axis name -> the components it has (NpidServo and GeometricError always; default
        all four).
    squareness_urad : float
        Out-of-squareness α (µrad = µm/m) of the second axis towards the first.
    macro_step_s, thermal_step_s : float
        Master clock and ThermalScrew step (s), as :func:`default_axis`.
    """
    one = default_axis(macro_step_s, macro_step_s, thermal_step_s)
    inputs, components, connections, outputs = [], [], [], []
    for axis in axes:
        kept = tuple(p for p in AXIS_PARTS if parts is None or p in parts[axis]
                     or p in ("NpidServo", "GeometricError"))
        inputs += [Variable(f"{axis}_{v.name}", v.unit, f"axis {axis}: {v.description}",
                            v.start) for v in one.inputs if v.name != "ambient_C"]
        components += [Component(component_name(axis, c.name), c.fmu, c.step_s,
                                 {**c.parameters, **(MACHINE_PLANT if c.name == "NpidServo"
                                                     else {})}, f"axis {axis}: {c.description}")
                       for c in one.components if c.name in kept]
        connections += [Connection(_renamed(c.source, axis), _renamed(c.target, axis))
                        for c in one.connections if c.target_component in kept]
        errors = tuple((f"{component_name(axis, p)}.error_um", 1.0) for p in ERROR_PARTS
                       if p in kept)
        outputs.append(Output(Variable(f"{axis}_positioning_error_um", "um",
                                       f"axis {axis}: table - servo position"), errors))
        table = ((f"{component_name(axis, 'NpidServo')}.position_mm", 1.0),) + tuple(
            (term, 1e-3) for term, _ in errors)
        if axis == axes[0] and squareness_urad:
            table += ((f"{component_name(axes[1], 'NpidServo')}.position_mm",
                       squareness_urad * 1e-6),)
        outputs.append(Output(Variable(f"{axis}_table_position_mm", "mm",
                                       f"axis {axis}: table position"), table))
    inputs.append(Variable("ambient_C", "degC", "ambient air temperature", 20.0))
    return AxisSystem("Machine", macro_step_s, tuple(inputs), tuple(components),
                      tuple(connections), tuple(outputs))


def _renamed(end, axis):
    """A connection end of the one-axis system in the machine (``ambient_C`` is shared)."""
    if end == "ambient_C":
        return end
    component, _, variable = end.partition(".")
    return f"{component_name(axis, component)}.{variable}" if variable else f"{axis}_{end}"


def machine_from_case_axes(machine, squareness_urad=0.0, macro_step_s=1e-3,
                           thermal_step_s=DEFAULT_THERMAL_STEP_S):
    """The system of a circular case's machine (:class:`feedaxis.circular_case.Machine`): each axis
    with StepperError where its ``[motor]`` is given, ThermalScrew where its screw has
    every thermal key, its ``[servo]`` controller in NpidServo, the axis.toml keys in the
    FMUs that take them; every catalog effect switched off (its neutral values)."""
    axes = machine.circular.axes
    parts = {name: _parts_of(machine.axes[name]) for name in axes}
    system = machine_system(axes, parts, squareness_urad, macro_step_s, thermal_step_s)
    return system.with_parameters(machine_parameters(machine, system))


def circular_machine(machine_path=None, radius_mm=None, feed_mm_min=None, center_mm=None,
                     squareness_urad=0.0, step_ms=1.0, thermal_step_s=None, set_items=(),
                     model_path=None):
    """(system, circle) of ``feedaxis simulate circular``: the machine of a circular case's
    axis.toml (or case folder) ``machine_path``, else axes X and Y with the FMUs' defaults;
    the circle's radius, feed and centre (``{"radius_mm", "feed_mm_min", "center_mm"}``)
    from the options, else that axis.toml's ``[circular]``, else R 100 mm, F 1000 mm/min,
    centre (R, R). A fitted model ``model_path`` (of a circular case on that machine) sets
    its effects' FMU parameters (:func:`model_parameters`) and its squareness; ``--set``
    items name the machine's components (``X_NpidServo.kp_V_per_mm``) and come last.
    """
    step_s, thermal_step_s = option_steps(step_ms, thermal_step_s)
    circle = {"radius_mm": 100.0, "feed_mm_min": 1000.0, "center_mm": None}
    overrides = {}
    if model_path and not machine_path:
        raise InputError("needs --machine (the axis.toml or case folder it was fitted on): "
                         "the FMU parameters depend on the machine", parameter="--model")
    if machine_path:
        from ..circular_case import read_machine

        path = Path(machine_path)
        machine = read_machine(path / "axis.toml" if path.is_dir() else path)
        if model_path:
            overrides, squareness_urad = model_parameters(machine, model_path, squareness_urad)
        system = machine_from_case_axes(machine, squareness_urad, step_s, thermal_step_s)
        circle = {"radius_mm": machine.circular.radius_mm,
                  "feed_mm_min": machine.circular.feed_mm_min,
                  "center_mm": machine.circular.center_mm}
    else:
        system = machine_system(squareness_urad=squareness_urad, macro_step_s=step_s,
                                thermal_step_s=thermal_step_s)
    given = {"radius_mm": radius_mm, "feed_mm_min": feed_mm_min, "center_mm": center_mm}
    for key, value in given.items():
        if value is not None:
            circle[key] = value
    for option, key in (("--radius-mm", "radius_mm"), ("--feed-mm-min", "feed_mm_min")):
        if not (math.isfinite(circle[key]) and circle[key] > 0):
            raise InputError(f"must be > 0, got {circle[key]:g}", parameter=option)
    if circle["center_mm"] is None:
        circle["center_mm"] = (circle["radius_mm"], circle["radius_mm"])
    if len(circle["center_mm"]) != 2 or not all(map(math.isfinite, circle["center_mm"])):
        raise InputError("expected two finite coordinates C1,C2", parameter="--center-mm")
    circle["center_mm"] = tuple(float(c) for c in circle["center_mm"])
    return (system.with_parameters(overrides).with_parameters(axis_overrides(set_items=set_items)),
            circle)


def model_parameters(machine, model_path, squareness_urad=0.0):
    """({component: {parameter: value}}, squareness in µrad) of a model fitted on a circular
    case of ``machine``: each effect of an axis in that axis's FMUs (``X_GeometricError``),
    the model's ``squareness`` in place of ``squareness_urad``. A ``servo_mismatch`` (a lag
    difference fitted without the plants) has no FMU parameter and is refused."""
    from ..effects import load_model
    from ..effects.circular import circular_effects

    model = load_model(model_path, circular_effects(machine))
    if "servo_mismatch" in model:
        raise InputError("[servo_mismatch] is a lag difference fitted without the axes' "
                         "plants: no FMU parameter reproduces it; fit servo_plant@AXIS on a "
                         "case with [axes.AXIS.servo], or set X_NpidServo values with --set",
                         path=model_path, column="servo_mismatch")
    overrides = {}
    for effect in model.effects:
        for component, values in effect.fmu_parameters(machine,
                                                       model.values[effect.name]).items():
            overrides.setdefault(component, {}).update(values)
    return overrides, model.values.get("squareness", {}).get("squareness_urad",
                                                              squareness_urad)


def _parts_of(axis):
    parts = {"NpidServo", "GeometricError"}
    if set(AXIS_KEYS["motor"]["StepperError"]) <= set(axis.motor):
        parts.add("StepperError")
    if set(AXIS_KEYS["screw"]["ThermalScrew"]) <= set(axis.screw):
        parts.add("ThermalScrew")
    return parts


def machine_parameters(machine, system):
    """{component: {parameter: value}} of each axis's axis.toml and neutral effects."""
    names = {c.name for c in system.components}
    overrides = {}
    for axis_name, axis in machine.axes.items():
        for fmu, values in neutral_fmu_parameters(axis).items():
            if component_name(axis_name, fmu) in names:
                overrides[component_name(axis_name, fmu)] = values
        if axis.servo:
            overrides[component_name(axis_name, "NpidServo")] = servo_to_fmu(axis.servo)
    return overrides


def reference_axes(system):
    """The axes whose servo references are system inputs (``X_position_ref_mm``), in order."""
    return [v.name[:-len(REFERENCE_INPUT)] for v in system.inputs
            if v.name.endswith(REFERENCE_INPUT)]


def interpolator_parameters(path, ahead_s, origin_mm=(0.0, 0.0)):
    """The CircleInterpolator FMU's parameter values commanding ``path``
    (:class:`feedaxis.physics.circle.CircleInterpolator`) ``ahead_s`` ahead, its outputs
    counted from the machine position ``origin_mm`` (first, second axis)."""
    return {"radius_mm": float(path.radius_mm), "feed_mm_min": float(path.feed_mm_min),
            "center_first_mm": float(path.center_mm[0]),
            "center_second_mm": float(path.center_mm[1]), "direction": int(path.direction),
            "start_deg": float(path.start_deg), "lead_in_deg": float(path.lead_in_deg),
            "lead_out_deg": float(path.lead_out_deg), "ahead_s": float(ahead_s),
            "origin_first_mm": float(origin_mm[0]), "origin_second_mm": float(origin_mm[1])}


def first_reference_mm(path, ahead_s):
    """(first, second axis) position (mm) the CircleInterpolator FMU commanding ``path``
    ``ahead_s`` ahead outputs at initialisation: the circle at ``ahead_s``."""
    return tuple(float(path.position_mm(ahead_s, index)) for index in (0, 1))


def interpolator_path(system):
    """The circle the CircleInterpolator component of ``system`` commands (the inverse of
    :func:`interpolator_parameters`)."""
    values = system.component(INTERPOLATOR).parameters
    return CircleInterpolator(values["radius_mm"], values["feed_mm_min"],
                              (values["center_first_mm"], values["center_second_mm"]),
                              values["direction"], values["start_deg"], values["lead_in_deg"],
                              values["lead_out_deg"])


def with_interpolator(system, path):
    """The machine ``system`` driven round ``path`` by the CircleInterpolator FMU: its
    outputs connected to the axes' servo references in place of the system inputs
    ``X_position_ref_mm`` and ``Y_position_ref_mm``.

    Its outputs after the step ending at t are the circle at t + h (h the macro step): a
    host stepping Jacobi gives each servo over [t, t + h] the circle at t + h, the reference
    feedaxis's master gives it (:func:`feedaxis.cosim.circular.run_circular`), and at
    initialisation the circle at h, as the master does.

    The position connectors count from that first reference (:func:`relative_to`): every
    one is 0 at the start, so a host that passes nothing on before the first step (fmpy's
    simulate_ssp sets every connector to 0) runs the same system as one that does.
    """
    axes = reference_axes(system)
    if len(axes) != 2:
        raise ValueError(f"a machine of two axes has two servo references, got {axes}")
    sources = {f"{axis}{REFERENCE_INPUT}": f"{INTERPOLATOR}.{output}"
               for axis, output in zip(axes, INTERPOLATOR_OUTPUTS)}
    origin_mm = first_reference_mm(path, system.macro_step_s)
    interpolator = Component(INTERPOLATOR, INTERPOLATOR, system.macro_step_s,
                             interpolator_parameters(path, system.macro_step_s, origin_mm),
                             "circle interpolator: both axes' references, one macro step ahead")
    system = relative_to(system, dict(zip(axes, origin_mm)))
    return replace(system, inputs=tuple(v for v in system.inputs if v.name not in sources),
                   components=(interpolator, *system.components),
                   connections=tuple(replace(c, source=sources.get(c.source, c.source))
                                     for c in system.connections))


def relative_to(system, origin_mm):
    """The machine ``system`` with each axis's position connectors counted from its
    ``origin_mm`` ({axis: machine position, mm}): every FMU of the axis gets it as
    ``position_offset_mm`` (its physics still sees machine positions), and each table
    position adds it back where a servo's position_mm enters (squareness included)."""
    names = {c.name for c in system.components}
    offsets = {component_name(axis, part): {POSITION_OFFSET: float(value)}
               for axis, value in origin_mm.items() for part in AXIS_PARTS
               if component_name(axis, part) in names}
    servo_mm = {f"{component_name(axis, 'NpidServo')}.position_mm": float(value)
                for axis, value in origin_mm.items()}
    outputs = tuple(replace(output, constant=output.constant + sum(
        factor * servo_mm.get(term, 0.0) for term, factor in output.terms))
        for output in system.outputs)
    return replace(system.with_parameters(offsets), outputs=outputs)
