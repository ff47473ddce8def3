"""Thermal identification on two loadings and compensation of a third (docs/thermal.md).

Run: ``python examples/thermal_identification.py``. Rong et al. 2023's Table 2 loadings at 3000 and
6000 mm/min identify k1..k4, λ and P_f (Eq. 17-20) with a lead error; the model then
compensates the 9000 mm/min loading, which the fit has not seen.
"""
import tempfile
from pathlib import Path

from feedaxis.case import read_case
from feedaxis.compensate import compensate
from feedaxis.effects import CATALOG, Model
from feedaxis.examples import write_table2_case
from feedaxis.fit import fit

with tempfile.TemporaryDirectory() as folder:   # cases are read whole into memory
    cases = {feed: read_case(write_table2_case(Path(folder) / f"table2-{feed}", feed, seed=seed,
                                               axis_fixed_end_mm=-111.0))
             for seed, feed in enumerate((3000, 6000, 9000))}
result = fit(Model([CATALOG["lead_error"], CATALOG["thermal_screw"]]), [cases[3000], cases[6000]])
for name in ("k2_W_m2K", "conductivity_W_mK", "fixed_end_mm"):
    print(f"thermal_screw.{name}: {result.params()['thermal_screw'][name]:.2f} "
          f"+/- {result.uncertainties['thermal_screw'][name]:.2f}")
compensation = compensate(cases[9000], result.model)
before_um = abs(compensation.thermal_error_um).max()
after_um = abs(compensation.left_um).max()
print(f"9000 mm/min: thermal error max {before_um:.1f} µm -> {after_um:.1f} µm "
      f"({100 * (1 - after_um / before_um):.0f} % less)")
