"""The one description of the co-simulated axis: components, connections, parameters, steps.

The fmpy master (:mod:`.master`), the SSP export (:mod:`.ssp`) and docs/cosim.md's system
table (:func:`markdown_tables`) are all generated from an :class:`AxisSystem`. The default
axis (:func:`default_axis`) is the signal flow of issue 3::

    position_ref_mm, disturbance_N -> NpidServo -> position_mm, velocity_mm_s
        -> StepperError, GeometricError, ThermalScrew (+ ambient_C) -> error_um each
    positioning_error_um = sum of the three error_um
    table_position_mm    = NpidServo.position_mm + positioning_error_um / 1000

Multi-rate scheme: the macro step h is the master's clock. A component with communication
step r·h (r a whole number) steps on the macro steps k with (k + 1) mod r = 0, over
[t_{k+1} - r·h, t_{k+1}], so every step ends on a macro grid point; between its steps its
outputs are held. Components step in dependency order within a macro step (Gauss-Seidel):
an input connected to an upstream output sees that output at t_{k+1}; a system input sees
its value k (held over [t_k, t_{k+1})).
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path

from ..errors import InputError, ParameterError

DEFAULT_THERMAL_STEP_S = 0.1


@dataclass(frozen=True)
class Variable:
    """A system input or output: name with its unit suffix, unit, meaning."""

    name: str
    unit: str
    description: str
    start: float = 0.0


@dataclass(frozen=True)
class Component:
    """One FMU instance: its model (FMU name), communication step and parameter values."""

    name: str
    fmu: str
    step_s: float
    parameters: dict = field(default_factory=dict)
    description: str = ""


@dataclass(frozen=True)
class Connection:
    """``source`` ("Component.variable" or a system input name) drives ``target``."""

    source: str
    target: str

    @property
    def target_component(self):
        return self.target.split(".", 1)[0]

    @property
    def source_component(self):
        """The source's component, or None for a system input."""
        return self.source.split(".", 1)[0] if "." in self.source else None


@dataclass(frozen=True)
class Output:
    """A system output: a linear combination of component outputs plus a constant,
    constant + sum(factor x term)."""

    variable: Variable
    terms: tuple
    constant: float = 0.0

    def formula(self):
        """The combination as text, e.g. ``A.x + 0.001 B.y`` (``61.5 + A.x`` with a constant)."""
        parts = [(f"{factor:g} " if factor != 1.0 else "") + term for term, factor in self.terms]
        return " + ".join(([repr(self.constant)] if self.constant else []) + parts)


