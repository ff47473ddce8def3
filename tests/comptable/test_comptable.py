"""feedaxis comp-table: each controller's vendor example and limits, and a round trip: the
written file, read back as the controller applies it, removes a known lead error,
eccentricity and backlash between the targets of a generated case."""
import json

import numpy as np
import pytest

from feedaxis.case import read_case, write_case
from feedaxis.measurement.positioning import PositioningSamples as Positioning
from feedaxis.cli import main
import synthetic as syn
from feedaxis.comptable import CONTROLLERS, build_table, from_model, grid_mm, verify
from feedaxis.comptable import beckhoff, fanuc, heidenhain, linuxcnc, siemens
from feedaxis.linefile import LineError
from feedaxis.comptable.table import CompTable
from feedaxis.comptable.verify import ALPHA, systematic_test
from feedaxis.effects import CATALOG, Model
from feedaxis.errors import InputError
from feedaxis.physics import geometry

LEAD_MM = 10.0
TRUTH = {"offset_um": 2.0, "slope_um_per_mm": -0.02, "cos_um": 1.5, "sin_um": -1.0,
         "backlash_um": 4.0}
NOISE_UM = 0.2


def true_error_um(position_mm, direction):
    return (geometry.lead_error_um(position_mm, TRUTH["offset_um"], TRUTH["slope_um_per_mm"])
            + geometry.eccentricity_error_um(position_mm, LEAD_MM, TRUTH["cos_um"],
                                             TRUTH["sin_um"])
            + geometry.backlash_error_um(direction, TRUTH["backlash_um"]))


def generated_case(folder, seed=1, cycles=3):
    """81 targets about 4.9 mm apart over 400 mm (under half the lead, so they resolve the
    once-per-revolution eccentricity), bidirectional."""
    rng = np.random.default_rng(seed)
    targets = np.round(np.arange(81) * 4.9 + rng.uniform(0.0, 0.5, 81), 3)
    rows = []
    for run in range(1, cycles + 1):
        rows += [(t, 1.0, run) for t in targets] + [(t, -1.0, run) for t in targets[::-1]]
    target_mm, direction, run = (np.array(column) for column in zip(*rows))
    error_um = true_error_um(target_mm, direction) + rng.normal(0.0, NOISE_UM, target_mm.size)
    return write_case(folder, {"name": "generated", "screw": {"lead_mm": LEAD_MM}},
                      positioning={"target_mm": target_mm, "error_um": error_um,
                                   "direction": direction, "run": run})


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    folder = generated_case(tmp_path_factory.mktemp("comp") / "case")
    model = folder.parent / "model.toml"
    assert main(["fit", str(folder), "--add", "lead_error", "--add", "assembly_eccentricity",
                 "--add", "backlash", "--out", str(model)]) == 0
    return folder, model


def left_between_targets(case, applied):
    """Systematic deviation (peak to valley over both directions, µm) of the true error on a
    dense grid between the first and last target, before and after the table."""
    target_mm = case.positioning.target_mm
    dense_mm = np.linspace(target_mm.min(), target_mm.max(), 8001)
    before = np.concatenate([true_error_um(dense_mm, d) for d in (1.0, -1.0)])
    after = np.concatenate([true_error_um(dense_mm, d) - applied.error_um(dense_mm, d)
                            for d in (1.0, -1.0)])
    return float(np.ptp(before)), float(np.ptp(after))


def run_comp_table(tmp_path, folder, *options):
    out = tmp_path / "table.COM"   # the ending Heidenhain's control needs; the others take any
    code = main(["comp-table", str(folder), "--out", str(out), "--json", *options])
    return code, out


