"""The report's plots read right (issue 21): the model is drawn between the targets, where a
short-period effect swings; no axes is empty, no legend is empty and matplotlib warns of
nothing; no tick label carries an offset; a period too short to read over the travel gets
a zoomed window; the ISO 230-2 plot says what it draws (± 2s bars only where runs repeat);
only resolvable wavelengths are marked; numbers are right-aligned, text is not."""
import re
import warnings

import numpy as np
import pytest

import feedaxis.report.plots as plots
import synthetic as syn
from feedaxis.analysis import analyse
from feedaxis.positioning_details import POINTS_PER_PERIOD
from feedaxis.case import read_case, write_case
from feedaxis.effects import CATALOG, Model
from feedaxis.examples import write_table2_case
from feedaxis.measurement import measurement_of
from feedaxis.physics import geometry
from feedaxis.report import write_report
from feedaxis.report.positioning import _positioning_contributions

LEAD = {"offset_um": 1.5, "slope_um_per_mm": -0.5}
ECCENTRICITY = {"cos_um": 100.0, "sin_um": -100.0}   # 141 µm, invisible at the targets
BACKLASH = {"backlash_um": 3.0}
FIFTY_TARGETS_MM = np.arange(0.0, 501.0, 50.0)      # multiples of the 10 mm lead


def fifty_case(folder, runs=3, both=True):
    """Targets every 50 mm on a 10 mm lead (every target at one phase of the lead), lead
    error, backlash and noise; ``runs`` per direction."""
    rng = np.random.default_rng(5)
    rows = []
    for run in range(1, runs + 1):
        for sign in ((1.0, -1.0) if both else (1.0,)):
            targets = FIFTY_TARGETS_MM if sign > 0 else FIFTY_TARGETS_MM[::-1]
            error = (geometry.lead_error_um(targets, **LEAD)
                     + geometry.backlash_error_um(sign, BACKLASH["backlash_um"] if both else 0.0)
                     + rng.normal(0.0, 0.4, targets.size))
            rows += [(t, e, sign, run) for t, e in zip(targets, error)]
    target, error, direction, run = (np.array(c) for c in zip(*rows))
    return read_case(write_case(folder, {"name": "fifty", "screw": {"lead_mm": 10.0}},
                                positioning={"target_mm": target, "error_um": error,
                                             "direction": direction, "run": run}))


class Drawn(list):
    """Records every figure the report draws, after it is drawn (``with Drawn() as drawn``)."""

    def __enter__(self):
        self.png = plots._png

        def record(figure):
            data = self.png(figure)
            self.append(figure)
            return data

        plots._png = record
        return self

    def __exit__(self, *exc):
        plots._png = self.png


@pytest.fixture
def drawn():
    with Drawn() as figures:
        yield figures


def report(analysis, tmp_path):
    """The page of ``analysis``, written with every warning an error."""
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        return write_report(analysis, tmp_path / "r.html").read_text(encoding="utf-8")


def titled(figures, title):
    return next(axes for figure in figures for axes in figure.axes
                if axes.get_title().startswith(title))


def plot_axes(figure):
    return [axes for axes in figure.axes if not hasattr(axes, "_colorbar")]


def assert_every_plot_reads(figures):
    assert figures
    for figure in figures:
        for axes in plot_axes(figure):
            name = axes.get_title() or figure.get_suptitle()
            assert axes.has_data(), f"empty axes: {name}"
            legend = axes.get_legend()
            assert legend is None or legend.get_texts(), f"empty legend: {name}"
            for axis in (axes.xaxis, axes.yaxis):
                assert axis.get_offset_text().get_text() == "", f"offset label: {name}"


@pytest.fixture(scope="module")
def eccentric(tmp_path_factory):
    """The fifty case with a model that puts ±141 µm between the targets: (analysis, its
    page, the figures drawn)."""
    folder = tmp_path_factory.mktemp("fifty")
    case = fifty_case(folder / "case")
    model = Model([CATALOG["lead_error"], CATALOG["assembly_eccentricity"], CATALOG["backlash"]],
                  {"lead_error": LEAD, "assembly_eccentricity": ECCENTRICITY,
                   "backlash": BACKLASH})
    analysis = analyse(case, model)
    with Drawn() as figures:
        page = report(analysis, folder)
    return analysis, page, figures


