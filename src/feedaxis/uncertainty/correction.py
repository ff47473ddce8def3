"""Positioning deviations corrected to 20 °C, the reference temperature of ISO 1 that
ISO 230-2 reports at: the normal thermal expansion of the axis's measuring system (its
screw, or a scale) at the machine temperature T is taken out,

    x_20 = x - α·(T - 20 °C)·(X - X_ref)·10³   (µm, X in mm),

the ambient expansion of Rong et al. 2023 Eq. 1 (:func:`feedaxis.physics.thermal.ambient_error_um`,
the function the ``ambient_expansion`` effect and the ThermalScrew FMU use), α the screw's
``expansion_per_K`` and X_ref its fixed end (``fixed_end_mm``, where a screw held in its
fixed bearing grows from; 0 mm without it). T is the material temperature of each sample
(``material_C``, what a laser system's material sensors record), the ambient temperature
of each sample (``ambient_C``) or one measured material temperature.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

from ..case import AXIS_FILE, PHYSICAL_RANGE
from ..errors import InputError
from ..fmu_map import ISO_REFERENCE_TEMPERATURE_C
from ..physics.thermal import ThermalScrewParams, ambient_error_um

OPTION = "--correct-to-20C"
AMBIENT = "ambient"
MATERIAL = "material"
SAMPLE_COLUMN = {MATERIAL: "material_C", AMBIENT: "ambient_C"}
OPTION_HELP = ("correct the deviations to 20 °C for the thermal expansion of the screw "
               "(axis.toml expansion_per_K) at T: 'material' (each sample's material_C; the "
               "default when the option is given without T), 'ambient' (each sample's "
               "ambient_C) or the machine's measured material temperature in °C, e.g. 21.4")


def temperature_option(text):
    """The value of ``--correct-to-20C``: ``"material"``, ``"ambient"`` or a temperature in
    °C (argparse ``type``); :class:`InputError` naming the option otherwise."""
    if text.strip().lower() in SAMPLE_COLUMN:
        return text.strip().lower()
    low, high = PHYSICAL_RANGE["ambient_C"]
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not low <= value <= high:
        raise InputError(f"expected 'material', 'ambient' or a temperature in °C from {low:g} "
                         f"to {high:g}",
                         parameter=f"{OPTION} {text}")
    return value


@dataclass(frozen=True)
class Correction:
    """The correction to 20 °C of one case: the temperature (°C, per sample or one value),
    where it came from, and the screw's expansion from its reference."""

    temperature_C: object
    source: str
    params: ThermalScrewParams

    @property
    def expansion_per_K(self):
        return self.params.expansion_per_K

    @property
    def reference_mm(self):
        return self.params.fixed_end_mm

    def expansion_um(self, position_mm, expansion_per_K=None, temperature_offset_K=0.0):
        """The thermal expansion (µm) the correction removes at ``position_mm``, with the
        expansion coefficient ``expansion_per_K`` (default: the screw's) and the temperature
        off by ``temperature_offset_K``; arrays broadcast (a Monte Carlo's trials)."""
        scale = 1.0 if expansion_per_K is None else expansion_per_K / self.expansion_per_K
        delta_K = (self.temperature_C + temperature_offset_K
                   - ISO_REFERENCE_TEMPERATURE_C) * scale
        return ambient_error_um(self.params, position_mm, delta_K)

    def to_json(self):
        return {"temperature": self.source, "expansion_per_K": self.expansion_per_K,
                "reference_mm": self.reference_mm}


def correction_for(case, temperature):
    """The :class:`Correction` of ``case`` at ``temperature`` (``"material"``,
    ``"ambient"`` or °C).

    Raises
    ------
    InputError
        When axis.toml has no ``[screw] expansion_per_K``, or ``"material"`` or
        ``"ambient"`` is asked of a case without the ``material_C`` or ``ambient_C`` column.
    """
    screw = case.axis.screw
    if "expansion_per_K" not in screw:
        raise InputError(f"{OPTION} needs the expansion coefficient of the screw: [screw] "
                         "expansion_per_K", path=case.folder / AXIS_FILE,
                         column="screw.expansion_per_K")
    if temperature in SAMPLE_COLUMN:
        column = SAMPLE_COLUMN[temperature]
        temperature_C = getattr(case.positioning, column)
        if temperature_C is None:
            from ..measurement.positioning import POSITIONING_FILE  # SciPy-heavy: on error

            raise InputError(f"{OPTION} {temperature} needs the {column} column; or give the "
                             f"material temperature in °C, e.g. {OPTION} 21.4",
                             path=case.folder / POSITIONING_FILE, column=column)
        source = f"{column} of each sample"
    else:
        temperature_C, source = float(temperature), f"material temperature {temperature:g} °C"
    params = ThermalScrewParams(expansion_per_K=screw["expansion_per_K"],
                                fixed_end_mm=screw.get("fixed_end_mm", 0.0))
    return Correction(temperature_C, source, params)


def corrected_case(case, temperature):
    """``case`` with its positioning deviations corrected to 20 °C at ``temperature``
    (``"ambient"`` or °C); ``case`` itself when ``temperature`` is None."""
    if temperature is None:
        return case
    if case.positioning is None:
        raise InputError(f"{OPTION} corrects positioning.csv; the case has none",
                         path=case.folder)
    correction = correction_for(case, temperature)
    positioning = case.positioning
    error_um = positioning.error_um - correction.expansion_um(positioning.target_mm)
    return case.with_samples("positioning", replace(positioning,
                                                    error_um=np.asarray(error_um, dtype=float)))