@pytest.mark.parametrize("controller", sorted(CONTROLLERS))
def test_round_trip_removes_lead_eccentricity_and_backlash_between_targets(
        tmp_path, fitted, capsys, controller):
    folder, model = fitted
    code, out = run_comp_table(tmp_path, folder, "--model", str(model), "--controller",
                               controller)
    report = json.loads(capsys.readouterr().out)
    assert code == 0
    applied = CONTROLLERS[controller].read(out.read_text())
    case = read_case(folder)
    before_um, after_um = left_between_targets(case, applied)
    assert after_um <= 0.2 * before_um, (before_um, after_um)
    assert report["included"] == ["lead_error", "assembly_eccentricity", "backlash"]
    assert report["direction_dependent"]
    assert report["excluded"] == {}  # nothing left out, no effect named that the model lacks
    figures = report["figures"]
    assert figures["E_um"]["after_um"] < 0.2 * figures["E_um"]["before_um"]
    # a table held in whole detection units (Fanuc: 1 µm) may leave one unit of reversal
    quantum_um = CONTROLLERS[controller].quantum_um
    assert figures["B_um"]["after_um"] < 0.2 * figures["B_um"]["before_um"] + quantum_um
    assert not report["warnings"]
    between = report["between_targets"]  # the fitted model's view, close to the truth's
    assert between["pv_before_um"] == pytest.approx(before_um, rel=0.05)
    assert between["pv_after_um"] <= 0.2 * between["pv_before_um"]


def test_the_measured_means_leave_the_eccentricity_between_targets(tmp_path, fitted, capsys):
    folder, model = fitted
    case = read_case(folder)
    left = {}
    for options in ((), ("--from-measurement",)):
        code, out = run_comp_table(tmp_path, folder, "--model", str(model), "--controller",
                                   "linuxcnc", *options)
        assert code == 0
        report = json.loads(capsys.readouterr().out)
        left[options] = left_between_targets(case, linuxcnc.read(out.read_text()))[1]
    assert report["source"] == "measurement" and report["points"] == 81
    assert report["figures"]["E_um"]["after_um"] < 1e-3  # exact at the targets (0.1 nm digits)
    assert left[("--from-measurement",)] > 2 * TRUTH["cos_um"] > 4 * left[()]
    # the fitted model sees what the measured means leave between the targets
    assert report["between_targets"]["pv_after_um"] == pytest.approx(
        left[("--from-measurement",)], rel=0.1)
    assert any("in-sample" in note for note in report["notes"])


def test_thermal_effects_and_unresolvable_ripples_stay_out(tmp_path):
    folder = write_case(tmp_path / "micro", {"name": "m", "screw": {"lead_mm": 1.0},
                                             "motor": {"step_angle_deg": 0.72,
                                                       "error_period_steps": 10}},
                        positioning={"target_mm": np.linspace(0, 5, 51),
                                     "error_um": np.zeros(51)})
    case = read_case(folder)
    model = Model([CATALOG[n] for n in ("lead_error", "assembly_eccentricity",
                                        "motor_step_error")],
                  {"lead_error": {"offset_um": 0.0, "slope_um_per_mm": -0.5},
                   "assembly_eccentricity": {"cos_um": 0.2, "sin_um": 0.15},
                   "motor_step_error": {"harmonic1_cos_um": 0.12, "harmonic1_sin_um": 0.09}})
    table = from_model(case, model, grid_mm(0.0, 5.0, 0.125))
    assert table.included == ("lead_error", "assembly_eccentricity")
    assert "0.02 mm wavelength" in table.excluded["motor_step_error"]
    fine = from_model(case, model, grid_mm(0.0, 5.0, 0.0025))
    assert "motor_step_error" in fine.included
    thermal = Model([CATALOG["lead_error"], CATALOG["ambient_expansion"]],
                    {"lead_error": {"offset_um": 0.0, "slope_um_per_mm": 0.0}})
    table = from_model(case, thermal, grid_mm(0.0, 5.0, 0.5))
    assert table.included == ("lead_error",) and not np.any(table.forward_um)
    assert "thermal" in table.excluded["ambient_expansion"]