@dataclass(frozen=True)
class AxisSystem:
    """Components, connections, inputs and outputs of the co-simulated axis, and its clock."""

    name: str
    macro_step_s: float
    inputs: tuple
    components: tuple
    connections: tuple
    outputs: tuple

    def __post_init__(self):
        if not (math.isfinite(self.macro_step_s) and self.macro_step_s > 0):
            raise ValueError(f"macro step must be > 0 s, got {self.macro_step_s!r}")
        for component in self.components:
            self.ratio(component)
        names = {c.name for c in self.components}
        inputs = {v.name for v in self.inputs}
        targets = [c.target for c in self.connections]
        twice = sorted({t for t in targets if targets.count(t) > 1})
        if twice:
            raise ValueError(f"{', '.join(twice)}: driven by more than one connection")
        for connection in self.connections:
            if connection.target_component not in names:
                raise ValueError(f"connection target {connection.target}: no such component")
            source = connection.source_component
            if (source is None and connection.source not in inputs) or (
                    source is not None and source not in names):
                raise ValueError(f"connection source {connection.source}: no such input "
                                 "or component")
        self.ordered_components()

    def output_values(self, columns):
        """{system output: values} from ``columns`` ({"Component.variable": values}), each
        output the linear combination of its terms."""
        return {output.variable.name: output.constant + sum(factor * columns[term]
                                                            for term, factor in output.terms)
                for output in self.outputs}

    def component(self, name):
        """The component called ``name``."""
        for component in self.components:
            if component.name == name:
                return component
        raise ParameterError(f"no component {name!r}; components: "
                             f"{', '.join(c.name for c in self.components)}", name)

    def ratio(self, component):
        """Macro steps per communication step of ``component`` (a whole number >= 1)."""
        ratio = whole_ratio(component.step_s, self.macro_step_s)
        if ratio is None:
            raise ParameterError(f"{component.name} step {component.step_s:g} s must be a whole "
                                 f"multiple of the macro step {self.macro_step_s:g} s",
                                 f"{component.name} step")
        return ratio

    def inputs_of(self, component_name):
        """Connections that drive ``component_name``, in declaration order."""
        return [c for c in self.connections if c.target_component == component_name]

    def ordered_components(self):
        """Components in dependency order (every source before its targets)."""
        ordered, remaining = [], list(self.components)
        while remaining:
            done = {c.name for c in ordered}
            ready = [c for c in remaining
                     if all(s.source_component in (None, *done)
                            for s in self.inputs_of(c.name))]
            if not ready:
                raise ValueError("the connections form an algebraic loop: "
                                 f"{', '.join(c.name for c in remaining)}")
            ordered.extend(ready)
            remaining = [c for c in remaining if c not in ready]
        return ordered

    def with_parameters(self, overrides):
        """A copy with ``{component: {parameter: value}}`` merged over the parameter values.

        ``Model.fmu_parameters(axis)`` of a fitted model has this form; components it names
        that this system lacks are an error.
        """
        for name in overrides:
            self.component(name)
        components = tuple(
            replace(c, parameters={**c.parameters, **overrides.get(c.name, {})})
            for c in self.components)
        return replace(self, components=components)

    def with_steps(self, macro_step_s=None, **step_s):
        """A copy with a new macro step and/or component steps (``ThermalScrew=1.0``)."""
        for name in step_s:
            self.component(name)
        components = tuple(replace(c, step_s=step_s.get(c.name, c.step_s))
                           for c in self.components)
        return replace(self, macro_step_s=macro_step_s or self.macro_step_s,
                       components=components)


def whole_ratio(step_s, macro_step_s):
    """``step_s / macro_step_s`` when it is a whole number >= 1, else None."""
    ratio = step_s / macro_step_s
    if math.isfinite(ratio) and ratio >= 1 - 1e-9 and abs(ratio - round(ratio)) < 1e-6:
        return int(round(ratio))
    return None


ERROR_COMPONENTS = ("StepperError", "GeometricError", "ThermalScrew")
FMI_TYPES = {bool: "Boolean", int: "Integer", float: "Real", str: "String"}


def check_parameter_values(component, variables):
    """Raise :class:`ParameterError` unless every parameter value of ``component`` names a
    parameter of its FMU (``variables``: name -> model variable) with a value of its type
    within its declared min and max."""
    for name, value in component.parameters.items():
        where = f"{component.name}.{name}"
        declared = variables.get(name)
        if declared is None or declared.causality != "parameter":
            known = sorted(n for n, v in variables.items() if v.causality == "parameter")
            raise ParameterError(f"no parameter {name}; its parameters: {', '.join(known)}",
                                 component.name)
        kind = FMI_TYPES.get(type(value))
        if kind != declared.type and not (kind == "Integer" and declared.type == "Real"):
            raise ParameterError(f"{declared.type} parameter, got {value!r}", where)
        if kind in ("Integer", "Real"):
            _check_within(where, value, declared)


def _check_within(where, value, declared):
    if not math.isfinite(value):
        raise ParameterError(f"must be finite, got {value!r}", where)
    if declared.min is not None and value < float(declared.min):
        raise ParameterError(f"must be >= {declared.min} (the FMU's minimum), got {value!r}",
                             where)
    if declared.max is not None and value > float(declared.max):
        raise ParameterError(f"must be <= {declared.max} (the FMU's maximum), got {value!r}",
                             where)


