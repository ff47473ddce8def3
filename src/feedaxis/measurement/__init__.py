"""What a case's samples are and how a model predicts them: one module per kind of
measurement, registered in :mod:`feedaxis.kinds`, chosen here, in one place, from the case
and the model.

- :mod:`.positioning`: deviations at targets (positioning.csv), ISO 230-2;
- :mod:`.tracking`: deviations over time (tracking.csv), Anang et al. 2017's closed loop.

A model acts on one kind (its effects name it, ``Effect.measurement``); a model with no
effect of any kind (the empty model) is compared with each kind the case holds. A new kind
is one new module: a :class:`~.base.Measurement` subclass registered with
``@feedaxis.kinds.register`` (docs/layout.md).
"""
from __future__ import annotations

from ..errors import InputError
from ..kinds import kind as kind_named
from ..kinds import kinds
from .base import Measurement, Shape, Trial
from .positioning import Positioning
from .tracking import Tracking, servo_params

__all__ = ["Measurement", "Positioning", "Shape", "Tracking", "Trial", "kinds_for",
           "measurement_of", "model_kind", "servo_params"]


def model_kind(model):
    """The kind of measurement the model's effects act on, None when none names one.

    A model mixing kinds is refused with an :class:`InputError` naming the effects.
    """
    named = {}
    for effect in model.effects:
        if effect.measurement:
            named.setdefault(effect.measurement, []).append(effect.name)
    if len(named) > 1:
        parts = "; ".join(f"{', '.join(names)} act on {kind_named(kind).file}"
                          for kind, names in named.items())
        raise InputError(f"the model mixes kinds of measurement ({parts}); a model acts on "
                         "one kind: fit them as two models", parameter="model")
    return next(iter(named), None)


def kinds_for(cases, model):
    """The kinds to compare ``model`` with on every one of ``cases``: the model's kind, or
    for a model naming none each kind every case holds (positioning first)."""
    kind = model_kind(model)
    if kind:
        return [kind]
    registered = kinds()
    held = [k for k, cls in registered.items() if all(cls.holds(case) for case in cases)]
    if not held:
        raise InputError("the cases hold no kind of measurement in common: "
                         f"{', '.join(cls.file for cls in registered.values())}",
                         path=cases[0].folder)
    return held


def measurement_of(case, kind):
    """The samples of ``kind`` in ``case``; :class:`InputError` when the case has none."""
    cls = kind_named(kind)
    if not cls.holds(case):
        raise InputError(f"the case has no {cls.file} (the model's effects act on the {kind} "
                         "measurement)", path=case.folder)
    return cls(case)
