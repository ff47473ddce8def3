"""The four FMUs as one axis in the project's fmpy master (docs/cosim.md).

Run: ``python examples/cosimulation.py``. The FMUs are built once into the user cache.
"""
import numpy as np

from feedaxis.cosim.fmu_cache import cached_fmus
from feedaxis.cosim.master import Master
from feedaxis.cosim.system import default_axis

t_s = np.arange(1000) * 1e-3                       # 1 s of 1 ms macro steps
with Master(default_axis(), cached_fmus()) as master:
    result = master.run(1.0, {"position_ref_mm": 10 * np.sin(2 * np.pi * 0.4 * t_s),
                              "ambient_C": 22.0},
                        parameters={"NpidServo": {"nonlinear": True}},   # this run only
                        output_interval_s=0.01)
print(result.dtype.names[:6])
print(f"{result['positioning_error_um'][-1]:.3f} µm at {result['table_position_mm'][-1]:.4f} mm")
