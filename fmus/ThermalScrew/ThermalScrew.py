"""ThermalScrew FMU: finite-difference screw heating and its positioning error (Rong et al. 2023).

Thin adapter over feedaxis.physics.thermal (Eq. 1-19); defaults: Table 1 and the X axis
of Table 3. The temperature field is advanced in stable sub-steps of at most
``time_step_s`` whatever the communication step.
"""
from dataclasses import fields

import numpy as np
from pythonfmu import DefaultExperiment

from feedaxis_fmu_physics import fmu_steps, thermal
from feedaxis_slave import AxisSlave

UNITS = {"length_m": "m", "diameter_m": "m", "density_kg_m3": "kg/m3",
         "specific_heat_J_kgK": "J/(kg.K)", "expansion_per_K": "1/K", "nut_length_m": "m",
         "bearing_length_m": "m", "cell_length_m": "m", "time_step_s": "s",
         "conductivity_W_mK": "W/(m.K)", "k1_W_m2K_per_mm_min": "W.min/(m2.K.mm)",
         "k2_W_m2K": "W/(m2.K)", "k3_W_per_mm_min": "W.min/mm", "k4_W_per_mm_min": "W.min/mm",
         "fixed_end_mm": "mm", "ambient_reference_offset_mm": "mm"}
DESCRIPTIONS = {"length_m": "Screw length L", "diameter_m": "Screw diameter D",
                "density_kg_m3": "Density rho", "specific_heat_J_kgK": "Specific heat c",
                "expansion_per_K": "Expansion coefficient alpha", "nut_length_m": "Nut length L_N",
                "bearing_length_m": "Fixed-end bearing length L_B",
                "cell_length_m": "Finite-difference cell length dx",
                "time_step_s": "Largest internal time step dt (sub-stepped further if unstable)",
                "conductivity_W_mK": "Thermal conductivity lambda (identified, Table 3)",
                "k1_W_m2K_per_mm_min": "h = k1 v + k2 (Eq. 17)", "k2_W_m2K": "h = k1 v + k2 (Eq. 17)",
                "k3_W_per_mm_min": "Bearing heat Q_B = k3 v (Eq. 18)",
                "k4_W_per_mm_min": "Nut heat Q_N = k4 v (Eq. 19)",
                "fixed_end_mm": "Axis coordinate P_f of the fixed end (Eq. 15-16)",
                "ambient_reference_offset_mm": "TE_a = alpha dT_a (X - P_f - offset) (Eq. 1)"}


class ThermalScrew(AxisSlave):
    """Temperature field of the screw driven by the nut's motion; thermal positioning error."""

    # the cross-check run ThermalScrew_ref.opt: start, stop and step
    default_experiment = DefaultExperiment(start_time=0.0, stop_time=900.0, step_size=1.0)
    description = "Ball-screw thermal error from a 1-D finite-difference model (Rong et al. 2023)"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.input("position_mm", 0.0, "Axis position (nut position through P_f)", "mm")
        self.input("velocity_mm_s", 0.0, "Axis velocity; |v| drives heat and convection", "mm/s")
        self.input("ambient_C", 20.0, "Ambient air temperature", "degC")
        self.output("error_um", "Thermal positioning error at position_mm, TE (Eq. 15-16)", "um")
        self.output("elongation_um", "Free-end elongation of the screw TE_m(L)", "um")
        self.output("peak_rise_K", "Largest temperature rise of the screw above ambient", "K")
        self.parameter("reference_ambient_C", 20.0, "Ambient at which TE_a = 0 (Eq. 1)", "degC",
                       tunable=True)
        for field in fields(thermal.ThermalScrewParams):
            limits = None if field.name.endswith("_mm") else (0, None)
            self.parameter(field.name, float(field.default), DESCRIPTIONS[field.name],
                           UNITS[field.name], limits)
        self.position_offset_parameter("the nut is at position_offset_mm + position_mm")
        self.rise_K = None

    def build(self):
        params = thermal.ThermalScrewParams(
            **{field.name: getattr(self, field.name) for field in fields(thermal.ThermalScrewParams)})
        self.rise_K = np.zeros(params.n_cells)
        return params

    def step(self, step_size_s):
        position_mm = self.position_offset_mm + self.position_mm
        self.rise_K = thermal.advance(self.model, self.rise_K, step_size_s, position_mm,
                                      self.velocity_mm_s * 60.0)
        ambient_delta_K = self.ambient_C - self.reference_ambient_C
        self.error_um = float(thermal.thermal_error_um(self.model, self.rise_K, position_mm,
                                                       ambient_delta_K))
        self.elongation_um = float(thermal.screw_elongation_um(self.model, self.rise_K,
                                                               self.model.length_m))
        self.peak_rise_K = float(self.rise_K.max())

    def native_step(self):
        return fmu_steps.native_step("ThermalScrew")

    def native_block(self):
        return fmu_steps.thermal_screw_block(self.position_offset_mm, self.reference_ambient_C,
                                             self.model.cells, self.rise_K)

    def restore_native(self, block):
        self.rise_K = np.array(fmu_steps.thermal_screw_rise_K(block))

    def model_state(self):
        return {"rise_K": self.rise_K.tolist()}

    def restore_model_state(self, state):
        rise_K = np.array(state["rise_K"], dtype=float)
        if rise_K.shape != (self.model.n_cells,) or not np.isfinite(rise_K).all():
            raise ValueError(f"rise_K must be {self.model.n_cells} finite temperatures")
        self.rise_K = rise_K
