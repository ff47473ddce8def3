"""Whether a table is safe to load: which of the model's effects it may use, and when the
table is refused.

A table never uses an effect with a parameter the data cannot determine. Two sources name
them, and both count:

- the model's fit record (``[fit] undetermined``): what the fit itself found (a parameter on
  its bound, or inseparable from another on the data it was fitted on, which may be several
  cases);
- the case the table is made for: the same singular-direction test the fit applies
  (:func:`feedaxis.fit.inseparable`), on the Jacobian of the model at its values at this
  case's samples. A model written by hand has no record, and a parameter this case cannot
  determine is one the table's verification on this case cannot check either.

Nor does it use a periodic effect the diagnosis passes over on this case as unresolvable
(:meth:`feedaxis.measurement.positioning.Positioning.unresolvable`: the targets cannot resolve its
wavelength, so a fitted value of it is an alias, and between the targets the table would add
a ripple no measurement supports).

A table is refused (unless forced) when it had to leave such an effect out, or when its own
verification (:mod:`.verify`) expects it to raise an ISO 230-2 accuracy A or systematic
deviation E at the targets, or the model's peak to valley between them.
"""
from __future__ import annotations

import numpy as np

from ..effects import Model
from ..fit import inseparable
from ..measurement.positioning import Positioning
from .table import DIRECTIONAL_EFFECTS, POSITION_TABLE_EFFECTS

WORSE_FIGURES = ("A_um", "A_up_um", "A_down_um", "E_um", "E_up_um", "E_down_um")
# A figure "rises" when it grows by more than this (µm): float rounding, far below any
# laser's resolution (0.001 µm).
ROUNDING_UM = 1e-6
RELATIVE_STEP = 1e-6


def unsafe_effects(case, model):
    """{effect name: [why, ...]} of the table effects of ``model`` a table on ``case`` must
    not use: a parameter undetermined by the fit record or on ``case``, or a wavelength the
    case's targets cannot resolve."""
    undetermined = dict(model.record.undetermined) if model.record is not None else {}
    for key, reason in undetermined_on(case, model).items():
        undetermined.setdefault(key, f"on this case {reason}")
    measurement = Positioning(case)
    unsafe = {}
    for effect in model.effects:
        if effect.name not in POSITION_TABLE_EFFECTS + DIRECTIONAL_EFFECTS:
            continue
        reasons = [f"{key}: {reason}" for key, reason in undetermined.items()
                   if key.split(".", 1)[0] == effect.name]
        aliased = measurement.unavailable(effect) is None and measurement.unresolvable(effect)
        if aliased:
            reasons.append(f"the targets cannot resolve it: {aliased}")
        if reasons:
            unsafe[effect.name] = reasons
    return unsafe


def undetermined_on(case, model):
    """{"effect.parameter": why} of the parameters of ``model`` (at its values) that the
    samples of ``case`` cannot determine: the fit's singular-direction test on the Jacobian
    at those samples (forward differences), over the effects usable on ``case``."""
    measurement = Positioning(case)
    effects = [e for e in model.effects
               if e.parameters and measurement.unavailable(e) is None]
    if not effects:
        return {}
    usable = Model(effects, model.values)
    predict = measurement.predictor(usable)
    keys, columns = [], []
    base_um = predict(usable.values)
    for effect in effects:
        bounds = effect.bounds(case.axis)
        for parameter in effect.parameters:
            value = usable.values[effect.name][parameter.name]
            lower, upper = bounds[parameter.name]
            step = RELATIVE_STEP * max(abs(value), 1e-3 * (upper - lower), 1e-9)
            step = -step if value + step > upper else step
            moved = {**usable.values,
                     effect.name: {**usable.values[effect.name], parameter.name: value + step}}
            columns.append((predict(moved) - base_um) / step)
            keys.append(f"{effect.name}.{parameter.name}")
    return inseparable(np.column_stack(columns), keys)


def reasons_by_effect(unsafe):
    """{effect name: why} of :func:`unsafe_effects`, its reasons in one line."""
    return {name: "; ".join(whys) for name, whys in unsafe.items()}


def usable_model(model, unsafe):
    """``model`` without the effects named in ``unsafe`` (their fit record dropped)."""
    return Model([e for e in model.effects if e.name not in unsafe], model.values)


def risen_figures(report):
    """[(name, before, after)] of the figures the table raises: A and E at the targets, and
    the model's peak to valley between them."""
    risen = [(f["name"], f["before_um"], f["after_um"])
             for key, f in report["figures"].items()
             if key in WORSE_FIGURES and f["after_um"] > f["before_um"] + ROUNDING_UM]
    between = report["between_targets"]
    if between and between["pv_after_um"] > between["pv_before_um"] + ROUNDING_UM:
        risen.append(("between targets (model), P-V", between["pv_before_um"],
                      between["pv_after_um"]))
    return risen


def refusals(report, unsafe):
    """Why the table of ``report`` must not be loaded as it is (empty when it may): lines
    for the terminal."""
    reasons = []
    if unsafe:
        reasons.append(f"the data cannot determine {', '.join(unsafe)}; a table must leave "
                       "them out:")
        reasons += [f"  {name}: {why}" if not why.startswith(f"{name}.") else f"  {why}"
                    for name, whys in unsafe.items() for why in whys]
    risen = risen_figures(report)
    if risen:
        reasons.append("the table makes the axis worse: " + ", ".join(
            f"{name} rises from {before:.3f} to {after:.3f} µm" for name, before, after in risen))
    return reasons


def forced_warnings(report, unsafe):
    """What a table written with ``--force`` risks."""
    warnings = []
    if unsafe:
        warnings.append(f"written with --force without {', '.join(unsafe)}: their error stays "
                        "on the axis, uncompensated; refit a model the data determine "
                        "(feedaxis diagnose CASE names what they support) for a table that "
                        "includes what they can")
    risen = risen_figures(report)
    if risen:
        warnings.append("written with --force although it makes the axis worse: " + ", ".join(
            f"{name} {before:.3f} → {after:.3f} µm" for name, before, after in risen)
            + "; loading it adds this error")
    return warnings
