"""One analysis, computed once: the report only formats it, and the demo's loop gives the
same analysis as computing it afresh."""
import pytest

import feedaxis.analysis
import feedaxis.diagnose
import feedaxis.fit
import feedaxis.kinds
import feedaxis.measurement
import feedaxis.physics.servo
import feedaxis.positioning_details
import feedaxis.tracking_details
from feedaxis.analysis import analyse, error_ladder
from feedaxis.case import read_case
from feedaxis.demo import improve, ladder_of
from feedaxis.effects import Model
from feedaxis.examples import BUNDLED_CASE
from feedaxis.report import write_report


@pytest.fixture(scope="module")
def loop():
    case = read_case(BUNDLED_CASE)
    model, rounds, diagnosis = improve(case, Model(), echo=lambda line: None)
    return case, model, rounds, diagnosis


def test_the_demo_ladder_is_the_refitted_ladder(loop):
    case, model, rounds, _ = loop
    from_loop, refitted = ladder_of(rounds), error_ladder(case, model)
    assert [label for label, _ in from_loop] == [label for label, _ in refitted]
    assert [rms for _, rms in from_loop] == pytest.approx([rms for _, rms in refitted], rel=1e-4)


def test_the_demo_diagnosis_is_the_fresh_one(loop):
    case, model, rounds, diagnosis = loop
    fresh = analyse(case, model)
    assert fresh.diagnosis.to_json() == diagnosis.to_json()


@pytest.fixture(scope="module")
def tracking_analysis(tmp_path_factory):
    from feedaxis.effects import CATALOG
    from tracking_synthetic import step_loop, two_sines, write_tracking_case

    folder = write_tracking_case(tmp_path_factory.mktemp("t") / "c",
                                 step_loop(two_sines, 2.0, friction_N=1.0), 1)
    case = read_case(folder)
    return analyse(case, feedaxis.fit.fit(Model([CATALOG["coulomb_friction"]]), case).model)


@pytest.mark.parametrize("kind", ["positioning", "tracking"])
def test_the_report_computes_nothing(kind, loop, tracking_analysis, tmp_path, monkeypatch):
    """The page formats an Analysis of either kind: every fit, diagnosis, prediction,
    spectrum and figure refused, it still writes, with a number only the analysis holds."""
    if kind == "positioning":
        case, model, rounds, diagnosis = loop
        analysis = analyse(case, model, diagnosis=diagnosis, ladder=ladder_of(rounds))
    else:
        analysis = tracking_analysis
    label = analysis.ladder[0][0]
    analysis.ladder = [(label, 123.456), *analysis.ladder[1:]]   # a number only it holds

    def refuse(*args, **kwargs):
        raise AssertionError("the report computed")

    for module, name in [(feedaxis.fit, "fit"), (feedaxis.fit, "evaluate"),
                         (feedaxis.diagnose, "diagnose"), (feedaxis.analysis, "fit"),
                         (feedaxis.analysis, "diagnose"), (feedaxis.analysis, "compare"),
                         (feedaxis.positioning_details, "compensate"),
                         (feedaxis.positioning_details, "verify"),
                         (feedaxis.tracking_details, "periodogram"),
                         (feedaxis.positioning_details, "residual_spectrum"),
                         (feedaxis.physics.servo, "simulate")]:
        monkeypatch.setattr(module, name, refuse)
    for measurement in feedaxis.kinds.kinds().values():
        for name in ("predictor", "separable", "components", "figures", "core"):
            monkeypatch.setattr(measurement, name, refuse)
    page = write_report(analysis, tmp_path / "r.html").read_text(encoding="utf-8")
    assert "123.5" in page


def test_a_thermal_case_is_drawn_run_by_run(tmp_path):
    """In a time-dependent case each sample's run is its visit number at its target, so the
    model lines of the report join only samples of one run."""
    import numpy as np

    from feedaxis.effects import CATALOG
    from feedaxis.examples import write_table2_case

    case = read_case(write_table2_case(tmp_path / "t", 9000.0))
    from feedaxis.fit import fit

    analysis = analyse(case, fit(Model([CATALOG["lead_error"]]), case).model)
    runs, target_mm = analysis.details.run_of_sample, case.positioning.target_mm
    for number in np.unique(runs):
        chosen = runs == number
        assert np.unique(target_mm[chosen]).size == chosen.sum()   # each target once a run
    assert runs.max() >= 20                     # the 28 passes of the Table 2 test
    assert analyse(read_case(BUNDLED_CASE), Model()).details.run_of_sample is None


def test_compare_names_its_steps_and_gives_the_same_figures(loop):
    """compare's progress (the CLI's bar) is told each step; the figures do not change."""
    from feedaxis.analysis import compare

    case, model, _, _ = loop
    steps = []
    assert compare(case, model, progress=steps.append) == compare(case, model)
    assert steps == ["model", "figures"]
