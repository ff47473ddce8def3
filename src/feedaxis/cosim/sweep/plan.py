"""A sweep's plan: the scenario, its options, the axis and FMUs, the values every trial
takes (:mod:`.specs`), checked against the scenario and the FMUs before any trial runs."""
from __future__ import annotations

import math
from dataclasses import asdict, dataclass, is_dataclass
from pathlib import Path

import numpy as np

from ... import __version__
from ...errors import InputError, ParameterError, json_safe
from ...kinds import scenarios as registered_scenarios
from ..physics_check import check_parameters, fmu_variables
from .specs import design as make_design, model_draws


@dataclass
class Plan:
    """A sweep, checked and ready: what runs and what each trial takes."""

    scenario: str
    options: dict
    system: object
    fmu_paths: dict
    design: object
    draws: object = None
    axis: object = None
    set_items: tuple = ()
    model_path: str | None = None

    @property
    def trials(self):
        return self.design.trials

    @property
    def input_names(self):
        return self.design.names + (self.draws.keys if self.draws else ())

    def inputs(self, trial):
        """({input name: value}, {component: {parameter: value}}, redraws) of a trial."""
        values = self.design.values(trial)
        overrides, redraws = {}, 0
        if self.draws is not None:
            drawn, redraws = self.draws.values(trial)
            model = self.draws.model_at(drawn)
            for effect in model.effects:
                for fmu, fmu_values in effect.fmu_parameters(self.axis,
                                                             model.values[effect.name]).items():
                    overrides.setdefault(fmu, {}).update(fmu_values)
            values.update(drawn)
        for name in self.design.names:
            component, parameter = name.split(".", 1)
            overrides.setdefault(component, {})[parameter] = values[name]
        return values, overrides, redraws

    def identity(self, fmu_digest):
        """The plan as JSON-ready data: two sweeps with equal identities give equal tables."""
        return json_safe({
            "feedaxis": __version__, "scenario": self.scenario,
            "options": _plain(scenario_named(self.scenario).with_defaults(self.options)),
            "vary": [s.text for s in self.design.specs],
            "seed": self.design.seed, "trials": self.trials,
            "from_model": self.model_path, "held": dict(self.draws.held) if self.draws else {},
            "set": list(self.set_items), "macro_step_s": self.system.macro_step_s,
            "components": {c.name: {"step_s": c.step_s, "parameters": c.parameters}
                           for c in self.system.components},
            "fmus": fmu_digest})


def scenario_named(name):
    """The registered scenario ``name`` (:func:`feedaxis.kinds.scenarios`); InputError
    naming the known ones otherwise."""
    known = registered_scenarios()
    if name not in known:
        raise InputError(f"unknown scenario; scenarios: {', '.join(known)}",
                         parameter=f"scenario {name}")
    return known[name]


def _plain(value):
    """Options as JSON-ready data (a duty as its segments)."""
    if is_dataclass(value):
        return _plain(asdict(value))
    if isinstance(value, dict):
        return {k: _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple, np.ndarray)):
        return [_plain(v) for v in value]
    return value.item() if isinstance(value, np.generic) else value


class _OptionsChecked(Exception):
    """Raised by :class:`_DryMaster` once a scenario has checked its options."""


class _DryMaster:
    """A stand-in Master that stops a scenario where it would start simulating."""

    def __init__(self, system):
        self.system = system

    def run(self, *args, **kwargs):
        raise _OptionsChecked


def check_plan(plan):
    """Refuse, before any trial runs, a sweep whose options, specs or drawn values the
    scenario or the FMUs would refuse (:class:`InputError` naming the option or spec)."""
    try:
        scenario_named(plan.scenario).run(_DryMaster(plan.system), **plan.options)
    except _OptionsChecked:
        pass
    variables = fmu_variables(plan.system, plan.fmu_paths)
    check_parameters(plan.system, plan.fmu_paths, variables)
    for spec in plan.design.specs:
        for name, (low, high) in zip(spec.names, spec.support()):
            _check_within(name, low, high, variables, spec.option, "the spec's range")
    lowest, highest = _drawn_extremes(plan)
    for name, option in _options_of(plan).items():
        _check_within(name, lowest[name], highest[name], variables, option, "drawn values")
    for values in (lowest, highest):
        overrides = {}
        for name, value in values.items():
            component, parameter = name.split(".", 1)
            overrides.setdefault(component, {})[parameter] = value
        try:
            check_parameters(plan.system.with_parameters(overrides), plan.fmu_paths,
                             variables)
        except ParameterError as error:
            raise InputError(f"at the extremes of the drawn values: {error.message}",
                             parameter=_options_of(plan).get(error.parameter, error.parameter))\
                from None


