"""Where the model fails and what is missing: :func:`diagnose` (the decision, tests in
:mod:`.judge`), residual structure (:mod:`.structures`) and the spectrum (:mod:`.spectrum`)."""
from .decision import Candidate, Diagnosis, diagnose, estimate_noise_um
from .spectrum import Spectrum, residual_spectrum
from .structures import Structure

__all__ = ["Candidate", "Diagnosis", "Spectrum", "Structure", "diagnose", "estimate_noise_um",
           "residual_spectrum"]
