"""Scenarios on the co-simulated axis that write measurement cases (docs/case-format.md).

Each kind of measurement declares its own (its ``scenarios`` part,
:func:`feedaxis.kinds.scenarios`): :mod:`.positioning` (``iso230``, ``thermal``) and
:mod:`.tracking` (``tracking``); :mod:`.base` holds what they share (the
:class:`~.base.Scenario`, the run, the noise, the case written). The library functions
are named here as well.
"""
from .base import (MeasurementNoise, Scenario, ScenarioInterrupted, ScenarioRun, Series,
                   check_axis_ranges, write_run)
from .positioning import (iso230_motion, iso230_targets, run_iso230, run_thermal,
                          simulate_iso230, simulate_thermal, thermal_motion)
from .tracking import cutting_force_N, run_tracking, simulate_tracking

__all__ = ["MeasurementNoise", "Scenario", "ScenarioInterrupted", "ScenarioRun", "Series",
           "check_axis_ranges", "cutting_force_N", "iso230_motion", "iso230_targets",
           "run_iso230", "run_thermal", "run_tracking", "simulate_iso230", "simulate_thermal",
           "simulate_tracking", "thermal_motion", "write_run"]
