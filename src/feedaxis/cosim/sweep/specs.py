"""What a sweep varies: ``--vary NAME=SPEC`` items and a fitted model's covariance.

A spec names one FMU parameter (``Component.parameter``), or several for a correlated
normal, and how its value is chosen in each trial:

- ``grid(a,b,n)``: n evenly spaced values from a to b; grids combine as a full factorial
  and set their own trial count;
- ``uniform(a,b)``, ``normal(mu,sigma)``, ``truncnormal(mu,sigma,lo,hi)`` (a normal cut to
  [lo, hi]), ``triangular(a,mode,b)``: one draw per trial;
- ``mvnormal([mu1,...],[[c11,...],...])`` with ``A.x,B.y=``: a correlated normal from its
  mean vector and covariance matrix (any positive semi-definite one).

Trial k's values depend only on the seed and k: its random stream is
``SeedSequence(seed, spawn_key=(k, stream))`` (NumPy's independent child streams; one
stream for the ``--vary`` draws, another for a fitted model's), and a normal
vector is mean + F z with F from the covariance's eigen-decomposition, computed once. So a
sweep draws the same values whatever runs it, and every value is drawn and checked before
any trial runs.
"""
from __future__ import annotations

import ast
import math
from dataclasses import dataclass

import numpy as np

from ...errors import InputError

KINDS = {"grid": 3, "uniform": 2, "normal": 2, "truncnormal": 4, "triangular": 3, "mvnormal": 2}
# A covariance's checks, in correlation units (C_ij / (σ_i σ_j)): a fit's is symmetric to
# some 1e-12 there; 1e-6 leaves room for a file written with fewer digits. Its eigenvalues
# (0 to n for a correlation matrix) may be negative by round-off, 1e-12 for a singular fit.
SYMMETRY_TOLERANCE = 1e-6
DEFINITENESS_TOLERANCE = 1e-8
MAX_REDRAWS = 100  # draws of a fitted model's parameters outside their bounds, per trial


VARY_STREAM, MODEL_STREAM = 0, 1  # independent streams of one trial: --vary, --from-model


def trial_rng(seed, trial, stream=VARY_STREAM):
    """The random generator of trial ``trial`` of a sweep seeded with ``seed``: NumPy's child
    stream ``SeedSequence(seed, spawn_key=(trial, stream))``."""
    sequence = np.random.SeedSequence(seed, spawn_key=(trial, stream))
    return np.random.Generator(np.random.PCG64(sequence))


@dataclass(frozen=True)
class Spec:
    """One ``--vary`` item: parameter names, the distribution and its arguments."""

    text: str
    names: tuple
    kind: str
    arguments: tuple

    @property
    def option(self):
        """The item as the user wrote it, for messages."""
        return f"--vary {self.text}"

    @property
    def sampled(self):
        return self.kind != "grid"

    def grid_values(self):
        low, high, count = self.arguments
        return np.linspace(low, high, count)

    def support(self):
        """(lowest, highest) value a trial can take (±inf for a normal), per name."""
        a = self.arguments
        if self.kind == "grid":
            return [(a[0], a[1])]
        if self.kind == "uniform":
            return [(a[0], a[1])]
        if self.kind == "truncnormal":
            return [(a[2], a[3])]
        if self.kind == "triangular":
            return [(a[0], a[2])]
        return [(-math.inf, math.inf)] * len(self.names)

    def draw(self, rng):
        """Values of this spec's names for one trial, from ``rng``."""
        a = self.arguments
        if self.kind == "uniform":
            return (float(rng.uniform(a[0], a[1])),)
        if self.kind == "normal":
            return (float(a[0] + a[1] * rng.standard_normal()),)
        if self.kind == "truncnormal":
            from scipy.stats import truncnorm

            mu, sigma, low, high = a
            return (float(truncnorm.ppf(rng.random(), (low - mu) / sigma, (high - mu) / sigma,
                                        loc=mu, scale=sigma)),)
        if self.kind == "triangular":
            return (float(rng.triangular(a[0], a[1], a[2])),)
        mean, factor = a
        return tuple(float(v) for v in mean + factor @ rng.standard_normal(len(mean)))


def parse_spec(text):
    """A :class:`Spec` from ``NAME=SPEC``; :class:`InputError` naming the item otherwise."""
    option = f"--vary {text}"
    name, sep, rest = text.partition("=")
    names = tuple(n.strip() for n in name.split(","))
    if not sep or not all(n.count(".") == 1 and all(n.split(".")) for n in names):
        raise InputError("expected COMPONENT.PARAMETER=SPEC, e.g. NpidServo.friction_N="
                         "uniform(0,2)", parameter=option)
    rest = rest.strip()
    kind, paren, arguments = rest.partition("(")
    if kind not in KINDS:
        raise InputError(f"unknown distribution {kind!r}; known: "
                         f"{', '.join(f'{k}(...)' for k in KINDS)}", parameter=option)
    if not (paren and arguments.endswith(")")):
        raise InputError(f"expected {kind}(...) with its {KINDS[kind]} arguments",
                         parameter=option)
    try:
        values = ast.literal_eval(f"({arguments[:-1]},)")
    except (ValueError, SyntaxError):
        raise InputError(f"the arguments of {kind} must be numbers (and lists of numbers for "
                         "mvnormal)", parameter=option) from None
    if len(values) != KINDS[kind]:
        raise InputError(f"{kind} takes {KINDS[kind]} arguments, got {len(values)}",
                         parameter=option)
    if kind == "mvnormal":
        return _mvnormal(text, names, values)
    if len(names) != 1:
        raise InputError(f"{kind} varies one parameter; several need mvnormal",
                         parameter=option)
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
               for v in values):
        raise InputError(f"the arguments of {kind} must be finite numbers", parameter=option)
    _check_arguments(kind, values, option)
    values = (*map(float, values[:2]), int(values[2])) if kind == "grid" else \
        tuple(map(float, values))
    return Spec(text, names, kind, values)


