"""The tracking views of the report: the tracking error figures of Anang et al. 2017, the
deviation against time and velocity, the residual's spectrum."""
from __future__ import annotations

from . import plots
from .page import image, sample_contributions, table


def _tracking_views(analysis):
    """The tracking error figures of Anang et al. 2017 (in µm, as the plots), what the
    reference is, the deviation against time (the residual in a panel of its own) and
    velocity, the spectrum."""
    measurement, result, details = analysis.measurement, analysis.result, analysis.details
    comparison = analysis.comparison
    maximum, rms = comparison["max_tracking_error_mm"], comparison["rms_tracking_error_mm"]
    frequency_hz, amplitude_um = details.residual_spectrum
    return [
        "<h2>Tracking error</h2>",
        table(("after the first second", "measured (µm)", "predicted (µm)"),
              [(name, f"{1e3 * figure['measured']:.4g}", f"{1e3 * figure['predicted']:.4g}")
               for name, figure in (("max tracking error", maximum),
                                    ("RMS tracking error", rms))]),
        f"<p>The reference: {measurement.reference_kind()}.</p>",
        image(plots.error_against_time(measurement.time_s, result.measured_um,
                                       result.measured_um - result.residual_um,
                                       details.reversals_s, measurement.reference_kind()),
              "tracking deviation against time, and the residual below it"),
        image(plots.error_against_velocity(details.velocity_mm_s, result.measured_um,
                                           result.residual_um),
              "tracking deviation against velocity"),
        "<h2>Residual spectrum</h2>",
        image(plots.frequency_spectrum(frequency_hz, amplitude_um,
                                       analysis.diagnosis.unexplained), "residual spectrum"),
    ]


# the page's views, figures (none beyond the views') and contributions plot of a tracking
# analysis
VIEWS = (_tracking_views, lambda analysis: [], sample_contributions)
