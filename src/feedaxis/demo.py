"""`feedaxis demo` until the comparison loop lands: build the FMUs and run each through fmpy."""
from __future__ import annotations

import numpy as np

from .cosim.fmu_runner import run_fmu
from .fmu_build import build_fmus

DEMO_RUNS = {
    "NpidServo": dict(step_size_s=1e-3, duration_s=5.0, outputs=("tracking_error_mm",),
                      inputs=lambda t: {"position_ref_mm": 10.0 * np.sin(2 * np.pi * 0.4 * t)},
                      measure=lambda e: (np.max(np.abs(e[e.size // 2:])),),
                      summary="PID, 0.4 Hz x 10 mm sine: settled max |tracking error| {:.4f} mm "
                              "(seed 002 Table 1: 0.0639 mm)"),
    "StepperError": dict(step_size_s=0.01, duration_s=1.0, outputs=("error_um",),
                         inputs=lambda t: {"position_mm": 0.04 * t},
                         measure=lambda e: (np.ptp(e),),
                         summary="motor ripple over 0.04 mm: peak-to-valley {:.3f} um"),
    "GeometricError": dict(step_size_s=0.01, duration_s=5.0, outputs=("error_um",),
                           inputs=lambda t: {"position_mm": t, "velocity_mm_s": np.ones_like(t)},
                           measure=lambda e: (e[0], e[-1]),
                           summary="0 to 5 mm at 1 mm/s: error from {:.2f} to {:.2f} um "
                                   "(seed 001: 0 to about -3 um, 1 mm ripple)"),
    "ThermalScrew": dict(step_size_s=1.0, duration_s=3600.0, outputs=("elongation_um",),
                         inputs=lambda t: {"position_mm": 250.0 - 250.0 * np.cos(2 * np.pi * t / 10.0),
                                           "velocity_mm_s": np.full_like(t, 100.0),
                                           "ambient_C": np.full_like(t, 20.0)},
                         measure=lambda e: (np.max(np.abs(e)),),
                         summary="1 h back and forth at 6000 mm/min: screw elongation {:.1f} um"),
}


def run_demo(out_dir, echo=print):
    """Build the four FMUs into ``out_dir``, run each and return {name: summary line}."""
    summaries = {}
    for path in build_fmus(out_dir):
        run = DEMO_RUNS[path.stem]
        n = int(round(run["duration_s"] / run["step_size_s"]))
        t = np.arange(n) * run["step_size_s"]
        result = run_fmu(path, run["step_size_s"], n, run["inputs"](t), {}, run["outputs"])
        numbers = run["measure"](result[run["outputs"][0]])
        summaries[path.stem] = run["summary"].format(*numbers)
        echo(f"{path.stem:15s} {summaries[path.stem]}")
    return summaries