def _check_arguments(kind, values, option):
    problem = None
    if kind == "grid":
        low, high, count = values
        if not (isinstance(count, int) and count >= 1):
            problem = f"the count must be a whole number >= 1, got {count}"
        elif high < low or (count == 1 and high != low):
            problem = "needs a <= b (and a = b for one value)"
    elif kind == "uniform" and not values[0] < values[1]:
        problem = f"needs a < b, got {values[0]:g} and {values[1]:g}"
    elif kind in ("normal", "truncnormal") and not values[1] > 0:
        problem = f"sigma must be > 0, got {values[1]:g}"
    elif kind == "truncnormal" and not values[2] < values[3]:
        problem = f"needs lo < hi, got {values[2]:g} and {values[3]:g}"
    elif kind == "triangular" and not values[0] <= values[1] <= values[2] or (
            kind == "triangular" and values[0] == values[2]):
        problem = "needs a <= mode <= b and a < b"
    if problem:
        raise InputError(f"{kind}: {problem}", parameter=option)


def _mvnormal(text, names, values):
    option = f"--vary {text}"
    try:
        mean = np.array(values[0], dtype=float)
        covariance = np.array(values[1], dtype=float)
    except (TypeError, ValueError):
        mean, covariance = np.zeros(0), np.zeros(0)
    size = len(names)
    if mean.shape != (size,) or covariance.shape != (size, size):
        raise InputError(f"mvnormal of {size} parameters needs a mean of {size} numbers and "
                         f"a {size} x {size} covariance", parameter=option)
    factor = normal_factor(covariance, option)
    if not np.all(np.isfinite(mean)):
        raise InputError("the mean must be finite numbers", parameter=option)
    return Spec(text, names, "mvnormal", (mean, factor))


def normal_factor(covariance, where):
    """F with F Fᵀ = covariance (symmetric, positive semi-definite), from its eigenvectors
    and eigenvalues, so it exists for a singular covariance too.

    Both checks are made on the correlation scale, C_ij / (σ_i σ_j), so parameters of any
    units are judged alike: a covariance a fit computed is symmetric to round-off
    (:data:`SYMMETRY_TOLERANCE`; entries zero to round-off, 1e-22, may differ by 1e-5 of
    themselves) and its eigenvalues negative at most by round-off
    (:data:`DEFINITENESS_TOLERANCE`); it is used symmetrised.
    """
    covariance = np.asarray(covariance, dtype=float)
    if not np.all(np.isfinite(covariance)):
        raise InputError("the covariance must be a symmetric matrix of finite numbers",
                         parameter=where)
    sigma = np.sqrt(np.abs(np.diag(covariance)))
    scale = np.outer(sigma, sigma)
    scale[scale == 0.0] = max(float(np.max(np.abs(covariance), initial=0.0)),
                              np.finfo(float).tiny)  # a parameter held: its row is all 0
    asymmetry = np.abs(covariance - covariance.T) / scale
    if np.any(asymmetry > SYMMETRY_TOLERANCE):
        i, j = np.unravel_index(np.argmax(asymmetry), asymmetry.shape)
        raise InputError(f"the covariance must be a symmetric matrix: entries ({i + 1}, "
                         f"{j + 1}) and ({j + 1}, {i + 1}) differ by {asymmetry[i, j]:.3g} "
                         "of σ_i·σ_j", parameter=where)
    covariance = (covariance + covariance.T) / 2
    lowest = np.min(np.linalg.eigvalsh(covariance / scale), initial=0.0)
    if lowest < -DEFINITENESS_TOLERANCE:
        raise InputError(f"the covariance is not positive semi-definite (eigenvalue "
                         f"{lowest:.3g} of its correlation matrix)", parameter=where)
    eigenvalues, eigenvectors = np.linalg.eigh(covariance)
    return eigenvectors * np.sqrt(np.clip(eigenvalues, 0.0, None))


