"""StepperError FMU: stepper-motor angular error as axial displacement (Liu 2022 Eq. 6, 9, 10).

Thin adapter over feedaxis.physics.motor. Liu 2023 does not publish its motor coefficients;
the default first harmonic (0.1 µm amplitude) is illustrative.
"""
from pythonfmu import DefaultExperiment

from feedaxis_fmu_physics import fmu_steps, motor
from feedaxis_slave import AxisSlave


class StepperError(AxisSlave):
    """Periodic motor error over ``error_period_steps`` full steps, through the lead."""

    # the cross-check run StepperError_ref.opt: start, stop and step
    default_experiment = DefaultExperiment(start_time=0.0, stop_time=6.0, step_size=0.01)
    description = "Stepper-motor angular error mapped to axial displacement through the screw lead"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.input("position_mm", 0.0, "Axis position (rotor angle = position / lead x 360 deg)", "mm")
        self.output("error_um", "Axial displacement error of the motor", "um")
        self.parameter("lead_mm", 1.0, "Screw lead", "mm", (0, None))
        self.parameter("step_angle_deg", 0.72, "Full-step angle", "deg", (0, None))
        self.parameter("error_period_steps", 10, "Steps in one period of the angular error", None, (1, None))
        self.parameter("harmonic1_cos_um", 0.08, "First harmonic, cosine amplitude", "um", tunable=True)
        self.parameter("harmonic1_sin_um", 0.06, "First harmonic, sine amplitude", "um", tunable=True)
        self.parameter("harmonic2_cos_um", 0.0, "Second harmonic, cosine amplitude", "um", tunable=True)
        self.parameter("harmonic2_sin_um", 0.0, "Second harmonic, sine amplitude", "um", tunable=True)
        self.position_offset_parameter("the error is that at position_offset_mm + position_mm")

    def build(self):
        return motor.motor_error_period_mm(self.lead_mm, self.step_angle_deg, self.error_period_steps)

    def step(self, step_size_s):
        self.error_um = float(motor.motor_error_um(
            self.position_offset_mm + self.position_mm, self.model, (self.harmonic1_cos_um, self.harmonic2_cos_um),
            (self.harmonic1_sin_um, self.harmonic2_sin_um)))

    def native_step(self):
        return fmu_steps.native_step("StepperError")

    def native_block(self):
        return fmu_steps.stepper_error_block(
            self.position_offset_mm, self.model, (self.harmonic1_cos_um, self.harmonic2_cos_um),
            (self.harmonic1_sin_um, self.harmonic2_sin_um))
