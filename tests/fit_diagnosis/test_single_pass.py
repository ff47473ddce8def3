"""One + and one - pass per target (issue 33): the shapes of real acceptance tests, from
known parameters (tests/synthetic.py SINGLE_PASS_FAMILIES). A trend of -16.9 µm over the
travel against a pair scatter of 4.1 µm is named as the lead error, with its size; white
nulls on which an AR model of the mirrored pairs named structure name nothing; slow noise
in time leaves the verdict undetermined, with the reason; a reversal changing along the
travel is not taken for noise; a single run each way imported from a Renishaw .rtl is read
as pairs. False-alarm rates and power over 200 cases per family:
benchmarks/bench_single_pass.py (docs/diagnosis.md)."""
import json

import numpy as np
import pytest

import synthetic as syn
from feedaxis.cli import main
from feedaxis.diagnose import diagnose
from feedaxis.effects import Model
from feedaxis.importers.rtl import rtl_text
from feedaxis.measurement import measurement_of
from feedaxis.stats.noise import PureError, SerialPairs

TREND_UM = -16.9
TRAVEL_MM = 600.0


def single_pass(family, seed):
    return syn.single_pass_trial(np.random.default_rng(seed), **syn.SINGLE_PASS_FAMILIES[family])


def named_trend_um(found):
    """(change of the named lead error over the travel, its standard error) (µm)."""
    lead = next(c for c in found.candidates if c.effect == "lead_error")
    slope, error, _ = lead.sizes()["slope_um_per_mm"]
    return slope * TRAVEL_MM, error * TRAVEL_MM


@pytest.mark.parametrize("family, seed", [
    ("trend, 11 unequal targets", 2), ("trend, 11 unequal targets", 3),
    ("trend + bow, reversal changing 8 µm", 0), ("trend + bow, reversal changing 8 µm", 2),
    ("trend + bow, 17 unequal, t(3), zero at 12 µm", 0),
    ("trend, reversal changing 12 µm, 21 targets", 1)])
def test_a_trend_the_pairs_show_is_named_as_the_lead_error(family, seed):
    """The trend stands against the pairs' scatter (F test, the pure error's degrees of
    freedom all kept: the lead error is constant at a target); its size within three
    standard errors of the truth."""
    found = diagnose(single_pass(family, seed), Model())
    assert found.candidates[0].effect == "lead_error"
    change_um, error_um = named_trend_um(found)
    assert abs(change_um - TREND_UM) < 3 * error_um
    assert "+ and - readings" in found.noise_source


@pytest.mark.parametrize("family, seed", [
    ("null, white, 15 targets", 20), ("null, white, 15 targets", 33),
    ("null, white, 21 targets", 4), ("null, white, 21 targets", 41),
    ("null, white, 21 targets", 44), ("null, white, 21 targets", 54)])
def test_white_nulls_the_mirrored_pairs_misjudged_name_no_shape(family, seed):
    """These nulls named a reversal changing along the travel, a periodic error or a trend
    when an AR model was fitted to the noise part in the order taken (each half-difference
    twice, mirrored about the turn): now no shape and no effect but a backlash."""
    found = diagnose(single_pass(family, seed), Model())
    assert {c.effect for c in found.candidates} <= {"backlash"}
    assert found.unexplained == []


def test_the_pairs_are_the_noise_model_of_one_pass_each_way():
    measurement = measurement_of(single_pass("null, white, 21 targets", 0), "positioning")
    assert isinstance(measurement.noise, SerialPairs)
    assert isinstance(measurement.replicates, PureError) and measurement.replicates.paired
    assert measurement.replicates.dof == 21 - 1  # 42 readings, 21 targets, a reversal


def test_the_means_and_half_differences_along_the_travel():
    """Hand-worked: targets listed out of order, the pairs' means and half-differences
    come back in travel order."""
    pairs = PureError(np.array([1, 0, 2, 2, 0, 1]),
                      within=np.array([1.0, 1, 1, -1, -1, -1]), paired=True)
    noise = SerialPairs(pairs, np.array([1.0, 1, 1, -1, -1, -1]), np.array([0, 1, 2]))
    means, halves = noise._halves(np.array([2.0, 4, 6, 1, 0, 3]))
    np.testing.assert_allclose(means, [2.0, 2.5, 3.5])
    np.testing.assert_allclose(halves, [2.0, -0.5, 2.5])


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_slow_noise_leaves_one_pass_undetermined_and_says_why(seed):
    """AR(1) noise with ρ = 0.8 in the order taken, no trend: the half-differences are
    correlated along the travel; nothing is named and the verdict says one pass cannot
    tell slow noise from an irregular error."""
    found = diagnose(single_pass("null, AR(1) 0.8 in time, 21 targets", seed), Model())
    assert found.candidates == [] and found.unexplained == []
    assert found.verdict == "undetermined"
    assert "half-differences are serially correlated along the travel" in \
        found.undetermined_reason
    assert "serially correlated along the travel" in found.noise_source


def test_a_reversal_changing_along_the_travel_is_not_taken_for_noise():
    """A reversal changing 12 µm over the travel: the pairs are read about a reversal linear
    along the travel (the constant one would leave the change in the noise), and the
    diagnosis describes the change."""
    case = single_pass("trend, reversal changing 12 µm, 21 targets", 1)
    measurement = measurement_of(case, "positioning")
    assert "linear along the travel" in measurement.replicates.source
    found = diagnose(case, Model())
    assert found.candidates[0].effect == "lead_error"


def test_a_single_run_each_way_from_a_renishaw_rtl(tmp_path, capsys):
    """One + and one - run in an .rtl, imported: diagnose names the lead error against the
    pairs' scatter, in JSON."""
    case = single_pass("trend + bow, reversal changing 8 µm", 0)
    p = case.positioning
    n = p.target_mm.size // 2
    targets = p.target_mm[:n]
    runs = [(1, p.error_um[:n]), (-1, p.error_um[n:][::-1])]
    (tmp_path / "x.rtl").write_text(rtl_text(targets, runs, {"Axis": "X"}))
    (tmp_path / "axis.toml").write_text('name = "acceptance"\n[screw]\nlead_mm = 10.0\n')
    assert main(["import", str(tmp_path / "x.rtl"), "--axis", str(tmp_path / "axis.toml"),
                 "--out", str(tmp_path / "case")]) == 0
    capsys.readouterr()
    assert main(["diagnose", str(tmp_path / "case"), "--json"]) == 0
    diagnosis = json.loads(capsys.readouterr().out)
    assert diagnosis["candidates"][0]["effect"] == "lead_error"
    assert "+ and - readings" in diagnosis["noise_source"]
    slope = diagnosis["candidates"][0]["parameters"]["slope_um_per_mm"]
    assert abs(slope["value"] * TRAVEL_MM - TREND_UM) < 3 * slope["standard_error"] * TRAVEL_MM
