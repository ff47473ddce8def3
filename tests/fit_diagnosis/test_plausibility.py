"""Plausibility (issue 33): a readable case whose values no machine axis gives is read with a
warning naming the likely unit slip, never refused; a plausible case reads silently."""
import warnings

import numpy as np
import pytest

from feedaxis.case import read_case, write_case
from feedaxis.effects import CATALOG, Model
from feedaxis.plausibility import (ImplausibleWarning, MAX_FRICTION_N, positioning_problems,
                                   replicate_scatter_um, tracking_problems,
                                   warn_implausible_fit)

TARGETS_MM = np.repeat(np.linspace(0.0, 500.0, 11), 3)
DIRECTION = np.tile([1.0, -1.0, 1.0], 11)


def deviations_um(seed=1):
    rng = np.random.default_rng(seed)
    return -0.02 * TARGETS_MM + 1.5 * DIRECTION + rng.normal(0.0, 0.4, TARGETS_MM.size)


def read_warnings(folder, target_mm, error_um):
    write_case(folder, {"name": "p", "screw": {"lead_mm": 10.0}},
               positioning={"target_mm": target_mm, "error_um": error_um,
                            "direction": DIRECTION, "run": np.ones_like(DIRECTION)})
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        read_case(folder)
    return [str(w.message) for w in caught if w.category is ImplausibleWarning]


def test_the_replicate_scatter_is_the_pooled_standard_deviation():
    """Two groups of two: deviations ±1 about their means, 2 degrees of freedom: 1."""
    scatter = replicate_scatter_um(np.array([0.0, 0.0, 5.0, 5.0]), np.ones(4),
                                   np.array([1.0, 3.0, -1.0, 1.0]))
    assert scatter == pytest.approx(np.sqrt(4.0 / 2))


def test_a_plausible_test_reads_without_a_warning(tmp_path):
    assert read_warnings(tmp_path / "ok", TARGETS_MM, deviations_um()) == []


def test_deviations_in_mm_are_named(tmp_path):
    found = read_warnings(tmp_path / "mm", TARGETS_MM, deviations_um() / 1e3)
    assert len(found) == 1 and "error_um in mm?" in found[0] and "nm between repeats" in found[0]


def test_targets_in_m_are_named(tmp_path):
    found = read_warnings(tmp_path / "m", TARGETS_MM / 1e3, deviations_um())
    assert len(found) == 1 and "target_mm in m?" in found[0] and "10 mm lead" in found[0]


def test_a_tracking_trace_in_micrometres_is_named():
    time_s = np.arange(0.0, 2.0, 1e-3)
    reference_mm = 10.0 * np.sin(2 * np.pi * 0.4 * time_s)
    assert tracking_problems(reference_mm) == []
    assert "positions in µm?" in tracking_problems(reference_mm * 1e3)[0]


def test_a_fitted_friction_beyond_any_drive_is_named():
    model = Model([CATALOG["coulomb_friction"]], {"coulomb_friction": {"friction_N": 20.0}})
    assert warn_implausible_fit(model) == []
    heavy = Model([CATALOG["coulomb_friction"]],
                  {"coulomb_friction": {"friction_N": 2 * MAX_FRICTION_N}})
    with pytest.warns(ImplausibleWarning, match="beyond any feed drive"):
        assert warn_implausible_fit(heavy)


def test_a_single_pass_without_repeats_uses_the_size_of_the_deviations():
    target_mm = np.linspace(0.0, 500.0, 11)
    assert positioning_problems(target_mm, np.ones(11), np.full(11, 4e-4), 10.0)
    assert not positioning_problems(target_mm, np.ones(11), np.full(11, 0.4), 10.0)
