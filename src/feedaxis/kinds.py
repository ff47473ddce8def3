"""The registry of the kinds of measurement: the one place the rest of feedaxis asks which
kinds exist, and what each brings.

A kind is a :class:`feedaxis.measurement.base.Measurement` subclass; its module registers
it with :func:`register` (``@register`` over the class). The class names its file and its
parts: the reader of its samples, and the parts that live above the fit (its analysis
details, report views, terminal text, simulated scenario), each given as a callable or as
``"module:name"`` loaded on first use, as a plugin's entry point is (the report's plots
load only when a report is written). The built-in kinds are loaded by module name the
first time the registry is read, so reading a case never imports them by name.

This module imports no feedaxis module: the case reader below it and the command line
above it both read it.
"""
from __future__ import annotations

import importlib

BUILT_IN = ("feedaxis.measurement.positioning", "feedaxis.measurement.tracking",
            "feedaxis.measurement.circular")

_KINDS = {}
_loaded = []


def register(cls):
    """Register the kind ``cls`` (a Measurement subclass) under ``cls.kind``; returns it, so
    it serves as a class decorator. A second class under a registered name is refused."""
    if not cls.kind or not cls.file:
        raise TypeError(f"{cls.__name__} must name its kind and its file to be registered")
    held = _KINDS.get(cls.kind)
    if held is not None and held.__qualname__ != cls.__qualname__:
        raise TypeError(f"kind {cls.kind!r} is registered already ({held.__name__})")
    if hasattr(cls, "check_contract"):
        cls.check_contract()
    _KINDS[cls.kind] = cls
    return cls


def unregister(name):
    """Take kind ``name`` out of the registry (a kind registered by a test)."""
    _KINDS.pop(name, None)


def kinds():
    """{name: Measurement subclass} of every registered kind, the built-in ones first."""
    if not _loaded:
        _loaded.append(True)
        for module in BUILT_IN:
            importlib.import_module(module)
    ordered = sorted(_KINDS.values(), key=lambda cls: cls.__module__ not in BUILT_IN)
    return {cls.kind: cls for cls in ordered}


def kind(name):
    """The registered kind ``name`` (KeyError naming the known ones otherwise)."""
    known = kinds()
    if name not in known:
        raise KeyError(f"no kind of measurement {name!r}; registered: {', '.join(known)}")
    return known[name]


def scenarios():
    """{name: Scenario} of every registered kind's simulated scenarios (its ``scenarios``
    part, a sequence of :class:`feedaxis.cosim.scenarios.base.Scenario`), in the kinds'
    order; a kind without one adds none. Two kinds naming one scenario are refused."""
    found = {}
    for cls in kinds().values():
        for scenario in part(cls, "scenarios") or ():
            if scenario.name in found:
                raise TypeError(f"scenario {scenario.name!r} of kind {cls.kind!r} is "
                                "declared by another kind already")
            found[scenario.name] = scenario
    return found


def part(cls, name):
    """The part ``name`` of kind ``cls`` (``details``, ``views``, ``text``, ``scenarios``): its value,
    loaded from ``"module:attribute"`` on first use; None when the kind has none."""
    value = getattr(cls, name, None)
    if isinstance(value, str):
        module, _, attribute = value.partition(":")
        value = getattr(importlib.import_module(module), attribute)
    return value