def test_beckhoff_reproduces_the_manuals_worked_example():
    setpoint_um, plus_um, minus_um = 19866.7, 19856.5, 19874.7
    table = CompTable(np.array([setpoint_um, setpoint_um + 10000.0]) / 1e3,
                      np.array([plus_um - setpoint_um, 0.0]),
                      np.array([minus_um - setpoint_um, 0.0]))
    text = beckhoff.write(table)
    assert "kw.ssfk.table[0].setpoint     198667" in text
    assert "kw.ssfk.table[0].pos          -102" in text
    assert "kw.ssfk.table[0].neg          80" in text
    assert "kw.ssfk.interval              100000" in text
    assert "kw.ssfk.unit                  1" in text  # P-COMP-00017: 1 = metric, 0.1 um
    back = beckhoff.read(text)
    assert back.forward_um[0] == pytest.approx(-10.2) and back.reverse_um[0] == pytest.approx(8.0)


SIEMENS_MANUAL = """%_N_AX_EEC_INI
CHANDATA(1)
$AA_ENC_COMP[0,0,X1]=0.003 ; 1st compensation value (interpolation point 0): +3um
$AA_ENC_COMP[0,1,X1]=0.01 ; 2nd compensation value (interpolation point 1): +10um
$AA_ENC_COMP[0,2,X1]=0.012 ; 3rd compensation value (interpolation point 2): +12um
{rest}
$AA_ENC_COMP_STEP[0,X1]=1.0 ; Distance between interpolation points 1.0 mm
$AA_ENC_COMP_MIN[0,X1]=-200.0 ; Compensation starts at -200.0 mm
$AA_ENC_COMP_MAX[0,X1]=600.0 ; Compensation ends at +600.0 mm
$AA_ENC_COMP_IS_MODULO[0,X1]=0 ; Compensation without modulo function
M17
"""


def test_siemens_reads_the_manuals_example_and_its_sign():
    rest = "\n".join(f"$AA_ENC_COMP[0,{i},X1]=0.0" for i in range(3, 801))
    table = siemens.read(SIEMENS_MANUAL.format(rest=rest))
    assert table.size == 801  # the manual: MD38000 >= 801
    assert table.position_mm[0] == -200.0 and table.position_mm[-1] == 600.0
    # a positive value moves the axis in -: it removes a deviation of the same sign
    assert table.error_um(np.array([-200.0, -199.0, -198.5]), 1.0) == pytest.approx([3, 10, 11])
    written = siemens.write(CompTable(table.position_mm, table.forward_um, table.reverse_um))
    assert "$AA_ENC_COMP[0,200,X1]=0.000000" in written  # zero at the reference point
    assert "%_N_NC_CEC_INI" not in written


def test_siemens_direction_part_goes_into_two_cec_tables():
    position_mm = np.arange(5) * 10.0
    table = CompTable(position_mm, position_mm * 0.1 + 2.0, position_mm * 0.1 - 2.0)
    text = siemens.write(table)
    assert "$AN_CEC_DIRECTION[0]=1" in text and "$AN_CEC_DIRECTION[1]=-1" in text
    assert "$AN_CEC[0,0]=-0.002000" in text  # correction of +2 um in +
    back = siemens.read(text)
    np.testing.assert_allclose(back.forward_um - back.reverse_um, 4.0)


def test_linuxcnc_type1_example_matches_the_type0_example():
    # docs: type 0 "-1.000 -1.005 -0.995" (positions reached), type 1 "-1.000 0.005 -0.005"
    table = linuxcnc.read("-1.000 0.005 -0.005\n1.000 0.005 -0.005\n")
    reached_forward_mm, reached_reverse_mm = -1.005, -0.995
    assert table.forward_um[0] == pytest.approx((reached_forward_mm + 1.0) * 1e3)
    assert table.reverse_um[0] == pytest.approx((reached_reverse_mm + 1.0) * 1e3)
    assert linuxcnc.write(table).splitlines()[0] == "-1.000000 0.0050000 -0.0050000"


