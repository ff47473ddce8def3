"""GeometricError FMU: transmission error of the screw-nut pair (Liu 2022/2023 Eq. 1-5, 10).

Thin adapter over feedaxis.physics.geometry; defaults are the Liu 2023 case-study fit.
"""
from pythonfmu import DefaultExperiment

from feedaxis_fmu_physics import fmu_steps, geometry, mounting
from feedaxis_slave import AxisSlave


class GeometricError(AxisSlave):
    """Lead error + assembly eccentricity + backlash + gravity sag at the nut position."""

    # the cross-check run GeometricError_ref.opt: start, stop and step
    default_experiment = DefaultExperiment(start_time=0.0, stop_time=6.0, step_size=0.01)
    description = ("Ball-screw transmission error: cumulative lead error, assembly eccentricity "
                   "(wavelength = lead), backlash by direction of motion, gravity sag")

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.input("position_mm", 0.0, "Axis position", "mm")
        self.input("velocity_mm_s", 0.0, "Axis velocity; velocity x step moves the nut through its backlash play", "mm/s")
        self.output("error_um", "Positioning deviation, actual - nominal (ISO 230-2 sign)", "um")
        self.parameter("lead_mm", 1.0, "Screw lead, axial travel per revolution", "mm", (0, None))
        self.parameter("offset_um", 0.2515, "Lead error b1 at position 0 (Liu 2023)", "um", tunable=True)
        self.parameter("slope_um_per_mm", -0.5084, "Cumulative lead error a1 (Liu 2023)", "um/mm", tunable=True)
        self.parameter("eccentricity_cos_um", 0.2005, "Eccentricity a2, cosine term (Liu 2023)", "um", tunable=True)
        self.parameter("eccentricity_sin_um", 0.1504, "Eccentricity b2, sine term (Liu 2023)", "um", tunable=True)
        self.parameter("backlash_um", 0.0, "Reversal value B = mean(+) - mean(-)", "um")
        self.parameter("sag_enabled", True, "Add the gravity sag computed from the screw (Eq. 3-5)")
        self.parameter("length_m", 0.8, "Screw length between supports", "m", (0, None))
        self.parameter("diameter_m", 0.034, "Screw root diameter", "m", (0, None))
        self.parameter("density_kg_m3", 7800.0, "Screw material density", "kg/m3", (0, None))
        self.parameter("youngs_modulus_Pa", 2.1e11, "Screw Young's modulus", "Pa", (0, None))
        self.parameter("support", "fixed-free", "How the screw is held: fixed-free, fixed-fixed or supported-supported")
        self.parameter("fixed_end_mm", -141.0, "Axis coordinate P_f of the fixed end (Rong et al. 2023 Eq. 15-16)", "mm")
        self.position_offset_parameter("the error is that at position_offset_mm + position_mm")
        self.engagement = 1.0  # in the backlash play: -1 to +1 (geometry.play_engagement)

    def build(self):
        if self.support not in geometry.SUPPORTS:
            raise ValueError(f"support must be one of {geometry.SUPPORTS}, got {self.support!r}")
        return geometry.gravity_sag_table(self.length_m, self.diameter_m, self.density_kg_m3,
                                          self.youngs_modulus_Pa, self.support)

    def step(self, step_size_s):
        self.engagement = geometry.play_engagement(
            self.engagement, self.velocity_mm_s * step_size_s, self.backlash_um)
        position_mm = self.position_offset_mm + self.position_mm
        sag_um = 0.0
        if self.sag_enabled:
            screw_m = mounting.screw_coordinate_m(position_mm, self.fixed_end_mm)
            sag_um = geometry.gravity_sag_error_um(screw_m, self.model)
        self.error_um = float(geometry.transmission_error_um(
            position_mm, self.engagement, self.lead_mm, self.offset_um, self.slope_um_per_mm,
            self.eccentricity_cos_um, self.eccentricity_sin_um, self.backlash_um, sag_um))

    def native_step(self):
        return fmu_steps.native_step("GeometricError")

    def native_block(self):
        return fmu_steps.geometric_error_block(
            self.engagement, self.position_offset_mm, self.lead_mm, self.offset_um,
            self.slope_um_per_mm, self.eccentricity_cos_um, self.eccentricity_sin_um,
            self.backlash_um, self.sag_enabled, self.fixed_end_mm, self.model)

    def restore_native(self, block):
        self.engagement = block[0]

    def model_state(self):
        return {"engagement": self.engagement}

    def restore_model_state(self, state):
        engagement = state["engagement"]
        if (isinstance(engagement, bool) or not isinstance(engagement, (int, float))
                or not -1.0 <= engagement <= 1.0):  # NaN fails the range test too
            raise ValueError(f"engagement must be a number from -1 to 1, got {engagement!r}")
        self.engagement = float(engagement)
