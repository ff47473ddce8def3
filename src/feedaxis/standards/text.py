"""The figures of a standard (or of all, one after the other) for the terminal."""
from __future__ import annotations

from .definitions import DEFAULT, STANDARDS

RMS_LABEL = "RMS (the model alone)"  # every sample, no artefact fitted beside (fit prints both)
COLUMNS = {"measured_um": "measured", "residual_um": "residual", "explained": "explained",
           "predicted_um": "model", "compensated_um": "compensated"}


def standard_lines(block, rms=None):
    """One standard's block of ``compare``: its figures (µm) in columns, then what the
    standard asks that the data lack (each once, with the figures it touches), then what
    of its definition is not confirmed publicly (the default's block reads as ever)."""
    if block.get("unavailable"):
        return [f"{block['standard']}: no figures. {block['unavailable']}"]
    figures = list(block["figures"].values())
    columns = [key for key in COLUMNS if figures and key in figures[0]]
    default = block["standard"] == STANDARDS[DEFAULT].title
    label = f"{'ISO 230-2' if default else block['standard']} figure (µm)"
    width = max([32, len(label)] + [len(f["name"]) + 1 for f in figures])
    lines = [f"{label:{width}s} " + " ".join(f"{COLUMNS[key]:>10s}" for key in columns)
             if figures else f"{label}: none from these data"]
    for figure in figures:
        lines.append(f"{figure['name']:{width}s} "
                     + " ".join(_cell(figure, key) for key in columns))
    if rms and "residual_um" in columns:
        lines.append(f"{RMS_LABEL:{width}s} " + " ".join(f"{value:10.4g}" for value in rms))
    lines += _needs_lines(block) + [f"  note: {note}" for note in block.get("notes", [])]
    if block.get("not_confirmed_publicly") and not default:
        lines.append(f"  not confirmed publicly: {block['not_confirmed_publicly']}")
    return lines


def _cell(figure, key):
    value = figure[key]
    if key == "explained":
        return f"{'' if value is None else f'{100 * value:9.1f}%':>10s}"
    return f"{'':>10s}" if value is None else f"{value:10.4g}"


def _needs_lines(block):
    """Each thing the data lack once, with the figures it touches."""
    touched = {}
    for key, items in block.get("needs", {}).items():
        for item in items:
            touched.setdefault(item, []).append(key)
    names = {f.key: f.name for standard in STANDARDS.values()
             if standard.title == block["standard"] for f in standard.figures}
    lines = []
    for item, keys in touched.items():
        shown = [names.get(key, key) for key in keys]
        lines.append(f"  needs: {item} [{', '.join(shown)}]")
    return lines


OVERVIEW = (("accuracy A|P", ("A_um", "P_um")), ("repeat. R|Ps max", ("R_um", "Ps_max_um")),
            ("reversal B|U max", ("B_um", "U_max_um")), ("mean M|Pa", ("M_um", "Pa_um")))


def overview_lines(blocks):
    """The measured headline figures of every positioning standard side by side: accuracy
    (ISO's A, VDI's P), repeatability (R, Ps max), reversal (B, U max) and the range of the
    mean deviations (M, Pa; the same number)."""
    rows = [block for block in blocks.values()
            if block["figures"] and "residual_um" in next(iter(block["figures"].values()))]
    if not rows:
        return []
    width = max(len(block["standard"]) for block in rows) + 1
    lines = [f"{'measured (µm)':{width}s} " + " ".join(f"{label:>17s}" for label, _ in OVERVIEW)]
    for block in rows:
        cells = []
        for _, keys in OVERVIEW:
            found = [block["figures"][key]["measured_um"] for key in keys
                     if key in block["figures"]]
            cells.append(f"{found[0]:17.4g}" if found else f"{'-':>17s}")
        lines.append(f"{block['standard']:{width}s} " + " ".join(cells))
    return lines


def all_lines(blocks):
    """The headline figures side by side, then every standard's block in turn."""
    lines = [""] + overview_lines(blocks)
    for block in blocks.values():
        lines += [""] + standard_lines(block)
    return lines
