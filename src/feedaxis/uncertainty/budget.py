"""The uncertainty budget of an ISO 230-2 positioning test, in the structure of
ISO 230-2:2014 Annex A and ISO/TR 230-9: one table per contribution, each a distribution
(:mod:`~feedaxis.uncertainty.distributions`) of an input quantity with its unit in the key.

```toml
[device_calibration]            # the laser and its air compensation, per unit length
distribution = "normal"
expanded_ppm = 0.5              # U from the calibration certificate ...
coverage_factor = 2             # ... and its k
source = "certificate 1234"     # optional free text, printed with the results
```

A file gives only the contributions it changes; the others keep their defaults
(:data:`CONTRIBUTIONS`, with their sources). The repeatability at the targets is not a
budget entry: it comes from the case's own runs.
"""
from __future__ import annotations

from dataclasses import dataclass, field

from ..errors import InputError, finite_value, read_toml, shown_value, toml_key_line
from .distributions import BOUNDED, DISTRIBUTIONS, Distribution

HP_5528A = ("HP 5528A Laser Measurement System User's Guide, 'Distance Measurement Error "
            "Sources' and 'Error Budget Worksheet', pp. 6-24 to 6-28")


@dataclass(frozen=True)
class Contribution:
    """One budget entry: its input quantity (unit of its size keys), what it does to the
    measured deviations, when it applies, its default and the default's source."""

    name: str
    unit: str
    meaning: str
    default: Distribution
    source: str
    largest: float
    with_correction_only: bool = False


CONTRIBUTIONS = {c.name: c for c in (
    Contribution(
        "device_calibration", "ppm",
        "relative error of the laser's length reading (wavelength, air compensation): "
        "ε·L at a distance L from the laser's datum",
        Distribution("rectangular", 1.6),
        f"±1.5 ppm velocity-of-light compensation by the air sensor plus ±0.1 ppm of the "
        f"laser itself ({HP_5528A}); use your laser's calibration certificate",
        largest=1e3),
    Contribution(
        "machine_temperature", "K",
        "error of the machine (material) temperature used to correct to 20 °C: "
        "α·δT·(X - X_ref)",
        Distribution("rectangular", 0.1),
        f"±0.10 °C, the HP 10757 material sensor ({HP_5528A})",
        largest=100.0, with_correction_only=True),
    Contribution(
        "expansion_coefficient", "per_K",
        "error of the expansion coefficient used to correct to 20 °C: "
        "δα·(T - 20 °C)·(X - X_ref)",
        Distribution("rectangular", 1.0e-6),
        "±1 µm/(m·K) about the 11.7 µm/(m·K) catalogued for steel (HP 5528A manual, Rong et al. 2023 "
        "Table 1): the spread among carbon and alloy steels (an engineering judgement; use "
        "the machine builder's value)",
        largest=1e-3, with_correction_only=True),
    Contribution(
        "misalignment", "urad",
        "angle θ between the laser beam and the axis: the laser reads L·cos θ, a cosine "
        "error -L·θ²/2 at a distance L from its datum (always short)",
        Distribution("rectangular", 100.0),
        f"the beam held on the target within ±0.1 mm over 1 m of travel (±100 µrad; an "
        f"alignment judgement, the cosine error as in {HP_5528A})",
        largest=1e4),
    Contribution(
        "setup", "um",
        "set-up and Abbe offset: the offset between the laser beam and the functional point "
        "times the axis's angular motion, an error growing along the travel to the given "
        "size at its end",
        Distribution("rectangular", 0.1),
        "10 mm Abbe offset times 10 µrad of pitch change over the travel (an engineering "
        "judgement; ISO 230-2:2014 Annex A asks for the set-up's own estimate)",
        largest=1e5),
    Contribution(
        "eve", "um",
        "environmental variation error EVE (ISO 230-2 Annex A): the drift of the laser "
        "reading of a standing axis over the test's duration, taken as growing linearly "
        "from 0 at the first reading to its size at the last",
        Distribution("rectangular", 0.2),
        "EVE = 0.2 µm, the laser's air compensation (1 ppm per K, HP 5528A manual p. 6-24) "
        "over a 0.2 m dead-free path in a room drifting 1 K (an engineering judgement; "
        "measure it with the ISO 230-2 EVE test and give its value)",
        largest=1e5),
)}
FROM_THE_DATA = {"repeatability": "the repeatability at the targets comes from the case's own "
                                  "runs (the scatter of each target's readings), not the budget"}
DISTRIBUTION_KEYS = ("distribution", "source")
COVERAGE_FACTORS = (1.0, 10.0)  # a certificate's k: 1 (68 %) to far beyond 3 (99.7 %)


@dataclass(frozen=True)
class Budget:
    """The distribution of every contribution and where it came from (the file and line,
    or the default's source)."""

    distributions: dict
    sources: dict
    path: str | None = None
    notes: dict = field(default_factory=dict)

    def to_json(self):
        return {"file": self.path, "contributions": {
            name: {"distribution": d.kind, "size": d.size,
                   "unit": CONTRIBUTIONS[name].unit,
                   "standard_uncertainty": d.standard_uncertainty,
                   "source": self.sources[name]}
            for name, d in self.distributions.items()}}


