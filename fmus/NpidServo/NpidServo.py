"""NpidServo FMU: ball-screw position loop with PID or NPID control (Anang et al. 2017 Eq. 1-8)
or a drive's cascade (P position loop around a PI velocity loop, ``controller = "cascade"``).

Thin adapter over feedaxis.physics.servo; defaults are the Googol XY table x axis.
"""
from dataclasses import fields

from pythonfmu import DefaultExperiment

from feedaxis_fmu_physics import fmu_steps, servo
from feedaxis_slave import AxisSlave

# doStep's cost grows with h / time_step_s (one loop iteration per internal step, about
# 2 µs each in Python, 20 ns compiled): a step needing more is refused, so one call stays
# under a second.
MAX_INTERNAL_STEPS = 200_000
# Largest internal step: 1 ms, ten times Anang et al. 2017's 0.1 ms and under its 1.2 ms delay, which
# the loop represents in whole internal steps.
MAX_TIME_STEP_S = 1e-3

UNITS = {"controller": None, "plant_gain_mm_per_Vs2": "mm/(V.s2)", "plant_damping_per_s": "1/s",
         "plant_stiffness_per_s2": "1/s2", "delay_s": "s", "kp_V_per_mm": "V/mm",
         "ki_V_per_mm_s": "V/(mm.s)", "kd_V_s_per_mm": "V.s/mm", "ko_per_mm": "1/mm",
         "e_max_mm": "mm", "nonlinear": None, "force_constant_N_per_V": "N/V", "time_step_s": "s",
         "friction_N": "N", "damping_N_s_per_mm": "N.s/mm", "kp_per_s": "1/s",
         "kv_V_s_per_mm": "V.s/mm", "tn_s": "s", "velocity_feedforward": None, "force_N": "N",
         "coulomb_N": "N", "static_N": "N", "stribeck_velocity_mm_s": "mm/s"}
DESCRIPTIONS = {
    "controller": "pid | npid | cascade (P position loop around a velocity loop)",
    "plant_gain_mm_per_Vs2": "Plant numerator b of G(s) = b / (s2 + a1 s + a0) (Eq. 1)",
    "plant_damping_per_s": "Plant a1 (Eq. 1)", "plant_stiffness_per_s2": "Plant a0 (Eq. 1)",
    "delay_s": "Transport delay of the command (Anang et al. 2017: 1.2 ms)",
    "kp_V_per_mm": "PID proportional gain (Eq. 6)", "ki_V_per_mm_s": "PID integral gain (Eq. 6)",
    "kd_V_s_per_mm": "PID derivative gain (Eq. 6)", "ko_per_mm": "NPID rate KO (Eq. 8)",
    "e_max_mm": "NPID error beyond which K(e) is held (Eq. 8)",
    "nonlinear": "true: NPID (nonlinear gain in front of the PID), false: PID",
    "force_constant_N_per_V": "Axial force per volt of command (assumed; not in Anang et al. 2017)",
    "time_step_s": "Internal loop step",
    "friction_N": "Coulomb friction opposing the velocity (smoothed over |v| < 0.1 mm/s)",
    "damping_N_s_per_mm": "Viscous friction force per unit velocity",
    "kp_per_s": "Cascade position loop gain (velocity command per mm of error)",
    "kv_V_s_per_mm": "Cascade velocity loop gain (V per mm/s of velocity error)",
    "tn_s": "Cascade velocity loop integral time (0: no integral action)",
    "velocity_feedforward": "Cascade velocity feed-forward, share of dr/dt (0 to 1)",
    "force_N": "Constant axial force (weight on an inclined axis, a counterbalance)",
    "coulomb_N": "Stribeck friction: the Coulomb level in motion",
    "static_N": "Stribeck friction: the level at rest",
    "stribeck_velocity_mm_s": "Stribeck friction: the velocity over which it falls to Coulomb"}
NO_LIMITS = ("nonlinear", "controller", "force_N")


class NpidServo(AxisSlave):
    """Closed position loop: reference in, axial position, velocity and tracking error out."""

    # the cross-check run NpidServo_ref.opt: start, stop and step
    default_experiment = DefaultExperiment(start_time=0.0, stop_time=1.5, step_size=0.001)
    description = "Ball-screw position servo, PID or NPID (Anang et al. 2017) or a drive's cascade"

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.input("position_ref_mm", 0.0, "Commanded axis position", "mm")
        self.input("disturbance_N", 0.0, "External axial force, e.g. cutting force", "N")
        self.output("position_mm", "Axial position the motor angle commands (lead x turns)", "mm")
        self.output("velocity_mm_s", "Axial velocity", "mm/s")
        self.output("tracking_error_mm", "Position minus reference (the sign of every "
                    "feedaxis deviation: measured - commanded)", "mm")
        self.output("control_V", "Controller output", "V")
        for field in fields(servo.ServoParams):
            limits = (None if field.name in NO_LIMITS else
                      {"time_step_s": (0, MAX_TIME_STEP_S)}.get(field.name, (0, None)))
            self.parameter(field.name, field.default, DESCRIPTIONS[field.name], UNITS[field.name],
                           limits)
        self.position_offset_parameter("the loop runs to position_offset_mm + position_ref_mm "
                                       "and position_mm is its position less it")

    def build(self):
        if not self.time_step_s <= MAX_TIME_STEP_S:
            raise ValueError(f"time_step_s must be <= {MAX_TIME_STEP_S} s, got {self.time_step_s!r}")
        params = servo.ServoParams(
            **{field.name: getattr(self, field.name) for field in fields(servo.ServoParams)})
        return servo.Servo(params,
                           initial_reference_mm=self.position_offset_mm + self.position_ref_mm)

    def step(self, step_size_s):
        internal_steps = step_size_s / self.time_step_s
        if internal_steps > MAX_INTERNAL_STEPS:
            raise ValueError(f"a communication step of {step_size_s} s needs {internal_steps:.3g} "
                             f"internal steps of time_step_s = {self.time_step_s} s; at most "
                             f"{MAX_INTERNAL_STEPS} are taken in one doStep (split the step)")
        self.model.advance(step_size_s, self.position_offset_mm + self.position_ref_mm,
                           self.disturbance_N)
        (position_mm, self.velocity_mm_s, self.tracking_error_mm,
         self.control_V) = self.model.outputs()
        self.position_mm = position_mm - self.position_offset_mm

    def native_step(self):
        return fmu_steps.native_step("NpidServo")

    def native_block(self):
        return fmu_steps.npid_servo_block(self.position_offset_mm, self.model.params,
                                          MAX_INTERNAL_STEPS, self.model.coefficients,
                                          self.model.state())

    def restore_native(self, block):
        self.model.restore(fmu_steps.npid_servo_state(block))

    def model_state(self):
        return self.model.state()

    def restore_model_state(self, state):
        self.model.restore(state)