def test_the_model_is_drawn_densely_between_the_targets(eccentric):
    """The dense model is the physics at the points between the targets (an independent
    computation), swings ±141 µm between targets where the targets see none of it, and is
    what the plot draws."""
    eccentric, _, drawn = eccentric
    dense = eccentric.details.dense
    expected = (geometry.lead_error_um(dense.position_mm, **LEAD)
                + geometry.eccentricity_error_um(dense.position_mm, 10.0, **ECCENTRICITY)
                + geometry.backlash_error_um(dense.direction, BACKLASH["backlash_um"]))
    np.testing.assert_allclose(dense.predicted_um, expected, atol=1e-9)
    assert set(dense.direction) == {1.0, -1.0}
    swing = dense.predicted_um - expected + geometry.eccentricity_error_um(
        dense.position_mm, 10.0, **ECCENTRICITY)
    assert np.max(np.abs(swing)) == pytest.approx(np.hypot(100.0, 100.0), rel=0.01)
    assert np.ptp(eccentric.components["assembly_eccentricity"]) < 1e-9   # flat at targets
    assert np.ptp(dense.components["assembly_eccentricity"]) == pytest.approx(
        2 * np.hypot(100.0, 100.0), rel=0.01)
    axes = titled(drawn, "Measurement against model")
    model_lines = [line for line in axes.get_lines() if line.get_linestyle() == "-"]
    assert sum(line.get_xdata().size for line in model_lines) == dense.position_mm.size
    assert max(np.ptp(line.get_ydata()) for line in model_lines) > 250.0 + 2 * 141.0 - 10.0
    assert_every_plot_reads(drawn)


def test_wavelengths_the_targets_cannot_resolve_are_not_marked(eccentric):
    eccentric, page, drawn = eccentric
    details = eccentric.details
    assert "assembly_eccentricity" not in details.marks
    assert details.unresolved["assembly_eccentricity"] == measurement_of(
        eccentric.case, "positioning").unresolvable(CATALOG["assembly_eccentricity"])
    assert "10 mm" in details.unresolved["assembly_eccentricity"]
    assert "Not marked, the targets cannot resolve them: assembly_eccentricity" in page
    residual = titled(drawn, "Residual against position")
    assert [t.get_text() for t in residual.get_legend().get_texts()] == ["residual"]
    assert not any(line.get_xdata().size == 2 and line.get_xdata()[0] == line.get_xdata()[1]
                   for line in residual.get_lines())   # no period grid
    spectrum = titled(drawn, "Spatial spectrum")
    assert not any("eccentricity" in t.get_text() for t in spectrum.get_legend().get_texts())


def test_iso_plot_draws_bars_where_runs_repeat_and_the_line_taken_out(eccentric):
    eccentric, _, drawn = eccentric
    top = titled(drawn, "ISO 230-2 mean deviation")
    bottom = titled(drawn, "The same less the straight line")
    assert "bars x̄ ± 2s where the runs repeat" in top.get_title()
    assert top.containers and bottom.containers               # the ± 2s error bars
    offset_um, slope = eccentric.details.iso_line
    assert slope == pytest.approx(LEAD["slope_um_per_mm"], abs=0.01)
    assert offset_um == pytest.approx(LEAD["offset_um"], abs=1.0)
    less = np.concatenate([line.get_ydata() for line in bottom.get_lines()])
    assert np.ptp(less) < 10.0 < 200.0 < np.ptp(np.concatenate(
        [line.get_ydata() for line in top.get_lines()]))      # the 250 µm slope removed


def test_iso_plot_of_single_runs_says_it_has_no_band(tmp_path, drawn):
    details = analyse(fifty_case(tmp_path / "case", runs=1, both=False),
                      Model([CATALOG["lead_error"]], {"lead_error": LEAD})).details
    plots.iso230_deviation(details.iso_deviation, details.iso_line)
    top = titled(drawn, "ISO 230-2 mean deviation")
    assert "one run per target: no s, so no ± 2s band" in top.get_title()
    assert not top.containers
    assert_every_plot_reads(drawn)


def test_a_short_period_gets_a_zoomed_window_and_no_offset_label(tmp_path, drawn):
    """The motor ripple (0.02 mm over 5 mm: 250 periods) is drawn over three periods beside
    the travel; a contribution constant to 1e-12 µm reads as a constant."""
    case = read_case(syn.micro_case(tmp_path / "micro", syn.MICRO_TRUTH, seed=3))
    names = ("lead_error", "assembly_eccentricity", "motor_step_error")
    analysis = analyse(case, Model([CATALOG[n] for n in names], syn.MICRO_TRUTH))
    assert analysis.details.dense.windows == {"motor_step_error": pytest.approx((0.0, 0.06))}
    _positioning_contributions(analysis)   # the page's contributions plot
    contributions = next(f for f in drawn if f.get_suptitle() == "Each effect's contribution")
    zoom = next(a for a in contributions.axes if a.get_title(loc="left").startswith("zoomed"))
    x = zoom.get_lines()[0].get_xdata()
    y = zoom.get_lines()[0].get_ydata()
    assert x.min() == pytest.approx(0.0) and x.max() == pytest.approx(0.06, rel=1e-3)
    assert np.sum(np.diff(np.sign(y - y.mean())) != 0) in (5, 6, 7)   # three periods
    assert x.size >= 3 * POINTS_PER_PERIOD
    assert_every_plot_reads(drawn)


