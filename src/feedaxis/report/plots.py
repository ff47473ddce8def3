"""Report figures as PNG bytes (matplotlib, Agg backend); each takes computed arrays only.

Every figure reads without help: a legend only where something is labelled, tick labels
without an offset or a power of ten over the axis, and a span of at least
``MIN_SPAN_UM`` on a value axis, so a contribution constant to the last digit reads as the
constant it is.
"""
from __future__ import annotations

import io

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from matplotlib.ticker import ScalarFormatter  # noqa: E402

from ..iso230 import target_clusters  # noqa: E402

MARK_COLOURS = ("tab:red", "tab:purple", "tab:brown", "tab:olive")
DIRECTION_COLOURS = {1.0: "tab:blue", -1.0: "tab:orange"}
MODEL_COLOURS = {1.0: "navy", -1.0: "saddlebrown"}  # a direction's model over its dots
DIRECTION_TICKS = {-1.0: "− approach", 1.0: "+ approach"}
MAX_PERIOD_LINES = 60
MAX_MARKED_TARGETS = 60  # more targets than this are drawn as a line, without markers
MIN_SPAN_UM = 1e-3  # 1 nm, the diagnosis's resolution: a smaller span is rounding
MAX_PLOTTED = 4000  # points per series: beyond it the envelope (min and max per bin) is drawn


def _finish(figure, axes, xlabel, ylabel, title, grid="major"):
    """Labels, legend (when anything is labelled) and grid, then the figure as PNG bytes."""
    axes.set(xlabel=xlabel, ylabel=ylabel, title=title)
    _legend(axes)
    axes.grid(alpha=0.3, which=grid)
    return _png(figure)


def _legend(axes):
    if axes.get_legend_handles_labels()[0]:
        axes.legend(loc="best", fontsize=8)


def _readable(axes):
    """Plain tick labels (no offset, no power of ten over the axis) and a value axis at
    least ``MIN_SPAN_UM`` wide."""
    if axes.get_yscale() == "linear":
        low, high = axes.get_ylim()
        if high - low < MIN_SPAN_UM:
            centre = (low + high) / 2
            axes.set_ylim(centre - MIN_SPAN_UM / 2, centre + MIN_SPAN_UM / 2)
    for axis in (axes.xaxis, axes.yaxis):
        formatter = axis.get_major_formatter()
        if isinstance(formatter, ScalarFormatter):
            formatter.set_useOffset(False)
            formatter.set_scientific(False)


