"""Write the FMI cross-check files <Name>_in.csv, <Name>_ref.csv, <Name>_ref.opt per FMU.

The reference outputs come from feedaxis.physics called directly with the FMUs' default
parameters, so compliance tools (fmuCheck ``-i <Name>_in.csv``) and tests/fmus/test_fmus.py check
each FMU against its physics. The layout follows the FMI Cross-Check rules: every column
name quoted, ``<Name>_ref.opt`` beside them.
Run from the repository root: ``python tests/make_fmu_references.py``.
"""
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from scenarios import N_STEPS, OUTPUTS, STEP_SIZE_S, direct, scripted_inputs  # noqa: E402

from feedaxis.fmu_build import FMU_NAMES  # noqa: E402

FMU_SOURCES = Path(__file__).resolve().parents[1] / "fmus"


def write_reference(name):
    inputs = scripted_inputs(name)
    h, n = STEP_SIZE_S[name], N_STEPS[name]
    folder = FMU_SOURCES / name
    folder.mkdir(exist_ok=True)
    t_in = np.arange(n) * h
    _write_csv(folder / f"{name}_in.csv", t_in, inputs)
    outputs = direct(name, inputs, {})
    _write_csv(folder / f"{name}_ref.csv", np.arange(n + 1) * h,
               {out: outputs[:, i] for i, out in enumerate(OUTPUTS[name])})
    (folder / f"{name}_ref.opt").write_text(
        f"StartTime, 0.0\nStopTime, {n * h!r}\nStepSize, {h!r}\nRelTol, 1e-06\n")


def _write_csv(path, time_s, columns):
    header = ",".join(f'"{c}"' for c in ["time", *columns])
    table = np.column_stack([time_s] + [np.asarray(v, dtype=float) for v in columns.values()])
    np.savetxt(path, table, delimiter=",", header=header, comments="", fmt="%.17g")


if __name__ == "__main__":
    for fmu_name in FMU_NAMES:
        write_reference(fmu_name)
        print(FMU_SOURCES / fmu_name)
