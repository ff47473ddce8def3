"""Everything the report, the text and ``--json`` show about a model on a case, computed
once, for every kind of measurement.

:func:`analyse` returns an :class:`Analysis`: the model's result as it stands, the
diagnosis, the error ladder, the figures of ``compare``, each effect's contribution, and
the kind's own views (``details``, from the kind's ``details`` part: for positioning
:mod:`feedaxis.positioning_details`, for tracking :mod:`feedaxis.tracking_details`). ``feedaxis.report`` and
``feedaxis.text`` only format it, as lmfit's ``ModelResult.fit_report`` only reads a fit;
``feedaxis demo`` passes the diagnosis and ladder its loop already computed.
"""
from __future__ import annotations

from dataclasses import dataclass

from .diagnose import Diagnosis, diagnose
from .effects import CATALOG, Model
from .fit import FitResult, evaluate, fit
from .kinds import part
from .measurement import kinds_for, measurement_of
from .physics.threads import one_blas_thread
from .standards import DEFAULT


@dataclass
class Analysis:
    """A model (as fitted) on one kind of measurement of a case, with every result shown.

    ``ladder`` is [(label, residual RMS µm)]: the model with no effect, then each effect
    added in turn and refitted; ``comparison`` the figures of ``compare``; ``components``
    {effect: µm} per sample.
    """

    case: object
    model: Model
    effects: dict
    measurement: object
    result: FitResult
    diagnosis: Diagnosis
    ladder: list
    comparison: dict
    components: dict
    details: object

    @property
    def kind(self):
        return self.measurement.kind


def measurement_for(case, model, kind=None):
    """The samples of ``case`` that ``model`` is compared with: of ``kind``, else of the
    model's kind, else of the first kind the case holds."""
    return measurement_of(case, kind or kinds_for([case], model)[0])


def compare(case, model, kind=None, standard=DEFAULT, progress=None):
    """The figures of ``model`` (as it stands) on the ``kind`` samples of ``case`` (the
    kind's own: for positioning those of ``standard``, :mod:`feedaxis.standards`; the tracking
    error of Anang et al. 2017; a dict for ``--json``); ``progress`` is called with a label
    before each step."""
    notify = progress or (lambda label: None)
    measurement = measurement_for(case, model, kind)
    notify("model")
    result = evaluate(model, measurement)
    notify("figures")
    return _figures(measurement, result, standard)


def _figures(measurement, result, standard):
    """The measurement's figures; those of ``standard`` through the kind's ``standards``
    part (positioning: :mod:`feedaxis.standards`) when it has one."""
    of_standard = part(type(measurement), "standards")
    if standard == DEFAULT or of_standard is None:
        return measurement.figures(result)
    return of_standard(measurement, result, standard)


def error_ladder(case, model, kind=None):
    """[(label, residual RMS µm)]: the model with no effect, then each effect of ``model``
    added in turn, refitted."""
    return ladder_of(measurement_for(case, model, kind), model)


def ladder_of(measurement, model):
    """:func:`error_ladder` on ``measurement``."""
    steps = [(measurement.reference_label, evaluate(Model(), measurement).rms_um)]
    for count in range(1, len(model.effects) + 1):
        partial = Model(model.effects[:count])
        steps.append((f"+ {model.effects[count - 1].name}", fit(partial, measurement).rms_um))
    return steps


@one_blas_thread
def analyse(case, model, effects=None, diagnosis=None, ladder=None, kind=None, progress=None,
            standard=DEFAULT):
    """Analyse ``model`` (as fitted) on the ``kind`` samples of ``case``.

    Parameters
    ----------
    case : Case
    model : Model
    effects : dict, optional
        Effects by name the diagnosis may name (default: the catalog).
    diagnosis, ladder : optional
        Already computed for this case and model (``feedaxis demo``'s last round); computed
        here when not given.
    kind : str, optional
        The kind of measurement (default: the model's, else the first the case holds).
    progress : callable, optional
        Called with a label before each step and each fit.
    standard : str
        The standard of the positioning figures (:data:`feedaxis.standards.NAMES`).

    Returns
    -------
    Analysis
    """
    effects = CATALOG if effects is None else effects
    notify = progress or (lambda label: None)
    measurement = measurement_for(case, model, kind)
    notify("model")
    if diagnosis is None:
        diagnosis = diagnose(case, model, effects, notify, measurement=measurement)
    result = evaluate(model, measurement)  # after the diagnosis: its residual not held by it
    if ladder is None:
        notify("error ladder")
        ladder = ladder_of(measurement, model)
    notify("figures")
    details_of = part(type(measurement), "details")
    details = details_of(measurement, model, effects, result) if details_of else None
    return Analysis(case, model, effects, measurement, result, diagnosis, ladder,
                    _figures(measurement, result, standard), measurement.components(model),
                    details)