def test_linuxcnc_loader_stops_at_the_first_line_not_three_numbers():
    table = linuxcnc.read("0 0 0\n10 0.001 0.001\n# comment\n20 0.5 0.5\n")
    assert table.size == 2
    with pytest.raises(LineError, match="line 2.*strictly"):
        linuxcnc.read("0 0 0\n0 0 0\n")


@pytest.mark.parametrize("module, limit", [(linuxcnc, 256), (heidenhain, 256), (fanuc, 128),
                                           (beckhoff, 1500)])
def test_point_limits(module, limit):
    position_mm = np.arange(limit + 1) * 1.0
    table = CompTable(position_mm, np.zeros(limit + 1), np.zeros(limit + 1))
    with pytest.raises(InputError, match=f"at most {limit}"):
        module.write(table)
    module.read(module.write(CompTable(position_mm[:-1], np.zeros(limit), np.zeros(limit))))


@pytest.mark.parametrize("controller", ["siemens", "fanuc", "beckhoff", "mach4"])
def test_equidistant_controllers_refuse_free_positions(controller):
    table = CompTable(np.array([0.0, 1.0, 3.0]), np.zeros(3), np.zeros(3))
    with pytest.raises(InputError, match="equidistant"):
        CONTROLLERS[controller].write(table)


def test_fanuc_point_numbers_follow_the_manuals_example():
    # parameter manual: stroke -400 .. +800 mm, interval 50 mm, reference point No. 40 at 0:
    # farthest point on the - side 33, on the + side 56
    position_mm = np.arange(-400.0, 801.0, 50.0)
    text = fanuc.write(CompTable(position_mm, np.zeros(25), np.zeros(25)))
    parameters = dict(line.split(" A1 P") for line in text.splitlines() if " A1 P" in line)
    reference = int(parameters["N3620"])
    assert reference - int(parameters["N3621"]) == 40 - 33
    assert int(parameters["N3622"]) - reference == 56 - 40
    assert parameters["N3624"] == "50000"


def test_fanuc_manual_increments_survive_read_and_write():
    increments = [+2, +1, +1, -2, 0, -1, 0, -1, +2, +1, 0, -1, -1, -2, 0, +1, +2]  # No. 33-49
    lines = ["N3620 A1 P40", "N3621 A1 P33", "N3622 A1 P49", "N3623 A1 P1",
             "N3624 A1 P50000"] + [f"N{10033 + i} P{v}" for i, v in enumerate(increments)]
    table = fanuc.read("\n".join(lines))
    assert table.position_mm[0] == -400.0 and table.position_mm[-1] == 450.0
    correction_um = -table.forward_um
    assert correction_um[8] == 0.0  # the reference position, 0 mm
    assert correction_um[9] - correction_um[8] == 2.0  # No. 41 = +2: over 0 .. 50 mm
    rewritten = fanuc.read(fanuc.write(table))
    np.testing.assert_allclose(rewritten.forward_um, table.forward_um)


def test_fanuc_tape_never_sets_the_reference_position():
    """Parameter 1240 is the machine's reference position: the tape leaves it alone, a table
    without a point at 0 mm is refused, a parameter dump that has 1240 is read there, and a
    table built for a travel of 5 .. 305 mm is laid through 0 mm."""
    position_mm = np.arange(0.0, 301.0, 50.0)
    table = CompTable(position_mm, -0.01 * position_mm, -0.01 * position_mm)
    text = fanuc.write(table)
    assert "N1240" not in text
    with pytest.raises(InputError, match="point at 0 mm"):
        fanuc.write(CompTable(position_mm + 5.0, table.forward_um, table.reverse_um))
    shifted = fanuc.read("N1240 A1 P-100000\n" + text)
    np.testing.assert_allclose(shifted.position_mm, fanuc.read(text).position_mm - 100.0)
    target_mm = np.arange(5.0, 306.0, 50.0)
    case = syn.in_memory_case(syn.ISO_AXIS, target_mm=target_mm, error_um=0.0 * target_mm)
    grid = build_table(case, Model((), {}), "fanuc", spacing_mm=50.0)[0].position_mm
    np.testing.assert_allclose(grid, np.arange(0.0, 351.0, 50.0))


