"""Plain-text tables of fit, diagnosis, comparison and catalog results, for the terminal.

One vocabulary with the report: micrometres are written µm (JSON keys keep ``_um``), a
p-value as :func:`~feedaxis.stats.wording.p_text` writes it, an uncertainty after ±.
"""
from __future__ import annotations

import math
import re

from .effects.base import BasisEffect
from .kinds import kind, part
from .stats.wording import p_text


def micro(unit):
    """A unit as people read it: µm, not um (``um/mm`` -> ``µm/mm``)."""
    return re.sub(r"\bum\b", "µm", unit)


def _number(value, digits=4):
    return "n/a" if value is None or (isinstance(value, float) and math.isnan(value)) \
        else f"{value:.{digits}g}"


def fit_lines(result, rms_before_um, out_path=None, alone_um=None):
    """Statistics, then one line per parameter with its uncertainty; the measurement's
    artefacts (a drift fitted beside the effects, outliers left out) said apart, with the
    RMS of the model alone on every sample (``alone_um``, what compare gives) beside the
    RMS with them, and the parameter count split between the two."""
    s = result.statistics
    effects = [e for e in result.model.effects if not isinstance(e, BasisEffect)]
    n_effects = sum(len(e.parameters) for e in effects)
    artefacts = s.n_free - n_effects
    counted = (f"{s.n_free} parameters: {n_effects} of the effects, {artefacts} of the "
               "measurement's artefacts" if artefacts else f"{s.n_free} parameters")
    lines = [f"effects: {', '.join(e.name for e in effects) or '(none)'}",
             f"RMS {rms_before_um:.4g} µm -> {s.rms_um:.4g} µm   max {s.max_um:.4g} µm   "
             f"P-V {s.pv_um:.4g} µm   R² {s.r2:.4f}   AIC {s.aic:.1f}   BIC {s.bic:.1f}   "
             f"({s.n_points} points, {counted})"]
    if artefacts and alone_um is not None:
        lines.append(f"  RMS {s.rms_um:.4g} µm with the artefacts fitted beside the model; "
                     f"the model alone on every sample (as compare and the report's ladder "
                     f"give it): {alone_um:.4g} µm")
    for effect in effects:
        for parameter in effect.parameters:
            value = result.model.values[effect.name][parameter.name]
            sigma = result.uncertainties.get(effect.name, {}).get(parameter.name)
            note = result.undetermined.get(f"{effect.name}.{parameter.name}", "")
            lines.append(f"  {effect.name + '.' + parameter.name:44s} {value:12.6g} ± "
                         f"{_number(sigma, 2):8s} {micro(parameter.unit):8s} {note}".rstrip())
    lines += _artefact_lines(result)
    if out_path:
        lines.append(f"model written to {out_path}")
    return "\n".join(lines)


def _artefact_lines(result):
    """The measurement's artefacts of a fit: nuisances fitted beside the effects (not saved
    as effects, never in a table) and the rows left out."""
    lines = [f"  measurement artefact {e.name} fitted beside the effects (not the machine's): "
             + ", ".join(f"{name} {value:.4g} µm" for name, value in result.model.values[e.name].items())
             + " (drift = c0·s + c1·(s² − mean s²), s the test's clock scaled from −1 at "
               "its start to +1 at its end)"
             for e in result.model.effects if isinstance(e, BasisEffect)]
    for key, what in (("outlier_rows", "outliers"), ("transient_rows", "transients")):
        if result.artefacts.get(key):
            lines.append(f"  {what} left out, rows {', '.join(map(str, result.artefacts[key]))}")
    return lines


