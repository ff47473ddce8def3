"""`feedaxis demo`: the whole loop on the bundled Liu 2023 case, then the FMUs.

Each round diagnoses the model, adds the best missing effect and refits, until the verdict
is no longer ``missing_effect``. The case (copied first, to try the loop by hand on), the
laser example (an ``axis.toml`` and ``.rtl`` for ``feedaxis import``), the fitted model, the
report and the FMUs are written to the output folder, and the FMUs driven with the fitted
parameters are checked against the model.
"""
from __future__ import annotations

from dataclasses import replace
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
from .output import staged_folder, write_atomically
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
        echo(f"round {number}: RMS {diagnosis.rms_um:.4f} µm (noise {diagnosis.noise_um:.4f} µm)"
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
        echo(f"    add {best.effect}, refit: RMS {best.rms_after_um:.4f} µm")
    return model, rounds, diagnose(case, model, effects)


def ladder_of(rounds):
    """The error ladder [(label, RMS µm)] of a loop started from the empty model."""
    return [("measured", rounds[0]["rms_um"])] + [
        (f"+ {r['added']}", r["rms_after_um"]) for r in rounds if "added" in r]


def run_demo(out_dir, echo=print):
    """Run the loop on the bundled case and write the case, model, report, laser example and
    FMUs to ``out_dir``.

    They are written together (:func:`feedaxis.output.staged_folder`): an error, a full disk
    or Ctrl-C on the way leaves none of them.
    """
    out_dir = Path(out_dir)
    case = replace(read_case(BUNDLED_CASE), folder=out_dir / "case")
    echo(f"case: {case.name}")
    echo(f"      {case.positioning.size} laser points, {case.positioning.target_mm.min():g} to "
         f"{case.positioning.target_mm.max():g} mm; model: empty; copied to {case.folder}")
    model, rounds, diagnosis = improve(case, Model(), echo=echo)
    analysis = analyse(case, model, CATALOG, diagnosis=diagnosis, ladder=ladder_of(rounds))
    with staged_folder(out_dir) as staging:
        _copy_files(BUNDLED_CASE, staging / "case")
        write_atomically(staging / "model.toml", fit(model, case).fitted_model().to_toml())
        write_report(analysis, staging / "report.html")
        _copy_files(LASER_EXAMPLE, staging / "laser-example")
        fmu_paths = {path.stem: path for path in build_fmus(staging / "fmus", POSITION_FMUS)}
        difference_um = float(np.max(np.abs(replay_positioning(case, model, fmu_paths)
                                            - model.predict_um(case))))
    model_path, report_path = out_dir / "model.toml", out_dir / "report.html"
    laser_path = out_dir / "laser-example"
    echo(f"fitted model: {model_path}")
    echo(f"report:       {report_path}")
    echo(f"laser example: {laser_path} (axis.toml + X-axis.rtl for feedaxis import)")
    echo(f"FMUs {' + '.join(POSITION_FMUS)} with the fitted parameters reproduce the model "
         f"within {difference_um:.1e} µm ({out_dir / 'fmus'})")
    return {"case": str(case.folder), "rounds": rounds, "effects": list(model.names),
            "params": model.values, "model": str(model_path), "report": str(report_path),
            "laser_example": str(laser_path),
            "fmu_max_difference_um": difference_um}


def _copy_files(source, target):
    """The files of folder ``source`` written into ``target`` (a full disk named as such)."""
    for path in sorted(source.iterdir()):
        if path.is_file():
            write_atomically(target / path.name, path.read_bytes())
