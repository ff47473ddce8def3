"""Your own effect: a worn shaft coupling that adds a ripple once per 0.37 mm of travel.

Load it with ``--effects examples/coupling_ripple.py``; it then takes part in fit,
diagnose and report like a built-in effect. An effect is a function of the case and its
parameters returning the error in µm at each positioning sample, wrapped with ``@effect``.
"""
import numpy as np

from feedaxis.effects import Parameter, effect

WAVELENGTH_MM = 0.37


@effect("coupling_ripple", "a worn shaft coupling adds a ripple once per 0.37 mm of travel",
        [Parameter("cos_um", "um", -5.0, 5.0, "cosine amplitude"),
         Parameter("sin_um", "um", -5.0, 5.0, "sine amplitude")],
        wavelength_mm=WAVELENGTH_MM)
def coupling_ripple(case, cos_um, sin_um):
    phase_rad = 2 * np.pi * case.positioning.target_mm / WAVELENGTH_MM
    return cos_um * np.cos(phase_rad) + sin_um * np.sin(phase_rad)
