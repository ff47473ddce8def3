"""Two axes on a circle: where they go and the closed-form signatures of their errors.

The plane of a circular test (ISO 230-4): angle θ from the first axis towards the second,
nominal path x = c_x + R cos θ, y = c_y + R sin θ, direction +1 counter-clockwise (θ
increasing), −1 clockwise. A small error e_k (µm) of axis k along its own direction moves
the measured radius by e_x cos θ + e_y sin θ (first order in e/R), which is how every
one-axis error shows on the circle (:func:`radial_um`). The closed forms below are that
projection worked out for the classic machine errors; the tests check them against the
co-simulated machine and the diagnosis fits them.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .servo import ServoParams, simulate

UM_PER_MM = 1e3
# Each axis of a machine runs its servo with a type-1 plant (a0 = 0), as the positioning
# tests do: with the a0 of Anang et al. 2017 and its tiny integral gain the loop keeps a
# static error of position/364.
MACHINE_PLANT = {"plant_stiffness_per_s2": 0.0}
LEAD_IN_DEG = 45.0  # the arc an interpolator travels from standing before the measured turn
INTERPOLATION_STEP_S = 1e-3  # the interpolator's cycle: a new command every 1 ms


def unit_vector(angle_deg, axis_index):
    """cos θ (first axis) or sin θ (second axis): how an error of that axis moves the radius."""
    theta = np.radians(angle_deg)
    return np.cos(theta) if axis_index == 0 else np.sin(theta)


def radial_um(angle_deg, axis_index, axis_error_um):
    """The radial deviation (µm) an error ``axis_error_um`` of one axis gives."""
    return unit_vector(angle_deg, axis_index) * axis_error_um


def radius_change_um(angle_deg, radius_mm, first_error_um, second_error_um):
    """The change (µm) of the radius when the axes' errors (µm) move the commanded point
    R(cos θ, sin θ) about the centre: exact, not first order as :func:`radial_um`."""
    theta = np.radians(angle_deg)
    radius_um = radius_mm * UM_PER_MM
    return (np.hypot(radius_um * np.cos(theta) + first_error_um,
                     radius_um * np.sin(theta) + second_error_um) - radius_um)


def axis_positions_mm(angle_deg, radius_mm, center_mm, axis_index):
    """The nominal position (mm, machine coordinates) of one axis at each angle."""
    theta = np.radians(angle_deg)
    along = np.cos(theta) if axis_index == 0 else np.sin(theta)
    return center_mm[axis_index] + radius_mm * along


@dataclass(frozen=True)
class CircleInterpolator:
    """The commanded path of a circular test in one direction.

    The axes stand at the start of the lead-in arc, ``lead_in_deg`` before ``start_deg``,
    then travel the circle at the programmed feed through the lead-in arc, one measured
    turn from ``start_deg`` and the lead-out arc, and stand at its end. ``direction`` +1 is
    counter-clockwise, -1 clockwise. The one definition of the commanded circle: the
    project's master calls it, and the CircleInterpolator FMU is an adapter over it.
    """

    radius_mm: float
    feed_mm_min: float
    center_mm: tuple
    direction: int = 1
    start_deg: float = 0.0
    lead_in_deg: float = LEAD_IN_DEG
    lead_out_deg: float = 45.0

    def __post_init__(self):
        for name in ("radius_mm", "feed_mm_min"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0):
                raise ValueError(f"{name} must be > 0, got {value!r}")
        for name in ("lead_in_deg", "lead_out_deg"):
            value = getattr(self, name)
            if not (math.isfinite(value) and 0 <= value <= 360):
                raise ValueError(f"{name} must be 0 to 360, got {value!r}")
        if not 0.0 < self.degrees_per_s < math.inf:
            raise ValueError(f"feed_mm_min / radius_mm = {self.feed_mm_min!r} / "
                             f"{self.radius_mm!r}: the angular speed must be finite and > 0")
        if self.direction not in (1, -1):
            raise ValueError(f"direction must be 1 (counter-clockwise) or -1 (clockwise), "
                             f"got {self.direction!r}")
        if not all(math.isfinite(value) for value in (*self.center_mm, self.start_deg)):
            raise ValueError(f"the centre and start angle must be finite, got "
                             f"{self.center_mm!r} and {self.start_deg!r}")

    @property
    def degrees_per_s(self):
        """Angular speed (deg/s) at the programmed feed."""
        return math.degrees(self.feed_mm_min / 60.0 / self.radius_mm)

    @property
    def measured_s(self):
        """(start, end) time (s) of the measured turn."""
        start = self.lead_in_deg / self.degrees_per_s
        return start, start + 360.0 / self.degrees_per_s

    @property
    def duration_s(self):
        """Time (s) from the start of the lead-in arc to the end of the lead-out arc."""
        return (self.lead_in_deg + 360.0 + self.lead_out_deg) / self.degrees_per_s

    def angle_deg(self, time_s):
        """Commanded angle (deg, unwrapped) at the times ``time_s``."""
        travelled = np.clip(np.asarray(time_s, float), 0.0, self.duration_s) * self.degrees_per_s
        return self.start_deg + self.direction * (travelled - self.lead_in_deg)

    def position_mm(self, time_s, axis_index):
        """Commanded position (mm) of the first (0) or second (1) axis."""
        return axis_positions_mm(self.angle_deg(time_s), self.radius_mm, self.center_mm,
                                 axis_index)


def axis_direction(angle_deg, direction, axis_index):
    """The sign of one axis's velocity (+1 moving in +, −1 in −) on the circle.

    v_x = −dir·sin θ, v_y = dir·cos θ (times R ω): in the half turn after each of its
    reversals (:func:`since_reversal_deg`) an axis moves in −, then in +. At a reversal
    point, where the velocity is zero, the sign is that of the motion after it.
    """
    return np.where(_turned_deg(angle_deg, direction, axis_index) < 180.0, -1.0, 1.0)


def _turned_deg(angle_deg, direction, axis_index):
    """Angle travelled (deg, 0 to 360) since the axis's reversal at θ = 0° (first axis) or
    90° (second), after which it moves in −."""
    start = 0.0 if axis_index == 0 else 90.0
    return np.mod(direction * (np.asarray(angle_deg, float) - start), 360.0)


def backlash_um(angle_deg, direction, axis_index, backlash_um_value, radius_mm=None,
                lag_deg=0.0):
    """Backlash B of one axis: e = ±B/2 by its direction of motion (ISO 230-2 reversal
    sign), a step of B in the radius at that axis's reversal points (θ = 0°, 180° for the
    first axis, 90°, 270° for the second).

    With ``radius_mm`` the nut crosses its play as the GeometricError FMU's does
    (:func:`feedaxis.physics.geometry.play_engagement`): after the reversal the axis has
    travelled R(1 − cos φ), φ the angle since, so the error runs from ∓B/2 to ±B/2 over
    the first R(1 − cos φ) = B of travel instead of stepping. ``lag_deg`` is how far the
    axis trails the commanded angle (its servo lag times the angular speed): the reversal
    shows that much later on the circle.
    """
    return backlash_shape(angle_deg, direction, axis_index, radius_mm)(backlash_um_value,
                                                                       lag_deg)


def backlash_shape(angle_deg, direction, axis_index, radius_mm=None):
    """``f(B, lag_deg) -> radial µm`` of :func:`backlash_um` at these samples, what does
    not depend on B and the lag computed once."""
    turned = direction * (np.asarray(angle_deg, float) - (0.0 if axis_index == 0 else 90.0))
    along = unit_vector(angle_deg, axis_index)

    def radial(backlash_um_value, lag_deg=0.0):
        since = np.mod(turned - lag_deg, 360.0)
        second_half = since >= 180.0
        engagement = np.where(second_half, 1.0, -1.0)
        if radius_mm is not None and backlash_um_value != 0.0:
            play = abs(backlash_um_value) / (radius_mm * UM_PER_MM)   # 1 - cos φ at the end
            phi_deg = since - 180.0 * second_half
            crossing = np.flatnonzero(phi_deg < np.degrees(np.arccos(max(1.0 - play, -1.0))))
            travel = 1.0 - np.cos(np.radians(phi_deg[crossing]))
            engagement[crossing] *= np.clip(2.0 * travel / play - 1.0, -1.0, 1.0)
        return along * (0.5 * backlash_um_value) * engagement

    return radial


def squareness_um(angle_deg, radius_mm, squareness_urad):
    """Out-of-squareness α of the second axis towards the first (the table moves α·y along
    the first axis as the second travels y): α·R/2·sin 2θ, the same in both directions."""
    return squareness_urad * 1e-6 * radius_mm * UM_PER_MM / 2 * np.sin(2 * np.radians(angle_deg))


def scale_mismatch_um(angle_deg, radius_mm, scale_first_um_per_mm, scale_second_um_per_mm):
    """Scale (lead) errors s_x, s_y of the two axes about the centre:
    R(s_x + s_y)/2 + R(s_x − s_y)/2·cos 2θ (a radius change and an ellipse along the axes)."""
    two = 2 * np.radians(angle_deg)
    return radius_mm * ((scale_first_um_per_mm + scale_second_um_per_mm) / 2
                        + (scale_first_um_per_mm - scale_second_um_per_mm) / 2 * np.cos(two))


def lag_mismatch_um(angle_deg, direction, feed_mm_s, lag_first_s, lag_second_s):
    """Each axis lagging its command by T_k (e_k = −v_k·T_k): F·(T_x − T_y)/2·sin 2θ times
    the direction, an ellipse at 45° that flips with the direction."""
    return (direction * feed_mm_s * (lag_first_s - lag_second_s) / 2 * UM_PER_MM
            * np.sin(2 * np.radians(angle_deg)))


def centring_um(angle_deg, offset_first_um, offset_second_um):
    """An instrument pivot off the path's centre by (a, b): a cos θ + b sin θ (first harmonic,
    the same in both directions)."""
    theta = np.radians(angle_deg)
    return offset_first_um * np.cos(theta) + offset_second_um * np.sin(theta)


def since_reversal_deg(angle_deg, direction, axis_index):
    """Angle travelled (deg, 0 to 180) since the last reversal of one axis: its reversals
    are at θ = 0°/180° (first axis) or 90°/270° (second)."""
    return np.mod(_turned_deg(angle_deg, direction, axis_index), 180.0)


def reversal_spike_um(angle_deg, direction, axis_index, height_um, decay_deg):
    """A reversal spike of one axis: after each reversal the axis sticks (friction) and
    trails its new motion by h·exp(−φ/φ0), φ the angle travelled since the reversal; on the
    radius a spike outwards of height h at the reversal point."""
    return reversal_spike_shape(angle_deg, direction, axis_index)(height_um, decay_deg)


def reversal_spike_shape(angle_deg, direction, axis_index):
    """``f(h, φ0) -> radial µm`` of :func:`reversal_spike_um` at these samples."""
    phi = since_reversal_deg(angle_deg, direction, axis_index)
    outward = -axis_direction(angle_deg, direction, axis_index) * unit_vector(angle_deg,
                                                                             axis_index)
    return lambda height_um, decay_deg: height_um * outward * np.exp(-phi / decay_deg)


def passes(direction):
    """(start, stop) index of each pass: the runs of samples of one direction."""
    direction = np.asarray(direction)
    edges = np.flatnonzero(np.diff(direction) != 0) + 1
    return list(zip(np.r_[0, edges], np.r_[edges, direction.size]))


def loop_error_um(params, angle_deg, direction, radius_mm, feed_mm_min, center_mm,
                  axis_index, lead_in_deg=LEAD_IN_DEG, step_s=INTERPOLATION_STEP_S):
    """The error (µm, position − command) of one axis's closed loop at each sample of a
    circular test, the loop simulated by :func:`feedaxis.physics.servo.simulate` (the kernel
    of the NpidServo FMU) under ``params`` (:class:`~feedaxis.physics.servo.ServoParams`).

    Each pass (a run of one direction) starts from standing ``lead_in_deg`` before its
    first sample's angle; the interpolator commands the circle at the feed every
    ``step_s`` (the loop ramps between commands), as the co-simulated machine's
    interpolator does. A sample's angle is the commanded angle at its instant (as a
    ballbar assigns it from the programmed feed).
    """
    angle_deg = np.asarray(angle_deg, float)
    error_um = np.empty_like(angle_deg)
    deg_per_s = np.degrees(feed_mm_min / 60.0 / radius_mm)
    for start, stop in passes(direction):
        way = float(direction[start])
        turned_deg = np.degrees(np.unwrap(np.radians(way * angle_deg[start:stop])))
        sample_s = (lead_in_deg + turned_deg - turned_deg[0]) / deg_per_s
        time_s = np.arange(int(np.ceil(sample_s.max() / step_s - 1e-9)) + 1) * step_s
        commanded_deg = angle_deg[start] + way * (time_s * deg_per_s - lead_in_deg)
        command_mm = axis_positions_mm(commanded_deg, radius_mm, center_mm, axis_index)
        position_mm = simulate(params, time_s, command_mm)
        with np.errstate(over="ignore", invalid="ignore"):  # a fit's trial loop may run away
            error_um[start:stop] = np.interp(sample_s, time_s,
                                             position_mm - command_mm) * UM_PER_MM
    return error_um


def servo_params(servo, values=None):
    """:class:`ServoParams` of an axis of a machine: its ``[servo]`` controller (as NpidServo
    parameters) on the machine's plant (:data:`MACHINE_PLANT`), then ``values``."""
    return ServoParams(**{**servo, **MACHINE_PLANT, **(values or {})})
