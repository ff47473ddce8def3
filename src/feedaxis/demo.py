"""`feedaxis demo`: the whole loop on the bundled seed 001 case, then the FMUs.

Each round diagnoses the model, adds the best missing effect and refits, until the verdict
is no longer ``missing_effect``. The case (copied first, to try the loop by hand on), the
laser example (an ``axis.toml`` and ``.rtl`` for ``feedaxis import``), the fitted model, the
report and the FMUs are written to the output folder, and the FMUs driven with the fitted
parameters are checked against the model.
"""
from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np

from .analysis import analyse
from .case import read_case
from .cosim.replay import POSITION_FMUS, replay_positioning
from .diagnose import diagnose
from .effects import CATALOG, Model
from .examples import BUNDLED_CASE, LASER_EXAMPLE
from .fit import fit
from .fmu_build import build_fmus
from .output import write_atomically
from .report import write_report

MAX_ROUNDS = 8


def improve(case, model, effects=None, echo=print, max_rounds=MAX_ROUNDS):
    """Diagnose, add the best missing effect, refit; repeat.

    Returns (model, rounds, diagnosis): the final model, one JSON-ready dict per round and
    the last round's diagnosis (of the final model).
    """
    effects = CATALOG if effects is None else effects
    rounds = []
    for number in range(1, max_rounds + 1):
        diagnosis = diagnose(case, model, effects)
        round_ = {"round": number, "rms_um": diagnosis.rms_um, "noise_um": diagnosis.noise_um,
                  "verdict": diagnosis.verdict, **diagnosis.to_json()}
        echo(f"round {number}: RMS {diagnosis.rms_um:.4f} um (noise {diagnosis.noise_um:.4f} um)"
             f" -> {diagnosis.verdict}")
        for structure in diagnosis.unexplained:
            echo(f"    unexplained {structure.kind}: {structure.evidence}")
        if diagnosis.verdict != "missing_effect":
            rounds.append(round_)
            return model, rounds, diagnosis
        best = diagnosis.candidates[0]
        model = best.result.model
        round_.update(added=best.effect, rms_after_um=best.rms_after_um)
        rounds.append(round_)
        echo(f"    missing: {best.effect} ({best.meaning})")
        echo(f"    evidence: {best.evidence}")
        echo(f"    add {best.effect}, refit: RMS {best.rms_after_um:.4f} um")
    return model, rounds, diagnose(case, model, effects)


def ladder_of(rounds):
    """The error ladder [(label, RMS µm)] of a loop started from the empty model."""
    return [("measured", rounds[0]["rms_um"])] + [
        (f"+ {r['added']}", r["rms_after_um"]) for r in rounds if "added" in r]


def run_demo(out_dir, echo=print):
    """Run the loop on the bundled case and write model, report and FMUs to ``out_dir``."""
    out_dir = Path(out_dir)
    case = read_case(shutil.copytree(BUNDLED_CASE, out_dir / "case", dirs_exist_ok=True))
    echo(f"case: {case.name}")
    echo(f"      {case.positioning.size} laser points, {case.positioning.target_mm.min():g} to "
         f"{case.positioning.target_mm.max():g} mm; model: empty; copied to {case.folder}")
    model, rounds, diagnosis = improve(case, Model(), echo=echo)
    model_path = write_atomically(out_dir / "model.toml", fit(model, case).fitted_model().to_toml())
    analysis = analyse(case, model, CATALOG, diagnosis=diagnosis, ladder=ladder_of(rounds))
    report_path = write_report(analysis, out_dir / "report.html")
    laser_path = shutil.copytree(LASER_EXAMPLE, out_dir / "laser-example", dirs_exist_ok=True)
    echo(f"fitted model: {model_path}")
    echo(f"report:       {report_path}")
    echo(f"laser example: {laser_path} (axis.toml + X-axis.rtl for feedaxis import)")
    fmu_paths = {path.stem: path for path in build_fmus(out_dir / "fmus", POSITION_FMUS)}
    difference_um = float(np.max(np.abs(replay_positioning(case, model, fmu_paths)
                                        - model.predict_um(case))))
    echo(f"FMUs {' + '.join(POSITION_FMUS)} with the fitted parameters reproduce the model "
         f"within {difference_um:.1e} um ({out_dir / 'fmus'})")
    return {"case": str(case.folder), "rounds": rounds, "effects": list(model.names),
            "params": model.values, "model": str(model_path), "report": str(report_path),
            "laser_example": str(laser_path),
            "fmu_max_difference_um": difference_um}