def default_budget():
    """Every contribution at its documented default."""
    return Budget({name: c.default for name, c in CONTRIBUTIONS.items()},
                  {name: f"default: {c.source}" for name, c in CONTRIBUTIONS.items()})


def read_budget(path):
    """The budget of the TOML file ``path`` over the defaults.

    Raises
    ------
    InputError
        Naming the file, line and key: an unknown contribution (or the repeatability, which
        comes from the data), an unknown key or distribution, a size that is not a finite
        number >= 0, a table without its size.
    """
    text, data = read_toml(path, "budget file")
    budget = default_budget()
    for name, table in data.items():
        if name in FROM_THE_DATA:
            raise InputError(FROM_THE_DATA[name], path=path, row=toml_key_line(text, name),
                             column=name)
        if name not in CONTRIBUTIONS or not isinstance(table, dict):
            raise InputError(f"unknown contribution; known: {', '.join(CONTRIBUTIONS)}",
                             path=path, row=toml_key_line(text, name), column=name)
        distribution, source = _distribution(path, text, CONTRIBUTIONS[name], table)
        budget.distributions[name] = distribution
        budget.sources[name] = f"{path} [{name}]" + (f": {source}" if source else "")
    return Budget(budget.distributions, budget.sources, str(path))


def _distribution(path, text, contribution, table):
    """(Distribution, source text) of one ``[contribution]`` table."""
    name, unit = contribution.name, contribution.unit
    size_keys = {f"half_width_{unit}": "half-width", f"standard_uncertainty_{unit}": "u",
                 f"expanded_{unit}": "U", "coverage_factor": "k"}

    def bad(message, key=None):
        row = toml_key_line(text, key, name) if key else toml_key_line(text, name)
        return InputError(message, path=path, row=row,
                          column=f"{name}.{key}" if key else name)

    for key, value in table.items():
        if key not in (*DISTRIBUTION_KEYS, *size_keys):
            raise bad(f"unknown key; known: {', '.join((*DISTRIBUTION_KEYS, *size_keys))}",
                      key)
        if key == "source" and not isinstance(value, str):
            raise bad("must be text", key)
        if key in size_keys and not _finite_non_negative(value):
            raise bad(f"must be a finite number >= 0, got {shown_value(value)}", key)
        if key == "coverage_factor" and not COVERAGE_FACTORS[0] <= value <= COVERAGE_FACTORS[1]:
            raise bad(f"must be {COVERAGE_FACTORS[0]:g} to {COVERAGE_FACTORS[1]:g} (a "
                      f"certificate's k, 2 for 95 %), got {shown_value(value)}", key)
    kind = table.get("distribution", contribution.default.kind)
    if kind not in DISTRIBUTIONS:
        raise bad(f"unknown distribution {kind!r}; known: {', '.join(DISTRIBUTIONS)}",
                  "distribution")
    if kind in BOUNDED:
        key = f"half_width_{unit}"
        for other in (f"standard_uncertainty_{unit}", f"expanded_{unit}", "coverage_factor"):
            if other in table:
                raise bad(f"a {kind} distribution takes {key}, not {other}", other)
        if key not in table:
            raise bad(f"a {kind} distribution needs {key}")
        return _within(contribution, kind, float(table[key]), bad, key), table.get("source")
    size, key = _normal_size(table, unit, bad)
    return _within(contribution, kind, size, bad, key), table.get("source")


def _within(contribution, kind, size, bad, key):
    """The distribution of ``size``, refused beyond what the contribution can physically
    be (``contribution.largest``: 1e300 ppm would overflow every deviation)."""
    if not size <= contribution.largest:
        raise bad(f"gives a {'standard uncertainty' if kind == 'normal' else 'half-width'} "
                  f"of {size:.3g} {contribution.unit}, beyond the {contribution.largest:g} "
                  f"{contribution.unit} any {contribution.name} can be", key)
    return Distribution(kind, size)


def _finite_non_negative(value):
    try:
        return finite_value(value) >= 0
    except ValueError:
        return False


def _normal_size(table, unit, bad):
    """(u, the key giving it) of a normal contribution: ``standard_uncertainty_<unit>``, or
    ``expanded_<unit>`` with its ``coverage_factor`` as a certificate states them."""
    standard, expanded = f"standard_uncertainty_{unit}", f"expanded_{unit}"
    if f"half_width_{unit}" in table:
        raise bad(f"a normal distribution takes {standard} or {expanded}, not a half-width",
                  f"half_width_{unit}")
    if standard in table and expanded in table:
        raise bad(f"give {standard} or {expanded}, not both", expanded)
    if standard in table:
        return float(table[standard]), standard
    if expanded not in table:
        raise bad(f"a normal distribution needs {standard} or {expanded} with coverage_factor")
    if not table.get("coverage_factor"):
        raise bad(f"{expanded} needs coverage_factor > 0 (the k of the certificate)", expanded)
    return float(table[expanded]) / float(table["coverage_factor"]), expanded