def _plot(axes, x, y, *style, **options):
    """``axes.plot`` of a series thinned to at most ``MAX_PLOTTED`` points: in order of x,
    the smallest and the largest y of each of ``MAX_PLOTTED // 2`` bins, so every excursion
    stays on the picture (a report of 10^5 samples drew for 20 s unthinned)."""
    x, y = np.asarray(x), np.asarray(y)
    if x.size > MAX_PLOTTED:
        order = np.argsort(x, kind="stable")
        starts = np.linspace(0, x.size, MAX_PLOTTED // 2, endpoint=False).astype(int)
        bins = np.repeat(np.arange(starts.size), np.diff(np.r_[starts, x.size]))
        binned = y[order]
        chosen = [order[_first_per_bin(binned == extreme.reduceat(binned, starts)[bins], bins)]
                  for extreme in (np.fmin, np.fmax)]
        chosen = np.unique(np.concatenate(chosen))
        x, y = x[chosen], y[chosen]
    return axes.plot(x, y, *style, **options)


def _first_per_bin(mask, bins):
    """Index of the first True of ``mask`` in each bin that has one."""
    hits = np.flatnonzero(mask)
    return hits[np.unique(bins[hits], return_index=True)[1]]


def _png(figure):
    for axes in figure.axes:
        _readable(axes)
    buffer = io.BytesIO()
    figure.tight_layout()
    figure.savefig(buffer, format="png", dpi=110)
    plt.close(figure)
    return buffer.getvalue()


def _direction_label(sign):
    return "+" if sign > 0 else "-"


def measurement_vs_model(position_mm, measured_um, measured_direction, model_mm, model_um,
                         model_direction, model_line, per_run=False):
    """Measured deviations (light dots, coloured by approach direction) and the model between
    the targets (lines on top, in the darker shade of the same direction): ``model_mm``,
    ``model_um`` are points on lines numbered by ``model_line``, one per approach direction
    (and per run when ``per_run``: a time-dependent case, whose runs differ), so no line
    joins points of different runs."""
    figure, axes = plt.subplots(figsize=(9, 3.6))
    for sign in np.unique(measured_direction):
        chosen = measured_direction == sign
        _plot(axes, position_mm[chosen], measured_um[chosen], ".", ms=2, alpha=0.45,
              color=DIRECTION_COLOURS[float(sign)], zorder=2,
              label=f"measured, {_direction_label(sign)} approach")
    labelled = set()
    for number in np.unique(model_line):
        chosen = model_line == number
        sign = float(model_direction[chosen][0])
        label = None
        if sign not in labelled:
            labelled.add(sign)
            label = (f"model ({_direction_label(sign)} approach"
                     f"{', per run' if per_run else ''}), between the targets too")
        _plot(axes, model_mm[chosen], model_um[chosen], "-", lw=1.4,
              color=MODEL_COLOURS[sign], zorder=3, label=label)
    return _finish(figure, axes, "position (mm)", "error (µm)", "Measurement against model")


def iso230_deviation(per_direction, line):
    """The figure of ISO 230-2: the mean deviation x̄ at each target per direction, with bars
    x̄ ± 2s where the runs repeat (s is NaN with one run); below, the same less ``line``
    (offset_um, slope_um_per_mm), the straight line through the means, so a steep lead
    error does not hide the reversal and the scatter.

    ``per_direction`` is {"+" or "-": (target_mm, mean_um, std_um)}.
    """
    offset_um, slope_um_per_mm = line
    figure, (top, bottom) = plt.subplots(2, 1, figsize=(9, 6), sharex=True)
    repeated = False
    for sign, (target_mm, mean_um, std_um) in per_direction.items():
        colour = DIRECTION_COLOURS[1.0 if sign == "+" else -1.0]
        style = "o-" if target_mm.size <= MAX_MARKED_TARGETS else "-"
        finite = np.isfinite(std_um)
        repeated = repeated or bool(finite.any())
        for axes, values_um in ((top, mean_um),
                                (bottom, mean_um - (offset_um + slope_um_per_mm * target_mm))):
            _plot(axes, target_mm, values_um, style, ms=3, lw=1.0, color=colour,
                  label=f"x̄{'↑' if sign == '+' else '↓'} ({sign} approach)")
            if finite.any():
                axes.errorbar(target_mm[finite], values_um[finite], yerr=2 * std_um[finite],
                              fmt="none", ecolor=colour, elinewidth=0.8, capsize=2,
                              label=f"x̄ ± 2s ({sign})")
    band = ("bars x̄ ± 2s where the runs repeat" if repeated
            else "one run per target: no s, so no ± 2s band")
    top.set(ylabel="mean deviation (µm)",
            title=f"ISO 230-2 mean deviation x̄ per approach direction; {band}")
    bottom.set(xlabel="target position (mm)", ylabel="less the line (µm)",
               title=f"The same less the straight line through the means "
                     f"({slope_um_per_mm:+.4g} µm/mm, {offset_um:+.4g} µm at 0 mm)")
    _legend(top)
    for axes in (top, bottom):
        axes.grid(alpha=0.3)
    return _png(figure)


def residual_vs_position(position_mm, residual_um, marks):
    """Residual against position; the catalog wavelengths as period grids and scale bars."""
    figure, axes = plt.subplots(figsize=(9, 3.6))
    _plot(axes, position_mm, residual_um, ".", ms=2, color="tab:blue", label="residual")
    start, stop = float(np.min(position_mm)), float(np.max(position_mm))
    top = float(np.max(residual_um)) if residual_um.size else 1.0
    for (label, wavelength), colour in zip(marks.items(), MARK_COLOURS):
        if (stop - start) / wavelength <= MAX_PERIOD_LINES:
            for x in np.arange(start, stop + 1e-12, wavelength):
                axes.axvline(x, color=colour, lw=0.6, alpha=0.4)
        axes.plot([start, start + wavelength], [top, top], "-", lw=3, color=colour,
                  label=f"{label}: {wavelength:.4g} mm")
    return _finish(figure, axes, "target position (mm)", "residual (µm)",
                   "Residual against position" + (", with the catalog wavelengths the "
                                                  "targets resolve" if marks else ""))


def spectrum(residual, measured, marks, structures=(), target_mm=None):
    """Amplitude spectra (wavelength, amplitude) of the residual and of the detrended
    measurement against wavelength, over the wavelengths the targets resolve only (call it
    with at least one spectrum that is not empty); the catalog wavelengths ``marks`` (those
    the targets resolve) and unexplained peaks within that band marked, marks outside the
    band named in the title. The detrended measurement is drawn dashed over the residual, so
    neither hides the other. With ``target_mm`` (at most ``MAX_MARKED_TARGETS`` targets) the
    spectra are marked at their independent wavelengths, span / k: between them the curve
    is an interpolation, not a finer resolution."""
    figure, axes = plt.subplots(figsize=(9, 3.4))
    shown = [w for w, _ in (residual, measured) if w.size]
    low = min(float(w.min()) for w in shown)
    high = max(float(w.max()) for w in shown)
    top = 0.0
    independent = _independent_wavelengths(target_mm)
    for (wavelength_mm, amplitude_um), style in (
            (residual, dict(color="tab:blue", lw=1.2, zorder=2, label="residual")),
            (measured, dict(color="0.3", lw=1.0, ls="--", zorder=3,
                            label="measured, trend removed"))):
        if wavelength_mm.size:
            _plot(axes, wavelength_mm, amplitude_um, **style)
            _mark_independent(axes, wavelength_mm, amplitude_um, independent, style)
            axes.set_xscale("log")
            top = max(top, float(np.max(amplitude_um)))
    outside = []
    for (label, wavelength), colour in zip(marks.items(), MARK_COLOURS):
        if low <= wavelength <= high:
            axes.axvline(wavelength, color=colour, ls="--", lw=1,
                         label=f"{label} {wavelength:.4g} mm")
        else:
            outside.append(f"{label} {wavelength:.4g} mm")
    for structure in structures:
        if structure.wavelength_mm and low <= structure.wavelength_mm <= high:
            axes.axvline(structure.wavelength_mm, color="k", ls=":", lw=1.2,
                         label=f"unexplained {structure.wavelength_mm:.4g} mm")
    axes.set_xlim(low, high)
    axes.set_ylim(0.0, 1.1 * top if top > 0 else 1.0)
    title = "Spatial spectrum along the travel, over the wavelengths the targets resolve"
    if independent is not None:
        title += f"\n{np.unique(target_mm).size} targets: dots at the independent wavelengths"
    if outside:
        title += "\noutside this band: " + ", ".join(outside)
    return _finish(figure, axes, "wavelength (mm)", "amplitude (µm)", title, grid="both")


def _independent_wavelengths(target_mm):
    """span / k, k = 1 .. targets / 2: the wavelengths a few targets determine apart (None
    without targets or with more than ``MAX_MARKED_TARGETS``)."""
    if target_mm is None:
        return None
    targets = np.unique(target_mm)
    if targets.size > MAX_MARKED_TARGETS or targets.size < 2:
        return None
    return np.ptp(targets) / np.arange(1, targets.size // 2 + 1)


def _mark_independent(axes, wavelength_mm, amplitude_um, independent, style):
    """Dots on a spectrum at the independent wavelengths within its band."""
    if independent is None:
        return
    order = np.argsort(wavelength_mm)
    inside = independent[(independent >= wavelength_mm.min()) & (independent <= wavelength_mm.max())]
    axes.plot(inside, np.interp(inside, wavelength_mm[order], amplitude_um[order]), "o", ms=4,
              color=style["color"], zorder=style["zorder"])


def contributions(coordinate, components, xlabel, line=None, direction=None, windows=None):
    """Each effect's contribution against ``coordinate`` (position or time), one panel per
    effect, drawn as lines (numbered by ``line``, coloured by approach ``direction``;
    coordinates increasing along each line). An effect with a window in ``windows``
    {effect: (start, stop)} (a period too short to read over the whole travel) gets a
    second panel showing that window."""
    windows = windows or {}
    count = max(len(components), 1)
    line = np.zeros(coordinate.size, dtype=int) if line is None else line
    direction = np.ones(coordinate.size) if direction is None else direction
    figure = plt.figure(figsize=(9, 1.8 * count + 0.6))
    grid = figure.add_gridspec(count, 4 if windows else 1)
    first = None
    for row, (name, values_um) in enumerate(components.items()):
        axes = figure.add_subplot(grid[row, :3] if name in windows else grid[row, :],
                                  sharex=first)
        first = first or axes
        panels = [(axes, np.ones(coordinate.size, dtype=bool))]
        if name in windows:
            start, stop = windows[name]
            zoom = figure.add_subplot(grid[row, 3])
            zoom.set_title(f"zoomed in: {start:g} to {stop:.4g}", fontsize=8, loc="left")
            panels.append((zoom, (coordinate >= start) & (coordinate <= stop)))
        for panel, inside in panels:
            for number in np.unique(line):
                chosen = (line == number) & inside
                if chosen.any():
                    _plot(panel, coordinate[chosen], values_um[chosen], "-", lw=0.8,
                          color=DIRECTION_COLOURS[float(direction[chosen][0])])
            panel.grid(alpha=0.3)
        axes.set_ylabel("µm")
        axes.set_title(name, fontsize=9, loc="left")
        if row == count - 1:
            for panel, _ in panels:
                panel.set_xlabel(xlabel)
        else:
            axes.tick_params(labelbottom=False)
    figure.suptitle("Each effect's contribution")
    return _png(figure)


def ladder(steps, noise_um):
    """Residual RMS after each added effect (bars) and the noise level (line)."""
    figure, axes = plt.subplots(figsize=(9, 3.4))
    labels = [label for label, _ in steps]
    values = [value for _, value in steps]
    axes.bar(range(len(steps)), values, color="tab:blue")
    for index, value in enumerate(values):
        axes.text(index, value, f"{value:.3g}", ha="center", va="bottom", fontsize=8)
    axes.axhline(noise_um, color="tab:red", ls="--", label=f"noise {noise_um:.3g} µm")
    axes.set_xticks(range(len(steps)), labels, rotation=15, fontsize=8)
    return _finish(figure, axes, "", "residual RMS (µm)",
                   "Error ladder: RMS after each added effect")


def residual_against(panels):
    """Residual against other variables (time, direction, ambient): one titled panel each;
    the approach direction (values ±1) as two categories, each in its direction's colour."""
    figure, axes_list = plt.subplots(1, len(panels), figsize=(3.2 * len(panels), 3),
                                     squeeze=False)
    for axes, (label, values, residual_um) in zip(axes_list[0], panels):
        if set(np.unique(values)) <= set(DIRECTION_TICKS):
            for sign, tick in DIRECTION_TICKS.items():
                chosen = values == sign
                _plot(axes, values[chosen], residual_um[chosen], ".", ms=2,
                      color=DIRECTION_COLOURS[sign], alpha=0.6)
            axes.set_xticks(list(DIRECTION_TICKS), list(DIRECTION_TICKS.values()))
            axes.set_xlim(-2.0, 2.0)
        else:
            _plot(axes, values, residual_um, ".", ms=2)
        axes.set(xlabel=label, ylabel="residual (µm)", title=f"Residual against {label}")
        axes.title.set_fontsize(9)
        axes.grid(alpha=0.3)
    return _png(figure)


def thermal_compensation(target_mm, visit, time_s, thermal_error_um, left_um):
    """Rong et al. 2023 Fig. 13: thermal error against position, one line per visit coloured by time,
    without and with compensation on one scale; then the max of each visit against time."""
    figure, axes_list = plt.subplots(1, 3, figsize=(12, 3.6),
                                     gridspec_kw={"width_ratios": (1, 1, 1.1)})
    colours = plt.get_cmap("viridis")
    minutes = time_s / 60.0
    span_min = max(float(np.ptp(minutes)), 1e-9)
    limit = 1.05 * float(np.max(np.abs(thermal_error_um)))
    by_visit = [visit == v for v in np.unique(visit)]
    for axes, values_um, title in ((axes_list[0], thermal_error_um, "without compensation"),
                                   (axes_list[1], left_um, "with compensation")):
        for chosen in by_visit:
            order = np.argsort(target_mm[chosen])
            shade = (float(np.mean(minutes[chosen])) - float(np.min(minutes))) / span_min
            axes.plot(target_mm[chosen][order], values_um[chosen][order], "-", lw=0.9,
                      color=colours(shade))
        axes.set(xlabel="target position (mm)", ylabel="thermal error (µm)", title=title,
                 ylim=(-limit, limit))
        axes.grid(alpha=0.3)
    scale = plt.cm.ScalarMappable(cmap=colours, norm=plt.Normalize(minutes.min(), minutes.max()))
    figure.colorbar(scale, ax=axes_list[1], label="time (min)")
    axes = axes_list[2]
    run_minutes = [float(np.mean(minutes[chosen])) for chosen in by_visit]
    for values_um, label in ((thermal_error_um, "without"), (left_um, "with compensation")):
        axes.plot(run_minutes, [np.max(np.abs(values_um[chosen])) for chosen in by_visit], "o-",
                  ms=3, label=label)
    return _finish(figure, axes, "time (min)", "max |thermal error| (µm)",
                   "Largest error of each run")


def thermal_drift(time_s, target_mm, direction, drift_um, segments):
    """ISO 230-3: each target's drift (deviation less its first reading) against time, one
    line per target and approach direction (- dashed) coloured by position, over the
    duty's feed (shaded, right axis)."""
    figure, axes = plt.subplots(figsize=(9, 3.8))
    duty = axes.twinx()
    for segment in segments:
        duty.fill_between([segment.start_s / 60.0, segment.end_s / 60.0], 0.0,
                          segment.feed_mm_min / 1000.0, color="0.85", step="pre", lw=0)
    duty.set_ylabel("duty feed (m/min)", color="0.45")
    axes.set_zorder(duty.get_zorder() + 1)
    axes.patch.set_visible(False)
    colours = plt.get_cmap("viridis")
    centres_mm, cluster = target_clusters(target_mm)
    for index, target in enumerate(centres_mm):
        for sign, style in ((1.0, ".-"), (-1.0, ".--")):
            chosen = np.flatnonzero((cluster == index) & (direction == sign))
            if chosen.size == 0:
                continue
            order = chosen[np.argsort(time_s[chosen])]
            first = sign > 0 or not np.any((cluster == index) & (direction > 0))
            axes.plot(time_s[order] / 60.0, drift_um[order], style, ms=3, lw=0.9,
                      color=colours(index / max(centres_mm.size - 1, 1)),
                      label=f"{target:g} mm" if centres_mm.size <= 12 and first else None)
    return _finish(figure, axes, "time (min)", "drift (µm)",
                   "Deviation over time at each target, with the duty (ISO 230-3)")


def compensation_table(target_mm, means_um, table_mm, table_um):
    """Measured mean deviation per target and direction (dots) with the compensation table's
    deviation per direction (lines through its points, as the controller interpolates).

    ``means_um`` and ``table_um`` map a label ("+", "-") to arrays at ``target_mm[label]``
    and ``table_mm``.
    """
    figure, axes = plt.subplots(figsize=(9, 3.6))
    for (label, mean_um), colour in zip(means_um.items(), ("tab:blue", "tab:orange")):
        axes.plot(target_mm[label], mean_um, "o", ms=4, color=colour, alpha=0.5,
                  label=f"measured mean, {label} approach")
        axes.plot(table_mm, table_um[label], ".-", ms=3, lw=1.5, color="black"
                  if len(means_um) == 1 else colour, zorder=3, label=f"table, {label} direction")
    return _finish(figure, axes, "position (mm)", "deviation removed (µm)",
                   "Compensation table over the measured means")


def error_against_time(time_s, measured_um, predicted_um, reversals_s, reference):
    """Tracking deviation measured and predicted against time, and below it, on its own
    scale, the residual (measured − model): where the model covers the measurement the
    upper panel shows one line, the lower one what is left. Reversals marked; ``reference``
    names what the reference is (a sine, a point-to-point trajectory, reversals)."""
    figure, (upper, lower) = plt.subplots(2, 1, figsize=(9, 5.4), sharex=True,
                                          gridspec_kw={"height_ratios": (3, 2)})
    _plot(upper, time_s, measured_um, color="0.55", lw=0.8, label="measured")
    _plot(upper, time_s, predicted_um, color="tab:blue", lw=0.8, ls="--", label="model")
    _plot(lower, time_s, np.asarray(measured_um) - np.asarray(predicted_um),
          color="tab:orange", lw=0.8, label="residual (measured - model)")
    for axes in (upper, lower):
        for index, t in enumerate(reversals_s):
            axes.axvline(t, color="tab:red", lw=0.5, alpha=0.5,
                         label="velocity reversal" if index == 0 and axes is upper else None)
        axes.grid(alpha=0.3)
        _legend(axes)
    upper.set(ylabel="actual - reference (µm)",
              title=f"Tracking deviation against time ({reference})")
    lower.set(xlabel="time (s)", ylabel="residual (µm)")
    return _png(figure)


def error_against_velocity(velocity_mm_s, measured_um, residual_um):
    """Deviation and residual against the reference velocity: friction shows as a jump at 0."""
    figure, axes = plt.subplots(figsize=(9, 3.6))
    _plot(axes, velocity_mm_s, measured_um, ".", ms=1.5, color="0.55", label="measured")
    _plot(axes, velocity_mm_s, residual_um, ".", ms=1.5, color="tab:orange",
              label="residual after the model")
    axes.axvline(0.0, color="tab:red", lw=0.8, label="reversal (v = 0)")
    return _finish(figure, axes, "reference velocity (mm/s)", "µm",
                   "Tracking deviation against velocity")


def frequency_spectrum(frequency_hz, amplitude_um, structures):
    """Amplitude spectrum of the residual in Hz, unexplained frequencies marked."""
    figure, axes = plt.subplots(figsize=(9, 3.4))
    axes.loglog(frequency_hz, np.maximum(amplitude_um, 1e-12), lw=0.8, label="residual")
    for structure in structures:
        if structure.frequency_hz:
            axes.axvline(structure.frequency_hz, color="tab:red", ls="--",
                         label=f"unexplained {structure.frequency_hz:.4g} Hz")
    return _finish(figure, axes, "frequency (Hz)", "amplitude (µm)", "Residual spectrum",
                   grid="both")


def uncertainty_histograms(panels):
    """A small histogram per ISO 230-2 figure: the Monte Carlo values (their central
    99.8 %, so a long tail does not squeeze the rest), the figure of the data (line) and
    the 95 % coverage interval (shaded). ``panels`` is
    [(title, values_um, value_um, (low_um, high_um))]."""
    columns = min(3, len(panels))
    rows = -(-len(panels) // columns)
    figure, axes = plt.subplots(rows, columns, figsize=(3.2 * columns, 2.4 * rows),
                                squeeze=False)
    for axis, (title, values, value, (low, high)) in zip(axes.flat, panels):
        axis.hist(values, bins=60, range=tuple(np.quantile(values, (0.001, 0.999))),
                  color="tab:blue", alpha=0.7)
        axis.axvspan(low, high, color="tab:orange", alpha=0.2, label="95 % interval")
        axis.axvline(value, color="black", lw=1, label="value")
        axis.set_title(title, fontsize=9)
        axis.set_xlabel("µm", fontsize=8)
        axis.tick_params(labelsize=7)
        axis.set_yticks([])
    for axis in list(axes.flat)[len(panels):]:
        axis.set_visible(False)
    axes.flat[0].legend(fontsize=7)
    return _png(figure)


def table_with_uncertainty(position_mm, sides):
    """The compensation table's values against position with their 95 % coverage band,
    per direction; ``sides`` is [(label, value_um, low_um, high_um)]."""
    figure, axes = plt.subplots(figsize=(9, 3.4))
    for (label, value, low, high), colour in zip(sides, ("tab:blue", "tab:orange")):
        axes.plot(position_mm, value, color=colour, lw=1, label=label)
        axes.fill_between(position_mm, low, high, color=colour, alpha=0.25,
                          label=f"{label}: 95 % interval")
    return _finish(figure, axes, "position (mm)", "table value (µm)",
                   "compensation table and its 95 % coverage interval")


def polar_traces(angle_deg, direction, traces, figures):
    """The circle as ballbar users read it: one polar panel per trace ({title: radial
    deviation µm}: measured, model, residual), counter-clockwise and clockwise in their
    colours, the deviation drawn about a reference circle (dotted) so inward and outward
    read at a glance; ``figures`` ({title: text}) under each panel's title."""
    figure, panels = plt.subplots(1, len(traces), figsize=(4.2 * len(traces), 4.6),
                                  subplot_kw={"projection": "polar"})
    panels = np.atleast_1d(panels)
    span_um = max(max(float(np.ptp(values)) for values in traces.values()), MIN_SPAN_UM)
    reference_um = 1.5 * span_um
    theta = np.radians(angle_deg)
    for axes, (title, values) in zip(panels, traces.items()):
        centred = values - np.mean(values)
        for sign, colour in DIRECTION_COLOURS.items():
            chosen = direction == sign
            if chosen.any():
                order = np.argsort(theta[chosen], kind="stable")
                axes.plot(theta[chosen][order], reference_um + centred[chosen][order], ".",
                          markersize=1.5, color=colour,
                          label="counter-clockwise" if sign > 0 else "clockwise")
        axes.plot(np.linspace(0, 2 * np.pi, 361), np.full(361, reference_um), ":",
                  color="0.5", linewidth=0.8)
        axes.set_ylim(0, reference_um + span_um)
        axes.set_yticklabels([])
        axes.set_title(f"{title}\n{figures.get(title, '')}", fontsize=9)
    panels[0].legend(loc="lower left", bbox_to_anchor=(-0.25, -0.2), fontsize=8)
    figure.suptitle(f"radial deviation about the mean radius; ring = {span_um:.3g} µm "
                    "from the dotted circle to the rim", fontsize=9)
    buffer = io.BytesIO()
    figure.tight_layout()
    figure.savefig(buffer, format="png", dpi=110)
    plt.close(figure)
    return buffer.getvalue()