def test_fanuc_magnification_keeps_increments_in_range():
    position_mm = np.arange(5) * 10.0
    table = CompTable(position_mm, -300.0 * np.arange(5), -300.0 * np.arange(5))
    text = fanuc.write(table)
    assert "N3623 A1 P3" in text
    assert all(abs(int(line.split("P")[1])) <= 127 for line in text.splitlines()
               if line.startswith("N1"))
    np.testing.assert_allclose(fanuc.read(text).error_um(position_mm, 1.0), table.forward_um)


def test_units_in_the_files():
    position_mm = np.array([0.0, 10.0])
    table = CompTable(position_mm, np.array([5.0, -2.5]), np.array([5.0, -2.5]))
    assert linuxcnc.write(table).splitlines()[1] == "10.000000 0.0025000 0.0025000"
    assert "$AA_ENC_COMP[0,1,X1]=-0.007500" in siemens.write(table)
    assert "kw.ssfk.table[1].pos          -25" in beckhoff.write(table)
    assert "+10.0000     -0.002500" in heidenhain.write(table)
    assert "1 10.000000 -0.002500 -0.002500" in CONTROLLERS["mach4"].write(table)


def test_verification_warns_when_the_error_is_repeatability(tmp_path, capsys):
    rng = np.random.default_rng(3)
    target_mm = np.tile(np.arange(11) * 50.0, 5)
    folder = write_case(tmp_path / "noise", {"name": "n", "screw": {"lead_mm": 10.0}},
                        positioning={"target_mm": target_mm,
                                     "error_um": rng.normal(0.0, 2.0, target_mm.size)})
    code, out = run_comp_table(tmp_path, folder, "--from-measurement", "--controller",
                               "linuxcnc")
    report = json.loads(capsys.readouterr().out)
    assert code == 0 and len(report["warnings"]) == 2
    assert "cannot help" in report["warnings"][0]
    assert "repeatability" in report["warnings"][1]


def _positioning(rng, systematic_um):
    target_mm = np.tile(np.arange(11) * 50.0, 5)
    error_um = systematic_um * np.sin(target_mm / 80.0) + rng.normal(0.0, 1.0, target_mm.size)
    return Positioning(target_mm, error_um, np.ones(target_mm.size))


def test_the_anova_by_group_sums_equals_scipys_f_oneway():
    """Uneven groups (targets x directions, 1 to 7 samples): the p-value and the share of
    the variance between the groups, computed by bincount, equal scipy's f_oneway and a
    direct sum."""
    from scipy.stats import f_oneway

    rng = np.random.default_rng(12)
    target_mm = np.repeat(np.arange(15) * 10.0, rng.integers(1, 8, 15))
    direction = rng.choice([-1.0, 1.0], target_mm.size)
    error_um = 0.3 * np.sin(target_mm / 20.0) + rng.normal(0.0, 1.0, target_mm.size)
    positioning = Positioning(target_mm, error_um, direction, has_direction=True)
    found = systematic_test(positioning)
    groups = [error_um[(target_mm == t) & (direction == d)]
              for t in np.unique(target_mm) for d in (-1.0, 1.0)]
    groups = [g for g in groups if g.size]
    assert found["p_value"] == pytest.approx(f_oneway(*groups).pvalue, rel=1e-9)
    between = sum(g.size * (g.mean() - error_um.mean()) ** 2 for g in groups)
    assert found["systematic_share"] == pytest.approx(
        between / np.sum((error_um - error_um.mean()) ** 2), rel=1e-9)


