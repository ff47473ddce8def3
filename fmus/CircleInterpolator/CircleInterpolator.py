"""CircleInterpolator FMU: the commanded circle of a circular test (ISO 230-4), the two axes'
position references.

Thin adapter over feedaxis.physics.circle.CircleInterpolator, the function feedaxis's master
commands the circle with. Time 0 is the start of the lead-in arc (the axes stand there before
it). The outputs after a step ending at t are the circle at t + ``ahead_s``: hosts that step
Jacobi (fmpy's simulate_ssp, OMSimulator, libcosim) hand the servos these outputs for the
next step, [t, t + h], and with ``ahead_s`` = h each servo steps towards the circle at
t + h, as the master commands it. A host that steps this FMU before the servos within a
macro step (Gauss-Seidel) needs ``ahead_s`` = 0.

The outputs count from (``origin_first_mm``, ``origin_second_mm``), by default the machine's
origin: set to the circle at ``ahead_s`` (the first reference), with each axis's FMUs'
``position_offset_mm`` the same, they are 0 at initialisation, what a host that passes
nothing on before its first step (fmpy's simulate_ssp) hands the servos.
"""
from pythonfmu import DefaultExperiment

from feedaxis_fmu_physics import circle
from feedaxis_slave import AxisSlave


class CircleInterpolator(AxisSlave):
    """The circle at the programmed feed with its lead-in and lead-out arcs, ahead_s ahead."""

    # the cross-check run CircleInterpolator_ref.opt: start, stop and step
    default_experiment = DefaultExperiment(start_time=0.0, stop_time=5.0, step_size=0.01)
    description = ("Circle interpolator of a circular test (ISO 230-4): both axes' position "
                   "references at the programmed feed, one macro step ahead for hosts that "
                   "step Jacobi")

    def __init__(self, **kwargs):
        super().__init__(**kwargs)
        self.communication_point_s = 0.0
        self.output("first_position_ref_mm", "First axis's commanded position at the end of "
                    "the step + ahead_s (connect to its servo's position_ref_mm)", "mm")
        self.output("second_position_ref_mm", "Second axis's commanded position at the end of "
                    "the step + ahead_s (connect to its servo's position_ref_mm)", "mm")
        self.parameter("radius_mm", 10.0, "Nominal radius of the circle", "mm", (0, None))
        self.parameter("feed_mm_min", 1000.0, "Programmed feed along the circle", "mm/min",
                       (0, None))
        self.parameter("center_first_mm", 10.0, "Centre, first axis's coordinate", "mm")
        self.parameter("center_second_mm", 10.0, "Centre, second axis's coordinate", "mm")
        self.parameter("direction", 1, "1: counter-clockwise (angle from the first axis towards "
                       "the second increasing), -1: clockwise", None, (-1, 1))
        self.parameter("start_deg", 0.0, "Angle where the measured turn starts", "deg")
        self.parameter("lead_in_deg", float(circle.LEAD_IN_DEG), "Arc travelled from standing "
                       "before the measured turn", "deg", (0, 360))
        self.parameter("lead_out_deg", 45.0, "Arc travelled after the measured turn", "deg",
                       (0, 360))
        self.parameter("ahead_s", 1e-3, "How far ahead of the step's end the outputs command: "
                       "one macro step for hosts that step Jacobi (the servos then step towards "
                       "the circle at the end of their step), 0 for one stepping this FMU "
                       "before the servos", "s", (0, None))
        for axis in ("first", "second"):
            self.parameter(f"origin_{axis}_mm", 0.0, f"Machine position of the {axis} axis "
                           f"that {axis}_position_ref_mm = 0 stands for (its FMUs' "
                           "position_offset_mm)", "mm")

    def setup_experiment(self, start_time, stop_time, tolerance):
        self.communication_point_s = start_time

    def enter_initialization_mode(self):
        """The outputs of the parameters set so far, for hosts that pass outputs on to
        connected inputs in initialisation mode (libcosim, OMSimulator: the servos then
        start at the first reference); fmi2ExitInitializationMode computes them again and
        reports a bad parameter."""
        try:
            self.model = self.build()
            self.step(0.0)
        except Exception:  # noqa: BLE001 -- reported at fmi2ExitInitializationMode
            pass
        finally:
            self.model = None

    def build(self):
        return circle.CircleInterpolator(
            self.radius_mm, self.feed_mm_min, (self.center_first_mm, self.center_second_mm),
            self.direction, self.start_deg, self.lead_in_deg, self.lead_out_deg)

    def step(self, step_size_s):
        at_s = self.communication_point_s + step_size_s + self.ahead_s
        self.first_position_ref_mm = (float(self.model.position_mm(at_s, 0))
                                      - self.origin_first_mm)
        self.second_position_ref_mm = (float(self.model.position_mm(at_s, 1))
                                       - self.origin_second_mm)

    def do_step(self, current_time, step_size):
        self.communication_point_s = current_time
        return super().do_step(current_time, step_size)

    def exchanger(self, input_names, output_names):
        """The adapter's exchange (:meth:`AxisSlave.exchanger`), first taking the host's
        communication point, which the step's time is counted from."""
        exchange = super().exchanger(input_names, output_names)

        def clocked(current_time, step_size, *inputs):
            self.communication_point_s = current_time
            return exchange(current_time, step_size, *inputs)

        clocked.state_error, clocked.initialised = exchange.state_error, exchange.initialised
        return clocked
