"""Your own effect closing an error the catalog does not know (docs/own-effect.md).

Run: ``python examples/own_effect.py``. A 0.2 µm ripple of 0.37 mm is added to the demo
case; the catalog model leaves it as an unexplained periodic structure, and the user effect
of ``coupling_ripple.py`` (next to this file) fitted on top closes the residual to the noise.
"""
import tempfile
from pathlib import Path

from feedaxis.case import read_case
from feedaxis.diagnose import diagnose
from feedaxis.effects import CATALOG, Model
from feedaxis.effects.files import load_user_effects
from feedaxis.examples import write_seed001_case
from feedaxis.fit import fit

user_effects = load_user_effects(Path(__file__).with_name("coupling_ripple.py"))
effects = {**CATALOG, **user_effects}
with tempfile.TemporaryDirectory() as folder:   # the case is read whole into memory
    case = read_case(write_seed001_case(Path(folder) / "ripple-case", ripple=(0.37, 0.2)))
start = fit(Model([CATALOG[name] for name in
                   ("lead_error", "assembly_eccentricity", "motor_step_error")]), case).model
before = diagnose(case, start, CATALOG)       # the catalog alone: no effect fits it
print(f"catalog model: RMS {before.rms_um:.4f} µm, verdict {before.verdict}")
for structure in before.unexplained:
    print(f"  unexplained {structure.kind}: {structure.evidence}")
final = fit(start + effects["coupling_ripple"], case).model
after = diagnose(case, final, effects)
print(f"with coupling_ripple: RMS {after.rms_um:.4f} µm (noise {after.noise_um:.4f} µm), "
      f"verdict {after.verdict}")
