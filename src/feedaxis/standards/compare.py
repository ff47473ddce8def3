"""The positioning kind's ``standards`` part (:func:`feedaxis.kinds.part`): ``compare``'s
figures of a standard other than the default, ISO 230-3's of a thermal case, or all."""
from __future__ import annotations

from . import ALL, THERMAL
from .thermal import thermal_block, thermal_comparison


def standard_figures(measurement, result, standard):
    """The figures of ``standard`` of a positioning ``measurement`` and the model's
    ``result`` on it: a positioning standard's (:meth:`figures`), ISO 230-3's of a thermal
    case, or every one side by side (``all``, ISO 230-3 with them)."""
    if standard == THERMAL:
        return {**measurement.head(result), **thermal_comparison(measurement.case,
                                                                 result.model)}
    payload = measurement.figures(result, standard)
    if standard == ALL:
        payload["standards"][THERMAL] = thermal_block(measurement.case, result.model)
    return payload