def _options_of(plan):
    """{Component.parameter: the option that varies it} over every varied FMU parameter."""
    options = {name: spec.option for spec in plan.design.specs for name in spec.names}
    if plan.draws is not None:
        for fmu, values in plan.inputs(0)[1].items():
            for parameter in values:
                options.setdefault(f"{fmu}.{parameter}", "--from-model")
    return options


def _drawn_extremes(plan):
    """({Component.parameter: lowest}, {...: highest}) over every trial's FMU values."""
    lowest, highest = {}, {}
    for trial in range(plan.trials):
        for component, values in plan.inputs(trial)[1].items():
            for parameter, value in values.items():
                name = f"{component}.{parameter}"
                if isinstance(value, bool) or not isinstance(value, (int, float)):
                    continue
                lowest[name] = min(lowest.get(name, value), value)
                highest[name] = max(highest.get(name, value), value)
    return lowest, highest


def _check_within(name, low, high, variables, option, what):
    component, parameter = name.split(".", 1)
    if component not in variables:
        raise InputError(f"no component {component}; components: {', '.join(variables)}",
                         parameter=option)
    declared = variables[component].get(parameter)
    if declared is None or declared.causality != "parameter" or declared.type != "Real":
        known = sorted(n for n, v in variables[component].items()
                       if v.causality == "parameter" and v.type == "Real")
        raise InputError(f"{component} has no Real parameter {parameter}; its Real "
                         f"parameters: {', '.join(known)}", parameter=option)
    if declared.min is not None and -math.inf < low < float(declared.min):
        raise InputError(f"{what} reach {low:g}, below {name}'s minimum {declared.min} "
                         "(the FMU's bound)", parameter=option)
    if declared.max is not None and math.inf > high > float(declared.max):
        raise InputError(f"{what} reach {high:g}, above {name}'s maximum {declared.max} "
                         "(the FMU's bound)", parameter=option)


def make_plan(scenario, vary=(), trials=None, seed=0, from_model=None, axis=None,
              hold_undetermined=False, step_ms=1.0, thermal_step_s=None, model=None,
              set_items=(), effects=None, fmus=None, **options):
    """Build and check the :class:`Plan` of a sweep (arguments as :func:`sweep`)."""
    from ..fmu_cache import fmu_paths
    from ..system import axis_from_options

    scenario_named(scenario)
    if from_model and model:
        raise InputError("give the model to draw from (--from-model) or a fixed one (--model),"
                         " not both", parameter="--model")
    if from_model and not axis:
        raise InputError("needs --axis (the axis.toml or case folder it was fitted on): the "
                         "FMU parameters depend on the axis", parameter="--from-model")
    if not vary and not from_model:
        raise InputError("nothing varies: give --vary NAME=SPEC or --from-model M.toml",
                         parameter="--vary")
    system = axis_from_options(step_ms, thermal_step_s, from_model or model, axis, set_items,
                               effects)
    draws, axis_table = None, None
    if from_model:
        from ...case import read_axis
        from ...effects import CATALOG, load_model

        axis_path = Path(axis)
        axis_table = read_axis(axis_path / "axis.toml" if axis_path.is_dir() else axis_path)
        draws = model_draws(load_model(from_model, CATALOG if effects is None else effects),
                            seed, hold_undetermined)
    plan = Plan(scenario, options, system, fmu_paths(fmus),
                make_design(vary, trials, seed, drawn_elsewhere=draws is not None), draws,
                axis_table, tuple(set_items or ()), str(from_model) if from_model else None)
    _refuse_masked(plan)
    check_plan(plan)
    return plan


def _refuse_masked(plan):
    """A --vary or --set on an FMU parameter the drawn model sets would hide its draws."""
    if plan.draws is None:
        return
    drawn = {f"{fmu}.{p}" for fmu, values in plan.inputs(0)[1].items() for p in values}
    varied = {n: s.option for s in plan.design.specs for n in s.names}
    for name in sorted(drawn & set(varied)):
        raise InputError(f"{name} is drawn from --from-model; vary it there or here, not "
                         "both", parameter=varied[name])
    for item in plan.set_items:
        if item.partition("=")[0] in drawn:
            raise InputError("sets a parameter the drawn model sets: its draws would be "
                             "hidden", parameter=f"--set {item}")