@dataclass(frozen=True)
class Design:
    """The trials of a sweep: which values each takes.

    ``names`` are the varied parameters (columns); trial k takes grid point k // draws (the
    first grid varies slowest) and its sampled values from :func:`trial_rng` (seed, k).
    """

    specs: tuple
    seed: int
    draws: int

    @property
    def grids(self):
        return [s for s in self.specs if not s.sampled]

    @property
    def trials(self):
        return self.draws * math.prod(len(s.grid_values()) for s in self.grids)

    @property
    def names(self):
        return tuple(n for s in self.specs for n in s.names)

    def values(self, trial):
        """{name: value} of trial ``trial``."""
        point, values = trial // self.draws, {}
        for spec in reversed(self.grids):
            grid = spec.grid_values()
            values[spec.names[0]] = float(grid[point % len(grid)])
            point //= len(grid)
        rng = trial_rng(self.seed, trial)
        for spec in self.specs:
            if spec.sampled:
                values.update(zip(spec.names, spec.draw(rng)))
        return {name: values[name] for name in self.names}


def design(texts, trials, seed, drawn_elsewhere=False):
    """The :class:`Design` of ``--vary`` items, ``--trials`` and ``--seed``;
    ``drawn_elsewhere``: something else is drawn in every trial (a fitted model)."""
    specs = tuple(parse_spec(text) for text in texts)
    seen = set()
    for spec in specs:
        twice = seen & set(spec.names)
        if twice:
            raise InputError(f"{sorted(twice)[0]} is varied twice", parameter=spec.option)
        seen |= set(spec.names)
    sampled = drawn_elsewhere or any(s.sampled for s in specs)
    if sampled and trials is None:
        raise InputError("sampled specs need the number of trials", parameter="--trials")
    if not sampled and trials is not None:
        raise InputError("only grids are varied and a grid sets its own count; drop --trials "
                         "or vary something sampled", parameter="--trials")
    if trials is not None and not (isinstance(trials, int) and trials >= 1):
        raise InputError(f"must be a whole number >= 1, got {trials}", parameter="--trials")
    return Design(specs, check_seed(seed), trials or 1)


def check_seed(seed):
    """``seed`` when it is a whole number >= 0 (NumPy's SeedSequence entropy)."""
    if isinstance(seed, bool) or not isinstance(seed, int) or seed < 0:
        raise InputError(f"must be a whole number >= 0, got {seed!r}", parameter="--seed")
    return seed


@dataclass(frozen=True)
class ModelDraws:
    """Parameters of a fitted model drawn from the covariance of its fit (``[fit]``).

    ``keys`` are the drawn ``effect.parameter`` keys; ``held`` maps the undetermined ones,
    held at their fitted values, to why the fit could not determine them. A draw outside
    the effects' bounds is drawn again from the same trial stream (at most
    :data:`MAX_REDRAWS` times): the band is that of the normal cut to the bounds.
    """

    model: object
    keys: tuple
    mean: np.ndarray
    factor: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    held: dict
    seed: int

    def values(self, trial):
        """({key: value}, redraws) of trial ``trial``."""
        rng = trial_rng(self.seed, trial, MODEL_STREAM)
        for redraws in range(MAX_REDRAWS + 1):
            drawn = self.mean + self.factor @ rng.standard_normal(self.mean.size)
            if np.all((drawn >= self.lower) & (drawn <= self.upper)):
                return dict(zip(self.keys, map(float, drawn))), redraws
        raise InputError(f"trial {trial}: {MAX_REDRAWS} draws from the fit's covariance all "
                         "fell outside the effects' bounds; the covariance says little about "
                         "these parameters", parameter="--from-model")

    def model_at(self, values):
        """The model with ``values`` ({effect.parameter: value}) over its fitted values."""
        merged = {name: dict(v) for name, v in self.model.values.items()}
        for key, value in values.items():
            effect, parameter = key.split(".", 1)
            merged[effect][parameter] = value
        return self.model.with_values(merged)


def model_draws(model, seed, hold_undetermined=False, path="--from-model"):
    """The :class:`ModelDraws` of a model loaded with its ``[fit]`` record.

    Raises
    ------
    InputError
        When the model has no fit record, or has undetermined parameters and
        ``hold_undetermined`` is False (their covariance means nothing).
    """
    record = model.record
    if record is None:
        raise InputError("has no [fit] table: write it with `feedaxis fit ... --out` to "
                         "draw its parameters from the fit's covariance", parameter=path)
    if record.undetermined and not hold_undetermined:
        listed = "; ".join(f"{k} ({why})" for k, why in record.undetermined.items())
        raise InputError(f"the fit could not determine {listed}: its covariance says nothing "
                         "about them; add --hold-undetermined to hold them at their fitted "
                         "values", parameter=path)
    keys = tuple(k for k in record.parameters if k not in record.undetermined)
    index = [record.parameters.index(k) for k in keys]
    covariance = record.covariance[np.ix_(index, index)]
    bounds = {f"{e.name}.{p.name}": (p.lower, p.upper) for e in model.effects
              for p in e.parameters}
    mean = np.array([model.values[k.split(".", 1)[0]][k.split(".", 1)[1]] for k in keys],
                    dtype=float)
    return ModelDraws(model, keys, mean, normal_factor(covariance, path),
                      np.array([bounds[k][0] for k in keys], dtype=float),
                      np.array([bounds[k][1] for k in keys], dtype=float),
                      dict(record.undetermined), check_seed(seed))