def test_the_cannot_help_test_has_its_false_alarm_rate_and_power():
    rng = np.random.default_rng(11)
    trials = 400
    false_alarms = np.mean([systematic_test(_positioning(rng, 0.0))["p_value"] <= ALPHA
                            for _ in range(trials)])
    power = np.mean([systematic_test(_positioning(rng, 1.0))["p_value"] <= ALPHA
                     for _ in range(trials)])
    assert 0.02 <= false_alarms <= 0.085  # 5 % nominal; binomial 99 % band for 400 trials
    assert power >= 0.85  # systematic amplitude = the noise sigma, 5 runs per target


def test_bad_options_exit_2_and_write_nothing(tmp_path, fitted, capsys):
    folder, model = fitted
    for options, phrase in ((("--controller", "siemens"), "--model"),
                            (("--model", str(model), "--controller", "linuxcnc",
                              "--spacing-mm", "0.5"), "at most 256"),
                            (("--model", str(model), "--controller", "fanuc",
                              "--spacing-mm", "-1"), "--spacing-mm")):
        code, out = run_comp_table(tmp_path, folder, *options)
        assert code == 2 and phrase in capsys.readouterr().err
        assert not out.exists()


def test_verify_of_a_table_that_removes_nothing_changes_nothing(fitted):
    case = read_case(fitted[0])
    zero = CompTable(np.array([0.0, 500.0]), np.zeros(2), np.zeros(2))
    for figure in verify(case, zero)["figures"].values():
        assert figure["after_um"] == pytest.approx(figure["before_um"])


def test_heidenhain_writes_the_cma_beside_the_com(tmp_path, fitted, capsys):
    folder, model = fitted
    out = tmp_path / "X.COM"
    assert main(["comp-table", str(folder), "--model", str(model), "--controller",
                 "heidenhain", "--out", str(out)]) == 0
    cma = (tmp_path / "X.CMA").read_text()
    assert "X.COM" in cma and "*" in cma
    assert heidenhain.read(out.read_text()).size == heidenhain.MAX_POINTS  # 0.1 µm not reached


@pytest.mark.parametrize("module, old, new, line", [
    (heidenhain, "+10.0000", "-10.0000", 4),
    (beckhoff, "kw.ssfk.table[1].setpoint     100000", "kw.ssfk.table[1].setpoint     0", 11),
])
def test_readers_refuse_positions_not_increasing(module, old, new, line):
    table = CompTable(np.array([0.0, 10.0, 20.0]), np.zeros(3), np.zeros(3))
    text = module.write(table)
    assert old in text
    with pytest.raises(LineError, match=f"line {line}"):
        module.read(text.replace(old, new))


def test_the_cli_offers_every_controller(capsys):
    from feedaxis.cli import main

    with pytest.raises(SystemExit):
        main(["comp-table", "--help"])
    assert f"--controller {{{','.join(CONTROLLERS)}}}" in capsys.readouterr().out


def test_mach4_map_reads_back_and_refuses_a_short_line():
    mach4 = CONTROLLERS["mach4"]
    table = CompTable(np.array([0.0, 10.0, 20.0]), np.array([1.0, 2.0, 3.0]),
                      np.array([-1.0, 0.0, 1.0]))
    text = mach4.write(table)
    back = mach4.read(text)
    np.testing.assert_allclose(back.forward_um, table.forward_um)
    np.testing.assert_allclose(back.reverse_um, table.reverse_um)
    with pytest.raises(LineError, match="line 7"):
        mach4.read(text.replace("1 10.000000 0.002000 0.000000", "1 10.000000 0.002000"))


def test_a_heidenhain_table_not_named_com_is_written_with_a_warning(tmp_path, fitted, capsys):
    folder, model = fitted
    out = tmp_path / "tab.heidenhain"
    assert main(["comp-table", str(folder), "--model", str(model), "--controller",
                 "heidenhain", "--out", str(out), "--json"]) == 0
    report = json.loads(capsys.readouterr().out)
    assert out.exists() and any(".COM ending" in w and "tab.COM" in w
                                for w in report["warnings"])
