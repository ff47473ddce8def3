"""The positioning figures of every standard a calibration laboratory is asked for, from one
engine (:mod:`.engine`) over the same per-target statistics, each standard a small
definition (:mod:`.definitions`) citing its clauses; ISO 230-3's thermal figures for
thermal cases (:mod:`.thermal`). docs/standards.md has the table and the sources.

``--standard NAME`` on compare, report and uncertainty: :func:`parse` checks the name (an
unknown one exits 2 naming the allowed names), :func:`comparison` gives the figures of
``compare --json`` under ``figures`` in the shape of ISO 230-2's, with ``standard`` naming
the standard and its edition.
"""
from __future__ import annotations

import argparse

from .definitions import ALL, DEFAULT, NAMES, STANDARDS, THERMAL, UNDEFINED
from .engine import evaluate, needs

__all__ = ["ALL", "DEFAULT", "NAMES", "STANDARDS", "THERMAL", "UNDEFINED", "FigureSet",
           "comparison", "entries", "evaluate", "figures_payload", "needs", "parse"]


def parse(name):
    """``--standard``'s value, checked: one of :data:`NAMES` (argparse exits 2 otherwise,
    naming the value and the allowed names)."""
    if name not in NAMES:
        raise argparse.ArgumentTypeError(f"unknown standard '{name}'; allowed: "
                                         f"{', '.join(NAMES)}")
    return name


def entries(names, measured, residual):
    """{key: {name, measured_um, residual_um, explained}} for the keys of ``names`` the
    measured figures hold; ``explained`` = 1 - residual / measured (None when 0)."""
    figures = {}
    for key, name in names.items():
        if key in measured:
            explained = 1 - residual[key] / measured[key] if measured[key] else None
            figures[key] = {"name": name, "measured_um": measured[key],
                            "residual_um": residual[key], "explained": explained}
    return figures


def comparison(name, target_mm, measured_um, residual_um, direction):
    """The figures of standard ``name`` (a key of :data:`STANDARDS` or an :data:`UNDEFINED`
    one) of the measured deviations and of the residual after the model, with the
    standard's provenance and what it asks that the data lack."""
    if name in UNDEFINED:
        title, reason = UNDEFINED[name]
        return {"standard": title, "figures": {},
                "unavailable": f"{title}: {reason}; feedaxis gives no figures rather than "
                               "guess (docs/standards.md)"}
    standard = STANDARDS[name]
    measured = evaluate(standard, target_mm, measured_um, direction)
    residual = evaluate(standard, target_mm, residual_um, direction)
    return {"standard": standard.title,
            "figures": entries({f.key: f.name for f in standard.figures}, measured, residual),
            "needs": needs(standard, target_mm, direction), **_provenance(standard)}


def _provenance(standard):
    described = standard.to_json()
    return {key: described[key] for key in ("coverage_factor", "adopts", "clauses",
                                            "confirmed_publicly", "not_confirmed_publicly")}


def figures_payload(name, target_mm, measured_um, residual_um, direction):
    """``compare``'s figures of the positioning standard ``name`` (``all``: every one under
    ``standards``, keyed by name; ISO 230-3's thermal block is :mod:`.thermal`'s)."""
    deviations = (target_mm, measured_um, residual_um, direction)
    if name == ALL:
        return {"standard": ALL, "standards": {other: comparison(other, *deviations)
                                               for other in positioning_names()}}
    return comparison(name, *deviations)


class FigureSet:
    """The figures of one standard, or of every defined one (``all``: keys ``name/key``,
    names headed by the standard's title), from one set of deviations or many trials'."""

    def __init__(self, name=DEFAULT):
        names = [other for other in positioning_names() if other in STANDARDS]
        self.standards = [STANDARDS[other] for other in names] if name == ALL else [
            STANDARDS[name]]
        self.title = ALL if name == ALL else STANDARDS[name].title
        self.prefixed = name == ALL

    def names(self):
        """{key: figure name} in the standards' order."""
        return {self._key(standard, f.key): (f"{standard.title} {f.name}" if self.prefixed
                                              else f.name)
                for standard in self.standards for f in standard.figures}

    def of(self, target_mm, error_um, direction):
        """{key: value} of every standard's figures the data give."""
        return {self._key(standard, key): value for standard in self.standards
                for key, value in evaluate(standard, target_mm, error_um, direction).items()}

    def _key(self, standard, key):
        return f"{standard.name}/{key}" if self.prefixed else key


def positioning_names():
    """The positioning standards of ``all``, in the order of :data:`NAMES`."""
    return [name for name in NAMES if name in STANDARDS or name in UNDEFINED]
