"""The plant of a drive identified from its own recorded input and output (inverse dynamics).

Where a drive records its controller output u (``control_V``), the plant of the loop,
ẍ + a1·ẋ + a0·x = b·(u(t − τ) + (F − F_c·sgn ẋ − c·ẋ) / K_F) (:mod:`.servo`; K_F the force
constant), is linear in its unknowns once divided by b:

    u(t − τ) = ẍ / b + (a1 / b + c / K_F)·ẋ + (a0 / b)·x + (F_c / K_F)·sgn ẋ − F / K_F

so one linear least squares on the recorded samples gives the gain b (the mass: K_F / b in
N per mm/s²), the damping (plant and viscous friction together: they enter alike), the
stiffness, the Coulomb friction and a constant force (Gautier & Khalil, "Direct calculation
of minimum set of inertial parameters of serial robots", IEEE Trans. Robotics and Automation
6 (1990); the standard inverse-dynamics identification). The derivatives come from the
position by central differences after the same zero-phase low-pass filter is applied to
every column and to u (a linear filter keeps the equation; it takes the encoder noise the
double difference would amplify). Samples near standstill are left out (``SLOW_SHARE``:
there the friction's sign flips within a sample, and a loop may stick and slip). The delay τ is the shift (in eighths of a sample, the input interpolated
linearly; up to ``MAX_DELAY_S``) that leaves the smallest residual. sgn ẋ is smoothed as in the loop.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .servo import FRICTION_SMOOTHING_MM_S
from .threads import one_blas_thread

MAX_DELAY_S = 0.01
# the filter's corner as a share of the sampling rate: a tenth keeps the motion of a
# closed position loop (tens of hertz at 1 kHz sampling) and takes the noise above
CORNER_SHARE = 0.1
# samples slower than this share of the record's top speed are left out: near a reversal the
# friction's sign changes within a sample and the loop may stick and slip, which no filtered
# regressor follows
SLOW_SHARE = 0.05
SHIFT_STEP = 0.125  # samples: the delay's resolution
COLUMNS = ("acceleration", "velocity", "position", "coulomb", "constant")


@dataclass(frozen=True)
class Identified:
    """The plant from a recorded controller output, with standard uncertainties.

    ``values`` and ``sigma`` are in the loop's parameter names (:class:`.servo.ServoParams`):
    ``plant_gain_mm_per_Vs2``, ``plant_damping_per_s`` (viscous friction included),
    ``plant_stiffness_per_s2``, ``delay_s``, ``friction_N`` (Coulomb) and ``force_N``.
    ``sigma`` rests on the residual as noise; an output recorded once per sample of a loop
    stepping several times within it leaves a model error beyond it (about 1 % on the
    friction in the tests), so these are a start, sized by the closed-loop fit.
    """

    values: dict
    sigma: dict
    residual_rms_V: float
    samples: int


def _lowpass(columns, step_s):
    """Every column filtered forward and backward by a second-order Butterworth low-pass at
    ``CORNER_SHARE`` of the sampling rate (zero phase)."""
    from scipy.signal import butter, sosfiltfilt

    sos = butter(2, 2.0 * CORNER_SHARE, output="sos")
    return sosfiltfilt(sos, columns, axis=0)


def regressors(time_s, actual_mm):
    """(step_s, the inverse-dynamics columns ẍ, ẋ, x − mean, sgn ẋ, 1) of an evenly sampled
    record, from the position filtered at ``CORNER_SHARE`` of the sampling rate."""
    step_s = float(np.median(np.diff(time_s)))
    position = np.asarray(actual_mm, dtype=float) - float(np.mean(actual_mm))
    velocity = np.gradient(position, step_s)
    # the friction's sign from the unfiltered velocity, then filtered like the rest:
    # filtering sgn(v) is not sgn of the filtered v, and the equation holds for the former
    coulomb = np.clip(velocity / FRICTION_SMOOTHING_MM_S, -1.0, 1.0)
    position, velocity, coulomb = _lowpass(np.column_stack((position, velocity, coulomb)),
                                           step_s).T
    acceleration = np.gradient(velocity, step_s)
    return step_s, np.column_stack((acceleration, velocity, position, coulomb,
                                    np.ones_like(position)))


@one_blas_thread
def identify_plant(time_s, actual_mm, control_V, force_constant_N_per_V, disturbance_N=None):
    """The plant, friction and constant force from the recorded ``control_V`` (inverse
    dynamics, see the module), or None when the record cannot fix them (too short, no
    motion, a singular regression).

    ``disturbance_N`` (a known force) is moved to the input side. The edges (one filter
    length at each end) are left out; the standard uncertainties are those of least squares
    widened by the residual's integrated autocorrelation time.
    """
    time_s = np.asarray(time_s, dtype=float)
    if time_s.size < 50:
        return None
    step_s, columns = regressors(time_s, actual_mm)
    drive_V = np.asarray(control_V, dtype=float)
    if disturbance_N is not None:
        drive_V = drive_V + np.asarray(disturbance_N, dtype=float) / force_constant_N_per_V
    drive_V = _lowpass(drive_V, step_s)
    edge = int(np.ceil(4.0 / CORNER_SHARE))
    max_shift = min(int(MAX_DELAY_S / step_s), time_s.size // 4 - 1)
    start, stop = edge + max_shift + 1, time_s.size - edge
    if stop - start < 20:
        return None
    speed = np.abs(columns[start:stop, 1])
    weight = (speed >= SLOW_SHARE * speed.max()).astype(float) if speed.max() > 0 else \
        np.zeros_like(speed)
    if weight.sum() < 20:
        return None
    kept = columns[start:stop] * weight[:, None]  # slow rows zeroed: left out
    gram = kept.T @ kept
    if np.linalg.matrix_rank(gram) < kept.shape[1]:
        return None

    def regression(shift):
        """(rss, shift, coefficients) of u(t − shift samples) on the columns."""
        whole = int(np.floor(shift))
        fraction = shift - whole
        target = ((1.0 - fraction) * drive_V[start - whole:stop - whole]
                  + fraction * drive_V[start - whole - 1:stop - whole - 1])
        moment = kept.T @ target
        coefficients = np.linalg.solve(gram, moment)
        return float((target * weight) @ target - coefficients @ moment), shift, coefficients

    # whole samples first, then eighths of a sample around the best (the output is recorded
    # once per sample, the loop steps several times within it: u(t − τ) is interpolated)
    best = min(regression(float(shift)) for shift in range(max_shift + 1))
    around = np.arange(max(best[1] - 1.0, 0.0), min(best[1] + 1.0, max_shift) + 1e-9,
                       SHIFT_STEP)
    best = min([best, *(regression(float(shift)) for shift in around)],
               key=lambda item: item[0])
    if best[2][0] <= 0.0:
        return None
    rss, shift, coefficients = best
    whole, fraction = int(np.floor(shift)), shift - np.floor(shift)
    target = ((1.0 - fraction) * drive_V[start - whole:stop - whole]
              + fraction * drive_V[start - whole - 1:stop - whole - 1])
    residual = (target - columns[start:stop] @ coefficients)[weight > 0]
    return _identified((rss, shift, coefficients, residual), columns[start:stop][weight > 0],
                       step_s, force_constant_N_per_V)


def _identified(best, columns, step_s, force_constant_N_per_V):
    """:class:`Identified` from the best regression (rss, shift, coefficients, residual)."""
    from ..stats.coloured import autocorrelation_time

    rss, shift, (inertia, damping, stiffness, coulomb, constant), residual = best
    n, k = columns.shape
    # τ from the first 2^14 samples: the FFT of a long prime-sized record costs more than the
    # whole regression
    variance = rss / max(n - k, 1) * autocorrelation_time(residual[:2**14])
    covariance = variance * np.linalg.inv(columns.T @ columns)
    error = np.sqrt(np.diag(covariance))
    gain = 1.0 / inertia
    values = {"plant_gain_mm_per_Vs2": gain, "plant_damping_per_s": damping * gain,
              "plant_stiffness_per_s2": stiffness * gain, "delay_s": float(shift) * step_s,
              "friction_N": coulomb * force_constant_N_per_V,
              "force_N": -constant * force_constant_N_per_V}
    relative = error[0] / inertia
    sigma = {"plant_gain_mm_per_Vs2": gain * relative,
             "plant_damping_per_s": abs(damping * gain) * np.hypot(error[1] / damping, relative)
             if damping != 0.0 else error[1] * gain,
             "plant_stiffness_per_s2": error[2] * gain, "delay_s": SHIFT_STEP * step_s / np.sqrt(12.0),
             "friction_N": error[3] * force_constant_N_per_V,
             "force_N": error[4] * force_constant_N_per_V}
    return Identified(values, {key: float(value) for key, value in sigma.items()},
                      float(np.sqrt(rss / n)), n)


# the plant gains the closed-loop search tries (mm/(V·s²)), a quarter decade apart: from a
# heavy table on a weak amplifier to the small one of Anang et al. 2017, and beyond
SEARCH_GAINS = np.logspace(-1.0, 7.0, 33)
SEARCH_DAMPINGS = (0.0, 30.0, 300.0)  # 1/s
SEARCH_SPAN_S = 5.0  # the search runs on the record's first seconds


@one_blas_thread
def loop_start(params, time_s, reference_mm, actual_mm, disturbance_N=None, skip_s=0.2):
    """The plant (``plant_gain_mm_per_Vs2``, ``plant_damping_per_s``,
    ``plant_stiffness_per_s2`` 0, ``delay_s`` 0) under which ``params``' controller,
    simulated from the reference, follows ``actual_mm`` best, or None when no plant on the
    grid makes a stable loop.

    A search over :data:`SEARCH_GAINS` x :data:`SEARCH_DAMPINGS` on the first
    :data:`SEARCH_SPAN_S` of the record (samples after ``skip_s`` compared), the best gain
    then refined within its neighbours by a golden-section search on its logarithm: a start
    for the closed-loop fit from the record alone, where no controller output is recorded.
    """
    from dataclasses import replace

    from .servo import MAX_POSITION_MM, simulate, step_counts

    time_s = np.asarray(time_s, dtype=float)
    stop = max(int(np.searchsorted(time_s, time_s[0] + SEARCH_SPAN_S)), min(time_s.size, 50))
    time_s, reference_mm = time_s[:stop], np.asarray(reference_mm, dtype=float)[:stop]
    actual_mm = np.asarray(actual_mm, dtype=float)[:stop]
    force = None if disturbance_N is None else np.asarray(disturbance_N, dtype=float)[:stop]
    compared = time_s >= time_s[0] + skip_s
    if compared.sum() < 10:
        compared[:] = True
    counts = step_counts(time_s, params.time_step_s)

    def misfit(gain, damping):
        trial = replace(params, plant_gain_mm_per_Vs2=float(gain),
                        plant_damping_per_s=float(damping), plant_stiffness_per_s2=0.0,
                        delay_s=0.0)
        with np.errstate(all="ignore"):
            position_mm = simulate(trial, time_s, reference_mm, force, counts)
        if not np.all(np.abs(position_mm) <= MAX_POSITION_MM):
            return np.inf
        return float(np.mean((position_mm - actual_mm)[compared] ** 2))

    scores = np.array([[misfit(g, d) for d in SEARCH_DAMPINGS] for g in SEARCH_GAINS])
    if not np.isfinite(scores).any():
        return None
    i, j = np.unravel_index(np.argmin(scores), scores.shape)
    damping = SEARCH_DAMPINGS[j]
    low = np.log(SEARCH_GAINS[max(i - 1, 0)])
    high = np.log(SEARCH_GAINS[min(i + 1, SEARCH_GAINS.size - 1)])
    best_log = _golden(lambda log_gain: misfit(np.exp(log_gain), damping), low, high,
                       np.log(SEARCH_GAINS[i]), scores[i, j])
    return {"plant_gain_mm_per_Vs2": float(np.exp(best_log)),
            "plant_damping_per_s": float(damping), "plant_stiffness_per_s2": 0.0,
            "delay_s": 0.0}


def _golden(function, low, high, best_x, best_value, iterations=12):
    """The best x of ``function`` found by a golden-section search on [low, high], or
    ``best_x`` when none beats ``best_value``."""
    ratio = (np.sqrt(5.0) - 1.0) / 2.0
    a, b = low, high
    c, d = b - ratio * (b - a), a + ratio * (b - a)
    fc, fd = function(c), function(d)
    for _ in range(iterations):
        if fc < fd:
            b, d, fd = d, c, fc
            c = b - ratio * (b - a)
            fc = function(c)
        else:
            a, c, fc = c, d, fd
            d = a + ratio * (b - a)
            fd = function(d)
    for x, value in ((c, fc), (d, fd)):
        if value < best_value:
            best_x, best_value = x, value
    return best_x
