"""The uncertainty result for the terminal: figures with their intervals, each input's
share, the parameters, the table's largest uncertainty, the notes."""
from __future__ import annotations

import math

from ..standards import DEFAULT, STANDARDS
from ..text import micro

SHORT_NAMES = {"repeatability": "repeat.", "device_calibration": "device",
               "machine_temperature": "temp.", "expansion_coefficient": "alpha",
               "misalignment": "align.", "setup": "setup", "eve": "EVE"}


def _interval(pair, digits=4):
    return f"[{pair[0]:.{digits}g}, {pair[1]:.{digits}g}]"


def _share(value):
    return "" if value is None or math.isnan(value) else f"{100 * value:.1f}%"


def number(value, spec):
    """``value`` formatted by ``spec``; a moment that does not exist (None) as ``n/a``."""
    return "n/a" if value is None else format(value, spec)


def uncertainty_lines(result):
    """The whole result as text lines (joined with newlines)."""
    payload = result.to_json()
    inputs = list(result.inputs)
    lines = [f"{payload['case']}: {result.trials} Monte Carlo trials (JCGM 101), seed "
             f"{result.seed}; 95 % coverage intervals",
             f"repeatability: {result.repeatability}",
             "corrected to 20 °C: " + (f"{result.correction.source}, α = "
                                       f"{result.correction.expansion_per_K:g}/K"
                                       if result.correction else "no")]
    if result.adaptive:
        adaptive = result.adaptive
        lines.append(f"adaptive (JCGM 101 §7.9): {adaptive.blocks} blocks, numerical tolerance "
                     f"{adaptive.reached:.2g} µm of {adaptive.tolerance:g} asked"
                     + ("" if adaptive.stabilised else " -- NOT reached"))
    width = max([28] + [len(f["name"]) for f in result.figures.values()])
    heading = {STANDARDS[DEFAULT].title: "ISO 230-2 ", "all": ""}.get(
        result.standard, result.standard + " ") + "figure (µm)"
    lines += ["", f"{heading:{width}s} {'value':>8s} {'u':>7s}  "
                  f"{'95 % interval':20s} {'shortest 95 %':20s}"]
    for figure in result.figures.values():
        lines.append(f"{figure['name']:{width}s} {figure['value_um']:8.4g} "
                     f"{number(figure['standard_uncertainty_um'], '7.2g'):>7s}  "
                     f"{_interval(figure['coverage_interval_um']):20s} "
                     f"{_interval(figure['shortest_coverage_interval_um']):20s}")
    lines += _share_lines(result, inputs, width)
    lines += _parameter_lines(result)
    if result.table:
        table = result.table
        lines += ["", f"compensation table ({table['source']}: "
                      f"{', '.join(table['included'])}), {len(table['position_mm'])} points, "
                      f"{table['trials']} trials: largest u "
                      + number(table['largest_standard_uncertainty_um'], '.2g') + (
                          "" if table["largest_standard_uncertainty_um"] is None else " µm")
                      + ("; shares: " + ", ".join(f"{SHORT_NAMES.get(i, i)} {_share(c['share'])}"
                                                  for i, c in table["contributions"].items())
                         if "standard_uncertainty" in result.moments else "")]
    lines += [f"note: {note}" for note in result.notes]
    return "\n".join(lines)


def _share_lines(result, inputs, width=28):
    """Each input's share of u² per figure (names ``width`` wide), or why there are none."""
    if "standard_uncertainty" not in result.moments:
        return ["", "share of u² per input: none (the outputs have no variance; see the note)"]
    lines = ["", "share of u² per input (JCGM 101 Annex B: each input varied alone)",
             f"{'':{width}s} " + " ".join(f"{SHORT_NAMES.get(i, i):>8s}" for i in inputs)]
    for figure in result.figures.values():
        lines.append(f"{figure['name']:{width}s} " + " ".join(
            f"{_share(figure['contributions'][i]['share']):>8s}" for i in inputs))
    return lines


def _refit_difference(in_u):
    """The refit check's largest difference, round-off (below 1e-6 u) shown as a bound."""
    return "below 1e-6" if in_u < 1e-6 else f"{in_u:.1g}"


def _parameter_lines(result):
    if not (result.parameters or result.undetermined):
        return []
    method = result.parameter_method
    lines = ["", f"fitted parameters ({method['method']}; checked by refitting "
                 f"{method['checked_trials']} trials: largest difference "
                 f"{_refit_difference(method['largest_refit_difference_in_u'])} u)",
             f"{'':44s} {'value':>11s} {'u':>9s} {'u fit':>9s}  95 % interval"]
    for key, entry in result.parameters.items():
        lines.append(f"  {key:42s} {entry['value']:11.5g} "
                     f"{number(entry['standard_uncertainty'], '9.2g'):>9s} "
                     f"{entry['fit_standard_uncertainty']:9.2g}  "
                     f"{_interval(entry['coverage_interval'], 5)} {micro(entry['unit'])}")
    lines += [f"  {key:42s} undetermined: {why}" for key, why in result.undetermined.items()]
    return lines
