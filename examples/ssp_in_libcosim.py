"""The axis exported as SSP and run in another importer, OSP libcosim (docs/cosim.md).

Run: ``python examples/ssp_in_libcosim.py`` (needs ``libcosimpy``). Writes ``axis.ssp`` in
a temporary folder (removed at the end), then steps it in libcosim with a sinusoidal
position reference.
"""
import tempfile
from pathlib import Path

import numpy as np
from libcosimpy.CosimExecution import CosimExecution
from libcosimpy.CosimLogging import CosimLogLevel, log_output_level
from libcosimpy.CosimManipulator import CosimManipulator
from libcosimpy.CosimObserver import CosimObserver

from feedaxis.cosim.fmu_cache import cached_fmus
from feedaxis.cosim.ssp import export_ssp
from feedaxis.cosim.system import default_axis

log_output_level(CosimLogLevel.WARNING)                  # libcosim logs every FMU call
with tempfile.TemporaryDirectory() as folder:
    ssp = export_ssp(Path(folder) / "axis.ssp", default_axis(), cached_fmus())
    execution = CosimExecution.from_ssp_file(str(ssp))   # base step 1 ms, thermal 0.1 s
    servo = execution.slave_index_from_instance_name("NpidServo")
    vr = {v.name.decode(): v.reference for v in execution.slave_variables(servo)}
    override, observer = CosimManipulator.create_override(), CosimObserver.create_last_value()
    execution.add_manipulator(override)
    execution.add_observer(observer)
    for k in range(500):                                  # 0.5 s; override k drives step k
        override.slave_real_values(servo, [vr["position_ref_mm"]],
                                   [10 * np.sin(2 * np.pi * 0.4 * k * 1e-3)])
        execution.step()
    print(observer.last_real_values(servo, [vr["position_mm"], vr["tracking_error_mm"]]))
