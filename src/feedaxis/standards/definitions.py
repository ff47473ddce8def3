"""The standards, each a small definition over the engine's per-target statistics: its
formulas, its figures with their clauses, what it asks of the test, and what of it could
and could not be confirmed from public sources (docs/standards.md holds the table and the
sources).

Symbols (µm), per target i: x̄_i↑, x̄_i↓ the mean deviations approaching in + and -,
s_i↑, s_i↓ their sample standard deviations (n - 1), k the coverage factor.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..iso230 import FIGURE_NAMES, figures_of_sides

ISO_TERMS = "clause 3, terms and definitions"
ISO_CLAUSES = {  # figure key: the term of ISO 230-2 (1997, 2006, 2014 editions) defining it
    "A_um": "bidirectional accuracy of positioning of an axis, A",
    "E_um": "bidirectional systematic positional deviation of an axis, E",
    "M_um": "range of the mean bidirectional positional deviation of an axis, M",
    "R_um": "bidirectional repeatability of positioning of an axis, R",
    "B_um": "reversal value of an axis, B",
    "B_mean_um": "mean reversal value of an axis, B̄",
    "E_up_um": "unidirectional systematic positional deviation of an axis, E↑",
    "E_down_um": "unidirectional systematic positional deviation of an axis, E↓",
    "R_up_um": "unidirectional repeatability of positioning of an axis, R↑",
    "R_down_um": "unidirectional repeatability of positioning of an axis, R↓",
    "A_up_um": "unidirectional accuracy of positioning of an axis, A↑",
    "A_down_um": "unidirectional accuracy of positioning of an axis, A↓",
}
REPEATED = {"A_um", "R_um", "R_up_um", "R_down_um", "A_up_um", "A_down_um"}
BIDIRECTIONAL = {"A_um", "E_um", "M_um", "R_um", "B_um", "B_mean_um"}


@dataclass(frozen=True)
class Figure:
    """One figure of a standard: key (as ``compare --json`` keys it), name, the clause
    defining it, whether it needs both directions, repeated runs, or one side."""

    key: str
    name: str
    clause: str
    bidirectional: bool = False
    repeats: bool = False
    side: str | None = None


@dataclass(frozen=True)
class Standard:
    """A standard's definition: what the engine needs to give its figures and to say what
    the data lack, and the provenance of both."""

    name: str
    title: str
    figures: tuple
    formulas: object
    coverage: float | None
    runs: int
    runs_clause: str
    bidirectional: bool = True
    targets_per_m: float = 0.0
    min_targets: int = 0
    rule_travel_m: float = 2.0  # the target rule holds up to this travel (ISO 230-2: 2 m)
    targets_clause: str = ""
    uneven_spacing: bool = False
    adopts: str | None = None
    confirmed: str = ""
    unconfirmed: str = ""

    def to_json(self):
        return {"name": self.name, "title": self.title, "coverage_factor": self.coverage,
                "runs": self.runs, "adopts": self.adopts,
                "clauses": {f.key: f.clause for f in self.figures},
                "confirmed_publicly": self.confirmed,
                "not_confirmed_publicly": self.unconfirmed}


def _iso_figure(key, title, name=None):
    side = "up" if key.endswith("_up_um") else "down" if key.endswith("_down_um") else None
    return Figure(key, name or FIGURE_NAMES[key], f"{title}, {ISO_TERMS}: '{ISO_CLAUSES[key]}'",
                  key in BIDIRECTIONAL, key in REPEATED, side)


def _iso(coverage):
    """ISO 230-2's formulas with coverage factor ``coverage`` (feedaxis.iso230)."""
    def formulas(targets, sides):
        return figures_of_sides(targets, sides, coverage)
    return formulas


ISO_RUNS = "the standard test cycle: five runs in each direction"
ISO_TARGETS = ("target positions: at least five per metre and five in all over up to 2000 mm, "
               "unevenly spaced")
ISO_FORMULAS = ("the per-target and axis formulas (x̄, s with n - 1, B_i, B, B̄, "
                "R_i = max(2s↑ + 2s↓ + |B_i|, 4s↑, 4s↓), R↑, R↓, E↑, E↓, M, A↑, A↓, A with "
                "±2s) as an independent implementation prints them, reproduced to 0.01 nm "
                "(the ecmc ISO 230-2 test report, github.com/paulscherrerinstitute/ecmccfg, "
                "examples/test/fat_sat/report.md; its bidirectional E and R lines combine "
                "otherwise and are checked against its own per-target table); the 2006 "
                "edition's change from ±3 standard deviations to ±2 standard uncertainties, "
                "computed as standard deviations, and its superseding NMTBA and VDI/DGQ "
                "3441: AMT (amtonline.org, article 133530)")