def fmi_text(value):
    """A parameter value as FMI/SSP XML text (Booleans as true/false)."""
    return str(value).lower() if isinstance(value, bool) else repr(value) \
        if isinstance(value, float) else str(value)


def default_axis(macro_step_s=1e-3, servo_step_s=1e-3, thermal_step_s=0.1):
    """The four-FMU feed axis with the FMUs' default physics (the four papers).

    Parameters
    ----------
    macro_step_s : float
        Master clock h (s).
    servo_step_s : float
        Communication step of NpidServo, StepperError and GeometricError (s).
    thermal_step_s : float
        Communication step of ThermalScrew (s); its field is advanced in sub-steps of at
        most its ``time_step_s`` (0.1 s, Rong et al. 2023).
    """
    inputs = (
        Variable("position_ref_mm", "mm", "commanded axis position"),
        Variable("disturbance_N", "N", "axial disturbance force, e.g. cutting force"),
        Variable("ambient_C", "degC", "ambient air temperature", 20.0),
    )
    components = (
        Component("NpidServo", "NpidServo", servo_step_s,
                  {"nonlinear": False, "time_step_s": 1e-4},
                  "position loop, PID or NPID (Anang et al. 2017 Eq. 1-8) or a drive's cascade"),
        Component("StepperError", "StepperError", servo_step_s, {},
                  "motor step error (Liu 2022 Eq. 6, 9, 10)"),
        Component("GeometricError", "GeometricError", servo_step_s, {"sag_enabled": True},
                  "lead, eccentricity, backlash, sag (Liu 2022/2023)"),
        Component("ThermalScrew", "ThermalScrew", thermal_step_s,
                  {"reference_ambient_C": 20.0, "time_step_s": 0.1},
                  "screw heating (Rong et al. 2023 Eq. 1-19)"),
    )
    connections = (
        Connection("position_ref_mm", "NpidServo.position_ref_mm"),
        Connection("disturbance_N", "NpidServo.disturbance_N"),
        Connection("NpidServo.position_mm", "StepperError.position_mm"),
        Connection("NpidServo.position_mm", "GeometricError.position_mm"),
        Connection("NpidServo.velocity_mm_s", "GeometricError.velocity_mm_s"),
        Connection("NpidServo.position_mm", "ThermalScrew.position_mm"),
        Connection("NpidServo.velocity_mm_s", "ThermalScrew.velocity_mm_s"),
        Connection("ambient_C", "ThermalScrew.ambient_C"),
    )
    errors = tuple((f"{name}.error_um", 1.0) for name in ERROR_COMPONENTS)
    outputs = (
        Output(Variable("positioning_error_um", "um",
                        "table position - servo position, sum of the three error_um"), errors),
        Output(Variable("table_position_mm", "mm", "actual table position"),
               (("NpidServo.position_mm", 1.0),) + tuple((t, 1e-3) for t, _ in errors)),
    )
    return AxisSystem("FeedAxis", macro_step_s, inputs, components, connections, outputs)


def axis_from_options(step_ms, thermal_step_s=None, model_path=None, axis_path=None,
                      set_items=(), effects=None):
    """The default axis at ``step_ms`` with a fitted model's and ``--set`` values over it.

    Parameters
    ----------
    step_ms : float
        Macro step = servo, motor and geometry step (ms).
    thermal_step_s : float, optional
        ThermalScrew step, a whole multiple of the macro step (s); default 0.1 s rounded up
        to a whole number of macro steps, so any ``step_ms`` works.
    model_path, axis_path : path, optional
        A fitted model (TOML) and the axis.toml or case folder it was fitted on: the
        model's FMU parameter values (:meth:`~feedaxis.effects.Model.fmu_parameters`).
    set_items : sequence of str
        ``COMPONENT.PARAMETER=VALUE`` items, applied last.
    effects : dict, optional
        Effects the model may name (default: the catalog).

    Raises
    ------
    InputError
        Naming the option (``--step-ms``, ``--thermal-step-s``, ``--model``, ``--set ...``).
    """
    step_s, thermal_step_s = option_steps(step_ms, thermal_step_s)
    overrides = axis_overrides(model_path, axis_path, set_items, effects)
    return default_axis(step_s, step_s, thermal_step_s).with_parameters(overrides)


