"""The loop on servo tracking data (tracking.csv with the ``[servo]`` table of axis.toml).

The tracking effects (:mod:`feedaxis.effects.tracking`) change the parameters of one
closed-loop simulation (``feedaxis.physics.servo``, the NpidServo FMU's physics) instead of
adding errors; the
model predicts ``actual_mm`` from ``reference_mm`` (and ``disturbance_N``) and the residual
is actual - predicted in µm. Fit, diagnosis, comparison and report follow the positioning
loop's shape and JSON field names.
"""