ISO_UNCONFIRMED = ("the clause texts themselves (sold by ISO; only scope pages are public): "
                   "the figure formulas are cited by term, not by sub-clause number")


def _iso230_2(edition, name=None, adopts=None, title=None, note=""):
    title = title or f"ISO 230-2:{edition}"
    return Standard(
        name or f"iso230-2:{edition}", title,
        tuple(_iso_figure(key, title) for key in FIGURE_NAMES), _iso(2), 2, 5,
        f"{title}, {ISO_RUNS}", targets_per_m=5, min_targets=5,
        targets_clause=f"{title}, {ISO_TARGETS}", uneven_spacing=True, adopts=adopts,
        confirmed=ISO_FORMULAS + note, unconfirmed=ISO_UNCONFIRMED)


ISO_1988_KEYS = ("A_um", "R_up_um", "R_down_um", "A_up_um", "A_down_um", "B_um", "B_mean_um")


def _iso230_2_1988():
    title = "ISO 230-2:1988"
    figures = tuple(_iso_figure(key, title, FIGURE_NAMES[key].replace(
        "accuracy", "accuracy (±3s)").replace("repeatability", "repeatability (6s)"))
        for key in ISO_1988_KEYS)
    return Standard(
        "iso230-2:1988", title, figures, _iso(3), 3, 5, f"{title}, {ISO_RUNS}",
        targets_clause=f"{title}, target positions", adopts=None,
        confirmed="the ±3 standard deviation convention of the standards before the 2006 "
                  "edition (AMT, amtonline.org article 133530)",
        unconfirmed="the 1988 text: which figures it defines. feedaxis gives A↑, A↓, A "
                    "(x̄ ± 3s), R↑, R↓ (6s), B and B̄; E, M and the bidirectional R are not "
                    "given. The ±3s era did know a bidirectional repeatability at a target, "
                    "max(3s↑ + 3s↓ + |B_i|, 6s↑, 6s↓) (JIS B 0182, term 346, as kk.jisw.com "
                    "reproduces it), but that ISO 230-2:1988 defines it is not confirmed")


def vdi3441_formulas(targets, sides):
    """VDI/DGQ 3441 (1977) figures from the per-target statistics (µm): reversal span
    U_i = |x̄_i↑ - x̄_i↓|, positional scatter Ps_i = 6 s̄_i with s̄_i = (s_i↑ + s_i↓)/2,
    x̄_i = (x̄_i↑ + x̄_i↓)/2; positional deviation Pa = max x̄_i - min x̄_i; positional
    uncertainty P = max(x̄_i + (U_i + Ps_i)/2) - min(x̄_i - (U_i + Ps_i)/2); U and Ps
    as their maximum and mean over the targets. Needs both directions; Ps and P repeated
    runs too."""
    if len(sides) < 2 or not np.array_equal(sides["up"][0], sides["down"][0]):
        return {}
    (_, mean_up, std_up, counts_up), (_, mean_down, std_down, counts_down) = (
        sides["up"], sides["down"])
    reversal = np.abs(mean_up - mean_down)
    mean = (mean_up + mean_down) / 2
    figures = {"Pa_um": np.ptp(mean, axis=-1), "U_max_um": np.max(reversal, axis=-1),
               "U_mean_um": np.mean(reversal, axis=-1)}
    if np.all(counts_up > 1) and np.all(counts_down > 1):
        scatter = 3 * (std_up + std_down)
        half = (reversal + scatter) / 2
        figures.update({"P_um": np.max(mean + half, axis=-1) - np.min(mean - half, axis=-1),
                        "Ps_max_um": np.max(scatter, axis=-1),
                        "Ps_mean_um": np.mean(scatter, axis=-1)})
    return {key: float(value) if np.ndim(value) == 0 else value
            for key, value in figures.items()}