def option_steps(step_ms, thermal_step_s=None):
    """(macro step, ThermalScrew step) in s from ``--step-ms`` and ``--thermal-step-s``
    (default 0.1 s rounded up to a whole number of macro steps); :class:`InputError`
    naming the option."""
    for option, value in (("--step-ms", step_ms), ("--thermal-step-s", thermal_step_s)):
        if value is not None and not (math.isfinite(value) and value > 0):
            raise InputError(f"must be > 0, got {value:g}", parameter=option)
    step_s = step_ms * 1e-3
    if thermal_step_s is None:
        thermal_step_s = step_s * math.ceil(DEFAULT_THERMAL_STEP_S / step_s - 1e-9)
    elif whole_ratio(thermal_step_s, step_s) is None:
        raise InputError(f"{thermal_step_s:g} s must be a whole multiple of the macro step "
                         f"--step-ms {step_ms:g}", parameter="--thermal-step-s")
    return step_s, thermal_step_s


def axis_overrides(model_path=None, axis_path=None, set_items=(), effects=None):
    """{component: {parameter: value}} from a fitted model on its axis and ``--set`` items,
    the items last (see :func:`axis_from_options`)."""
    overrides = {}
    if model_path:
        if not axis_path:
            raise InputError("needs --axis (the axis.toml or case folder it was fitted on): "
                             "the FMU parameters depend on the axis", parameter="--model")
        from ..case import read_axis
        from ..effects import CATALOG, load_model

        axis_path = Path(axis_path)
        axis = read_axis(axis_path / "axis.toml" if axis_path.is_dir() else axis_path)
        overrides = load_model(model_path, CATALOG if effects is None else effects) \
            .fmu_parameters(axis)
    for item in set_items or ():
        name, _, value = item.partition("=")
        component, _, parameter = name.partition(".")
        if not (component and parameter and value):
            raise InputError("expected COMPONENT.PARAMETER=VALUE, e.g. NpidServo.nonlinear=true",
                             parameter=f"--set {item}")
        overrides.setdefault(component, {})[parameter] = parameter_value(value)
    return overrides


def parameter_value(text):
    """A ``--set`` value: true/false, an integer, a number, else the text."""
    if text.lower() in ("true", "false"):
        return text.lower() == "true"
    for convert in (int, float):
        try:
            return convert(text)
        except ValueError:
            pass
    return text


def markdown_tables(system):
    """The system as Markdown tables (components, connections, outputs) for docs/cosim.md.

    Regenerate that section with ``python -m feedaxis.cosim.system``.
    """
    lines = [f"Macro step {system.macro_step_s * 1e3:g} ms; components in dependency order.",
             "", "| component | FMU | step | parameter values | role |", "|---|---|---|---|---|"]
    for c in system.ordered_components():
        values = ", ".join(f"`{k}` = {v!r}" for k, v in c.parameters.items()) or "FMU defaults"
        lines.append(f"| `{c.name}` | {c.fmu}.fmu | {c.step_s * 1e3:g} ms "
                     f"(every {system.ratio(c)} macro steps) | {values} | {c.description} |")
    lines += ["", "| from | to |", "|---|---|"]
    lines += [f"| `{c.source}` | `{c.target}` |" for c in system.connections]
    lines += ["", "| system variable | kind | unit | value |", "|---|---|---|---|"]
    lines += [f"| `{v.name}` | input | {v.unit} | start {v.start:g}: {v.description} |"
              for v in system.inputs]
    lines += [f"| `{o.variable.name}` | output | {o.variable.unit} | {o.formula()} |"
              for o in system.outputs]
    return "\n".join(lines)


if __name__ == "__main__":
    print(markdown_tables(default_axis()))
