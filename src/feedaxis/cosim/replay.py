"""Replay a fitted model through the FMUs at a case's positioning samples.

The fit and the FMUs call the same physics, so the FMUs driven with
``Model.fmu_parameters`` must reproduce the model's prediction; this is the check.
"""
from __future__ import annotations

import numpy as np

from .fmu_runner import run_fmu

POSITION_FMUS = ("GeometricError", "StepperError")
POSITION_EFFECTS = {"lead_error", "gravity_sag", "assembly_eccentricity", "motor_step_error",
                    "backlash"}


def replay_positioning(case, model, fmu_paths):
    """Sum of GeometricError and StepperError outputs, one FMU step per sample (µm).

    Parameters
    ----------
    case : Case
    model : Model
        Only position-dependent effects (geometry, motor, backlash); thermal effects need
        the co-simulated axis with its motion history.
    fmu_paths : dict
        FMU name -> path of the built FMU.
    """
    extra = [name for name in model.names if name not in POSITION_EFFECTS]
    if extra:
        raise ValueError(f"replay covers position-dependent effects only, not {', '.join(extra)}")
    parameters = model.fmu_parameters(case.axis)
    positioning = case.positioning
    inputs = {"position_mm": positioning.target_mm, "velocity_mm_s": positioning.direction}
    total_um = np.zeros(positioning.size)
    for name in POSITION_FMUS:
        wanted = {k: v for k, v in inputs.items() if name == "GeometricError" or k == "position_mm"}
        result = run_fmu(fmu_paths[name], 1.0, positioning.size, wanted, parameters[name],
                         ("error_um",), instance_name=name)
        total_um += result["error_um"]
    return total_um