def _vdi3441():
    title = "VDI/DGQ 3441:1977"
    clause = f"{title}, the characteristics of positioning accuracy: "
    figures = (
        Figure("P_um", "positional uncertainty P", clause + "'Positionsunsicherheit P'",
               True, True),
        Figure("Pa_um", "positional deviation Pa", clause + "'Positionsabweichung Pa'", True),
        Figure("Ps_max_um", "positional scatter Ps max",
               clause + "'Positionsstreubreite Ps', maximum", True, True),
        Figure("Ps_mean_um", "positional scatter Ps mean",
               clause + "'Positionsstreubreite Ps', mean", True, True),
        Figure("U_max_um", "reversal span U max", clause + "'Umkehrspanne U', maximum", True),
        Figure("U_mean_um", "reversal span U mean", clause + "'Umkehrspanne U', mean", True))
    return Standard(
        "vdi3441", title, figures, vdi3441_formulas, 3, 5,
        f"{title}, five runs in each direction", adopts=None,
        confirmed="the figures' names and that laser software reports P, Ps max, Ps mean, "
                  "Pa, U max, U mean (Keysight E1733A remote interface, analysis results "
                  "VDI_P ... VDI_UMEAN); the ±3 standard deviation convention (AMT, "
                  "amtonline.org article 133530)",
        unconfirmed="the guideline's text (withdrawn, not public): the formulas are as the "
                    "machine-tool literature reproduces them; that s̄_i is the mean of the "
                    "two directions' standard deviations is not confirmed")


UNDEFINED = {  # accepted names whose formulas no public source gave us: what was found
    "asme-b5.54": ("ASME B5.54-2005 (and B5.57-1998, lathes)",
                   "public sources name its linear displacement test (ASME B5.64-2022's "
                   "scope calls its own tests equivalent to those of B5.54, B5.57 and ISO "
                   "230; Klabunde and Schmidt, Modern Machine Shop, compare B5.54-92 with five "
                   "other standards) but none we could read gives its formulas: the coverage "
                   "factor and how the reversal enters could not be confirmed"),
    "nmtba": ("NMTBA (1972), with and without offset",
              "public sources give its title ('Definition and Evaluation of Accuracy and "
              "Repeatability of Numerically Controlled Machine Tools'), its ±3 standard "
              "deviation convention and that ISO 230-2:2006 supersedes it (AMT, "
              "amtonline.org article 133530), not its formulas nor what its offset is"),
    "bsi3800": ("BS 3800", "BS 3800 is the general British test code other machine-tool "
                "specifications refer to (a BS milling-machine specification's catalogue "
                "entry, ndls.org.cn); no public source gives positioning formulas of it (the "
                "British positioning standard the literature compares is BS 4656 Part 16)"),
    "jis-b6330": ("JIS B 6330:1980", "JIS B 6330, the general test code of NC machine "
                  "tools, is cited by JIS B 6333-1986 (kikakurui.com), and JIS B 0182's terms "
                  "define the reversal value at a target (term 342) and, with 3 standard "
                  "deviations, the bidirectional repeatability at a target (term 346); its "
                  "own positioning accuracy, its 7-run repeatability and its lost motion "
                  "could not be confirmed from a public source"),
    "gb10931-89": ("GB 10931-89", "laser software lists it (Keysight E1733A), but no public "
                   "source of its text or formulas was found"),
}


def _adoption(name, title, edition, note):
    return _iso230_2(edition, name=name, adopts=f"ISO 230-2:{edition}", title=title,
                     note=f"; {note}")


STANDARDS = {standard.name: standard for standard in (
    _iso230_2(2014), _iso230_2(2006), _iso230_2(1997), _iso230_2_1988(), _vdi3441(),
    _adoption("jis-b6190-2", "JIS B 6190-2:2008", 2006,
              "JIS B 6190-2 is the Japanese counterpart of ISO 230-2 that the identical "
              "adoption of ISO 3070-2:2016, JIS B 6210-2:2021, cites for its NC positioning "
              "tests (jis.eomec.com); that it adopts ISO 230-2:2006 unchanged is not "
              "confirmed publicly"),
    _adoption("jis-b6192", "JIS B 6192:1999", 1997,
              "adopted as ISO 230-2:1997 (not confirmed publicly): where JIS B 6190-2 "
              "differs, it is by edition only, and the 1997 and 2006 figures are equal"),
    _adoption("gbt17421.2", "GB/T 17421.2-2000", 1997,
              "adopted as ISO 230-2:1997 (its identical adoption is not confirmed "
              "publicly); the edition is listed by laser software (Keysight E1733A)"),
    _adoption("gbt17421.2:2016", "GB/T 17421.2-2016", 2014,
              "the edition (published 2016-04-25, in force 2016-11-01, since replaced) and "
              "its scope, ISO 230-2:2014's (uncertainty annex A, step cycle annex B, "
              "ISO/TR 230-9:2005 annex C): gbstd.com; its identical adoption of ISO "
              "230-2:2014 is not confirmed publicly"))}
DEFAULT = "iso230-2:2014"
THERMAL = "iso230-3"
ALL = "all"
NAMES = tuple(STANDARDS) + tuple(UNDEFINED) + (THERMAL, ALL)