def test_a_constant_reads_without_an_offset_label(drawn):
    plots.contributions(np.linspace(0.0, 500.0, 11), {"near_constant": np.full(11, 0.7184124463)
                                                      + 1e-12 * np.arange(11)}, "position (mm)")
    assert_every_plot_reads(drawn)
    axes = drawn[0].axes[0]
    low, high = axes.get_ylim()
    assert high - low == pytest.approx(plots.MIN_SPAN_UM) and low < 0.7184124463 < high


def test_too_few_targets_give_no_empty_spectrum_and_no_warning(tmp_path, drawn):
    """Three targets of a thermal case: no spectrum (the page says why), no legend without
    entries, no matplotlib warning (the report is written with warnings as errors)."""
    case = read_case(write_table2_case(tmp_path / "t", 9000.0, stroke_mm=(0.0, 100.0)))
    page = report(analyse(case, Model()), tmp_path)
    assert "No spatial spectrum: a spatial spectrum needs at least 8 targets; the case has 3" \
        in page
    assert not any(a.get_title().startswith("Spatial spectrum") for f in drawn for a in f.axes)
    assert_every_plot_reads(drawn)


def test_numbers_are_right_aligned_and_text_is_not(eccentric):
    page = eccentric[1]
    cells = re.findall(r"<td( class=\"number\")?>([^<]*)</td>", page)
    right = [text for aligned, text in cells if aligned]
    left = [text for aligned, text in cells if not aligned]
    assert right and all(re.fullmatch(r"[-+]?[\d.]+(e[-+]?\d+)?( %)?", t) for t in right)
    assert any(len(t) > 30 for t in left)
    assert not any(re.fullmatch(r"[-+]?[\d.]+(e[-+]?\d+)?", t) for t in left)


def line_colour(line):
    from matplotlib.colors import to_hex
    return to_hex(line.get_color())


def test_every_panel_has_a_title_and_measured_dots_are_coloured_by_direction(eccentric):
    """Dots of each approach direction in that direction's colour, the model drawn over
    them; every panel of every figure titled."""
    from matplotlib.colors import to_hex

    _, _, drawn = eccentric
    axes = titled(drawn, "Measurement against model")
    dots = [line for line in axes.get_lines() if line.get_marker() == "."]
    model_lines = [line for line in axes.get_lines() if line.get_linestyle() == "-"]
    assert {line_colour(line) for line in dots} == {
        to_hex(plots.DIRECTION_COLOURS[1.0]), to_hex(plots.DIRECTION_COLOURS[-1.0])}
    assert min(line.get_zorder() for line in model_lines) > max(d.get_zorder() for d in dots)
    for figure in drawn:
        for panel in plot_axes(figure):
            assert panel.get_title() or figure.get_suptitle(), figure


def test_residual_against_direction_is_two_categories(eccentric):
    from matplotlib.colors import to_hex

    _, _, drawn = eccentric
    axes = titled(drawn, "Residual against approach direction")
    assert [tick.get_text() for tick in axes.get_xticklabels()] == ["− approach", "+ approach"]
    colours = {line_colour(line): set(line.get_xdata()) for line in axes.get_lines()}
    assert colours == {to_hex(plots.DIRECTION_COLOURS[1.0]): {1.0},
                       to_hex(plots.DIRECTION_COLOURS[-1.0]): {-1.0}}


def test_a_constant_ambient_draws_no_panel(tmp_path):
    from feedaxis.report.positioning import _residual_panels

    case = fifty_case(tmp_path / "case")
    still = case.positioning.__class__(**{**case.positioning.__dict__,
                                          "ambient_C": np.full(case.positioning.size, 20.4)})
    assert [label for label, _, _ in _residual_panels(still, still.error_um)] == [
        "approach direction"]
    moving = case.positioning.__class__(**{**case.positioning.__dict__, "ambient_C":
                                           np.linspace(20.0, 21.0, case.positioning.size)})
    assert "ambient (°C)" in [label for label, _, _ in _residual_panels(moving, moving.error_um)]


def test_the_spectrum_shows_both_lines_and_its_independent_wavelengths(eccentric):
    """The detrended measurement dashed over the residual; 11 targets: dots at span / k."""
    _, _, drawn = eccentric
    axes = titled(drawn, "Spatial spectrum")
    residual = next(line for line in axes.get_lines() if line.get_label() == "residual")
    measured = next(line for line in axes.get_lines()
                    if line.get_label() == "measured, trend removed")
    assert measured.get_zorder() > residual.get_zorder() and measured.get_linestyle() == "--"
    dots = [line for line in axes.get_lines() if line.get_marker() == "o"]
    low, high = axes.get_xlim()
    expected = [w for w in 500.0 / np.arange(1, 6) if low <= w <= high]
    assert dots and all(sorted(d.get_xdata()) == pytest.approx(sorted(expected)) for d in dots)
    assert "11 targets" in axes.get_title()
