"""Plain-text output of the tracking commands (the CLI prints these without --json)."""
from __future__ import annotations


def diagnosis_lines(diagnosis):
    """Verdict, candidates best first, unexplained structure in time, passed-over effects."""
    lines = [f"residual RMS {diagnosis.rms_um:.4g} um, noise {diagnosis.noise_um:.3g} um "
             f"({diagnosis.noise_source})", f"verdict: {diagnosis.verdict}"]
    for candidate in diagnosis.candidates:
        lines.append(f"  missing: {candidate.effect:22s} RMS after {candidate.rms_after_um:.4g} um"
                     f"   p {candidate.p_value:.2g}")
        lines.append(f"      {candidate.evidence}")
    for structure in diagnosis.unexplained:
        frequency = "" if structure.frequency_hz is None else f" at {structure.frequency_hz:.4g} Hz"
        lines.append(f"  unexplained {structure.kind}{frequency}, amplitude "
                     f"{structure.amplitude_um:.3g} um: {structure.evidence}")
    for name, reason in diagnosis.skipped.items():
        lines.append(f"  passed over {name}: {reason}")
    return "\n".join(lines)


def comparison_lines(comparison):
    """Seed 002's figures after the first second: measured, predicted; then the residual."""
    maximum, rms = comparison["max_tracking_error_mm"], comparison["rms_tracking_error_mm"]
    return "\n".join([
        f"{comparison['samples']} samples after the first {comparison['after_s']:g} s; model: "
        f"{', '.join(comparison['effects']) or '(seed 002 plant)'}",
        f"{'tracking error (mm)':24s} {'measured':>10s} {'predicted':>10s}",
        f"{'max':24s} {maximum['measured']:10.5f} {maximum['predicted']:10.5f}",
        f"{'RMS':24s} {rms['measured']:10.5f} {rms['predicted']:10.5f}",
        f"residual actual - predicted: max {comparison['residual_max_um']:.4g} um, RMS "
        f"{comparison['residual_rms_um']:.4g} um"])
