"""The loop on the bundled case, from Python: diagnose, add the missing effect, refit, repeat.

Run: ``python examples/loop_on_bundled_case.py``. The same loop as ``feedaxis demo``
(the micro ball screw of Liu 2023, reconstructed), without the report and the FMUs.
"""
from feedaxis.case import read_case
from feedaxis.demo import improve
from feedaxis.effects import Model
from feedaxis.examples import BUNDLED_CASE
from feedaxis.fit import fit

case = read_case(BUNDLED_CASE)
model, rounds, diagnosis = improve(case, Model())   # prints one block per round
result = fit(model, case)
for effect, values in result.params().items():
    for name, value in values.items():
        sigma = result.uncertainties[effect][name]
        print(f"{effect + '.' + name:44s} {value:+.4f} +/- {sigma:.4f}")
print(f"{len(rounds)} rounds, verdict {diagnosis.verdict}, RMS {result.rms_um:.4f} µm")