def diagnosis_lines(diagnosis):
    """Verdict, candidates best first, unexplained structure, passed-over effects."""
    beside = [e.name for e in diagnosis.base.model.effects if isinstance(e, BasisEffect)]
    lines = [f"residual RMS {diagnosis.rms_um:.4g} µm"
             + (f" ({', '.join(beside)} fitted beside the model, as fit does)" if beside else "")
             + f", noise {diagnosis.noise_um:.3g} µm ({diagnosis.noise_source})",
             f"verdict: {diagnosis.verdict}"]
    if diagnosis.undetermined_reason:
        lines.append(f"  undetermined: {diagnosis.undetermined_reason}")
    if diagnosis.repeatability and not diagnosis.repeatability["repeatable"]:
        lines.append(f"  the axis does not repeat: {repeatability_text(diagnosis.repeatability)}")
    for candidate in diagnosis.candidates:
        lines.append(f"  missing: {candidate.effect:22s} RMS after {candidate.rms_after_um:.4g} µm"
                     f"   {p_text(candidate.test.p_value)}")
        lines.append(f"           {candidate.meaning}")
        lines.append(f"           evidence: {candidate.evidence}")
        lines += [f"           {name} = {_number(value, 4)} ± {_number(error, 2)} {micro(unit)}"
                  for name, (value, error, unit) in candidate.sizes().items()]
    for structure in diagnosis.unexplained:
        unit = structure.location_key.rsplit("_", 1)[1].replace("hz", "Hz")
        where = "" if structure.location is None else f" at {structure.location:.4g} {unit}"
        lines.append(f"  unexplained {structure.kind}{where}, amplitude "
                     f"{structure.amplitude_um:.3g} µm: {structure.evidence}")
    if diagnosis.outlier_rows:
        lines.append(f"  outliers kept out of the fit, rows of {diagnosis.file}: "
                     f"{', '.join(map(str, diagnosis.outlier_rows))}")
    if diagnosis.transient_rows:
        lines.append(f"  transients after the motion's start or stop kept out of the fit, rows "
                     f"of {diagnosis.file}: {', '.join(map(str, diagnosis.transient_rows))}")
    lines.append(f"  test: {diagnosis.test_used}")
    for name, reason in diagnosis.skipped.items():
        lines.append(f"  passed over {name}: {reason}")
    return "\n".join(lines)


def repeatability_text(repeatability):
    """Repeatability R against the systematic deviation E, in words."""
    r_um, e_um = repeatability["R_um"], repeatability["E_um"]
    if repeatability["repeatable"]:
        return f"repeatability R = {r_um:.3g} µm within the systematic deviation E = {e_um:.3g} µm"
    return (f"repeatability R = {r_um:.3g} µm exceeds the systematic deviation E = {e_um:.3g} µm "
            "(what varies from run to run is larger than what repeats: slip, a loose coupling "
            "or the set-up; no model or table removes it)")


def comparison_lines(comparison):
    """The figures of ``compare``, as the kind of measurement compared writes them (its
    ``text`` part: ISO 230-2 for positioning, Anang et al. 2017's for tracking), else one line per
    figure."""
    lines = part(kind(comparison["kind"]), "text")
    if lines:
        return lines(comparison)
    return "\n".join(f"{key}: {value}" for key, value in comparison.items())


def compensation_lines(result, out_path=None):
    """Thermal error before and after compensation: overall, per target, over time."""
    summary = result.summary()
    header = f"{'max before':>11s} {'max after':>10s} {'RMS before':>11s} {'RMS after':>10s}"

    def figures(row):
        return (f"{row['max_before_um']:11.3f} {row['max_after_um']:10.3f} "
                f"{row['rms_before_um']:11.3f} {row['rms_after_um']:10.3f}")

    lines = [f"thermal error max {summary['max_before_um']:.3f} µm -> {summary['max_after_um']:.3f}"
             f" µm ({100 * summary['reduction']:.1f} % less), RMS {summary['rms_before_um']:.3f}"
             f" -> {summary['rms_after_um']:.3f} µm over {result.time_s.size} samples",
             "", f"{'target (mm)':>11s} {'dir':>3s} {header}  (µm)"]
    lines += [f"{row['target_mm']:11.3f} {row['direction']:+3d} {figures(row)}"
              for row in result.by_target()]
    lines += ["", f"{'visit':>5s} {'t (min)':>9s} {header}  (µm)"]
    lines += [f"{row['visit']:5d} {row['time_s'] / 60.0:9.1f} {figures(row)}"
              for row in result.over_time()]
    if out_path:
        lines.append(f"per-sample correction written to {out_path}")
    return "\n".join(lines)


def effect_lines(effects):
    """The catalog: name, meaning, parameters with units."""
    lines = []
    for name, effect in effects.items():
        parameters = ", ".join(f"{p.name} [{micro(p.unit)}]" for p in effect.parameters) or \
            "none (computed from axis.toml)"
        lines += [f"{name}  (FMU {effect.fmu or '-'})", f"    {effect.meaning}",
                  f"    parameters: {parameters}"]
    return "\n".join(lines)
