"""The measurement model of an ISO 230-2 positioning test for the Monte Carlo: what each
input quantity does to the deviations, and the outputs computed from a trial's deviations.

A trial's deviations (µm, every sample k of group g) are

    x*_k = x_k + δ_g - ε·L_k + (θ²/2)·L_k - a·L_k/L_max - d·τ_k
           - [α*·(T* - 20 °C) - α·(T - 20 °C)]·(X_k - X_ref)   (with the 20 °C correction)

- repeatability, from the data (a type A evaluation, JCGM 101 §6.4.9): each (target,
  direction) group of n ≥ 2 readings with standard deviation s_g has its mean uncertain by
  δ_g = s_g/√n · t(n - 1) (drawn as σ* = s_g·sqrt((n-1)/χ²(n-1)), δ = σ*/√n·z); its
  readings move together, so the test's own standard deviations (R, A) stay as measured.
  A target read once takes the pooled standard deviation of the repeated targets, else the
  fitted model's residual (ν = n - p degrees of freedom);
- the budget's errors (:mod:`~feedaxis.uncertainty.budget`): the laser's relative error ε
  over the distance L from its datum (the first target), the cosine error of the beam's
  angle θ, the set-up/Abbe error growing to a over the travel, the environmental drift d
  over the test's time τ (0 to 1: ``time_s``, else the order of the rows, the order the
  laser recorded them), and the correction's temperature T* and coefficient α*.

Outputs: the figures of a standard (:class:`feedaxis.standards.FigureSet` of the trials),
the fitted model's parameters and the compensation table's values at its points. The
parameters are the fit's linearisation θ* = θ̂ + J⁺(x* - x) (J the model's Jacobian, J⁺ its
least-squares pseudo-inverse): exact for parameters the model is linear in, and checked
against refits on a few trials (:meth:`PositioningMeasurement.linearisation_check`). The
table from a model follows its parameters (θ* - θ̂ through the table's own derivative); a
table of measured means is linear in the trials' means.
"""
from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np
from scipy import sparse

from ..comptable import default_spacing_mm, from_measurement, from_model, grid_mm
from ..fit import SINGULAR_RATIO, fit
from ..compensate import visits
from ..iso230 import per_target, target_clusters, target_groups
from ..standards import FigureSet
from .budget import CONTRIBUTIONS

REPEATABILITY = "repeatability"
LINEARISATION_TOLERANCE = 0.1  # refit - linearisation within 0.1 standard uncertainty
MAX_TABLE_TARGETS = 101  # a measured-means table at more targets goes on a grid
FINITE_STEP = 1e-3  # finite-difference step, in standard uncertainties of the parameter


@dataclass(frozen=True)
class Repeatability:
    """The data's repeatability: each sample's group, the groups' means, standard
    deviations and sizes, and the pooled standard deviation (and its degrees of freedom)
    for groups read once (None when nothing estimates it)."""

    group: np.ndarray
    mean_um: np.ndarray
    std_um: np.ndarray
    counts: np.ndarray
    pooled_um: float | None
    pooled_dof: int
    source: str

    @classmethod
    def of(cls, positioning, fitted=None):
        group = target_groups(positioning)
        counts = np.bincount(group)
        mean = np.bincount(group, positioning.error_um) / counts
        squares = np.bincount(group, (positioning.error_um - mean[group]) ** 2)
        with np.errstate(invalid="ignore", divide="ignore"):
            std = np.where(counts > 1, np.sqrt(squares / (counts - 1)), 0.0)
        dof = int(np.sum(counts - 1))
        if dof > 0:
            pooled, source = float(np.sqrt(np.sum(squares) / dof)), "the repeated readings"
        elif fitted is not None and fitted.statistics.n_points > fitted.statistics.n_free:
            stats = fitted.statistics
            dof = stats.n_points - stats.n_free
            pooled = stats.rms_um * np.sqrt(stats.n_points / dof)
            source = "the fitted model's residual (one reading per target)"
        else:
            pooled, source = None, "none: one reading per target and no model to estimate it"
        return cls(group, mean, std, counts, pooled, dof, source)

    @property
    def available(self):
        return self.pooled_um is not None

    @property
    def dof(self):
        """The fewest degrees of freedom ν of a t distribution the draws use: n - 1 of the
        smallest repeated group, or the pooled ν for groups read once."""
        repeated = self.counts > 1
        dofs = [*(self.counts[repeated] - 1), *([self.pooled_dof] if not repeated.all() else [])]
        return int(min(dofs))

    @property
    def moments(self):
        """Which moments the outputs have (JCGM 101 §6.4.9: a t distribution with ν degrees
        of freedom has a mean for ν > 1 and a variance for ν > 2): the subset of
        ("mean", "standard_uncertainty") that exists."""
        if not self.available:
            return ("mean", "standard_uncertainty")
        return tuple(name for name, least in (("mean", 2), ("standard_uncertainty", 3))
                     if self.dof >= least)

    def draw(self, rng, trials):
        """The trials' shifts (trials, samples) of each group's readings: its mean's
        uncertainty, s_g·sqrt((n-1)/χ²(n-1))/sqrt(n)·z (the t-distribution of JCGM 101
        §6.4.9), one pooled σ* per trial for the groups read once."""
        repeated = self.counts > 1
        sigma = np.empty((trials, self.counts.size))
        if repeated.any():
            dof = self.counts[repeated] - 1
            sigma[:, repeated] = self.std_um[repeated] * np.sqrt(
                dof / rng.chisquare(dof, (trials, dof.size)))
        if not repeated.all():
            sigma[:, ~repeated] = self.pooled_um * np.sqrt(
                self.pooled_dof / rng.chisquare(self.pooled_dof, (trials, 1)))
        shift = sigma / np.sqrt(self.counts) * rng.standard_normal(sigma.shape)
        return shift[:, self.group]


@dataclass(frozen=True)
class ReadingNoise:
    """Each reading's own repeatability, for a thermal test (ISO 230-3), whose targets are
    read again and again while they drift: a drift is a reading less the target's first,
    so what moves a target's readings together cancels, and each reading's scatter is what
    its figures are uncertain by.

    The drift can change faster than the targets are revisited (a duty switching on and
    off), so the scatter is estimated across the targets of a run, not along its time: the
    change z_i = y_i(v+1) - y_i(v) of target i's reading between two successive runs
    (disjoint pairs of runs) leaves out the static errors, and its second divided
    difference over three adjacent targets (disjoint triples, x_0 < x_1 < x_2), d = Σ c_j
    z_j with c_j = 1/Π_{k≠j}(x_j - x_k), is zero for a drift change linear over the three
    targets and has Var d = 2σ²·Σ c_j² from the noise of the six readings; σ² is the mean
    of d²/(2 Σ c_j²) over the m such (triple, pair), ν = m degrees of freedom. What of the
    drift's change is not linear over three targets adds to σ: the estimate errs on the
    large side."""

    sigma_um: float | None
    dof: int
    size: int
    source: str

    @classmethod
    def of(cls, positioning):
        visit = visits(positioning)[0]
        centres_mm, cluster = target_clusters(positioning.target_mm)
        triples = np.arange(centres_mm.size // 3 * 3).reshape(-1, 3)
        apart = centres_mm[triples][:, :, None] - centres_mm[triples][:, None, :]
        apart[:, np.arange(3), np.arange(3)] = 1.0
        weights = 1.0 / np.prod(apart, axis=2)  # (triples, 3)
        scaled = []
        for sign in (1.0, -1.0):
            chosen = positioning.direction == sign
            grid = np.full((centres_mm.size, visit.max() + 1), np.nan)
            grid[cluster[chosen], visit[chosen]] = positioning.error_um[chosen]
            pairs = grid.shape[1] // 2
            change = grid[:, 1:2 * pairs:2] - grid[:, 0:2 * pairs:2]  # (targets, pairs)
            difference = np.einsum("tj,tjp->tp", weights, change[triples])
            found = difference[np.isfinite(difference)]
            scaled.append(found ** 2 / (2 * np.sum(weights ** 2, axis=1)[
                np.nonzero(np.isfinite(difference))[0]]))
        scaled = np.concatenate(scaled)
        if scaled.size == 0:
            return cls(None, 0, positioning.size, "none: no three adjacent targets read in "
                                                  "two successive runs")
        return cls(float(np.sqrt(np.mean(scaled))), int(scaled.size), positioning.size,
                   f"each reading's scatter about a drift change linear over three adjacent "
                   f"targets between two successive runs ({scaled.size} disjoint groups)")

    @property
    def available(self):
        return self.sigma_um is not None

    @property
    def moments(self):
        """The moments the outputs have: a t distribution with ν degrees of freedom has a
        mean for ν > 1 and a variance for ν > 2 (JCGM 101 §6.4.9)."""
        if not self.available:
            return ("mean", "standard_uncertainty")
        return tuple(name for name, least in (("mean", 2), ("standard_uncertainty", 3))
                     if self.dof >= least)

    def draw(self, rng, trials):
        """The trials' noise (trials, readings): one σ* = σ·sqrt(ν/χ²(ν)) per trial (the
        uncertainty of σ itself), then an independent σ*·z at every reading."""
        sigma = self.sigma_um * np.sqrt(self.dof / rng.chisquare(self.dof, (trials, 1)))
        return sigma * rng.standard_normal((trials, self.size))


class PositioningMeasurement:
    """The Monte Carlo model of one positioning case (:meth:`sample`), its input quantities
    (:attr:`inputs`) and outputs, with the fitted model (a :class:`~feedaxis.fit.FitResult`
    on the case, optional) and the 20 °C correction (optional)."""

    def __init__(self, case, budget, correction=None, fitted=None, outputs=None):
        positioning = case.positioning
        self.case, self.correction, self.fitted = case, correction, fitted
        self.outputs = outputs or FigureSet()
        self.target_mm, self.direction = positioning.target_mm, positioning.direction
        self.deviation_um = positioning.error_um
        self.expansion_um = correction.expansion_um(self.target_mm) if correction else 0.0
        self.distance_mm = self.target_mm - self.target_mm.min()
        self.span_mm = max(float(np.ptp(self.target_mm)), 1e-12)
        order = (positioning.time_s if positioning.time_s is not None
                 else np.arange(positioning.size, dtype=float))
        self.elapsed = (order - order.min()) / max(float(np.ptp(order)), 1e-12)
        self.repeatability = (ReadingNoise.of(positioning)
                              if getattr(self.outputs, "per_reading", False)
                              else Repeatability.of(positioning, fitted))
        self.budget = budget
        self.errors = {name: distribution for name, distribution in budget.distributions.items()
                       if distribution.size > 0
                       and (correction or not CONTRIBUTIONS[name].with_correction_only)}
        self.parameters = _Linearisation(case, fitted) if fitted else None
        self.table = _TableMap(case, fitted, self.parameters)

    @property
    def inputs(self):
        """The input quantities that vary: the repeatability (when the data estimate it)
        and the budget's contributions that apply."""
        return ((REPEATABILITY,) if self.repeatability.available else ()) + tuple(self.errors)

    def figures(self, deviation_um=None):
        """The figures (µm) of :attr:`outputs`' standards (default ISO 230-2:2014) of the
        case's deviations, or of trials'."""
        return self.outputs.of(self.target_mm, self.deviation_um if deviation_um is None
                               else deviation_um, self.direction)

    def trial_deviations(self, streams, trials, active):
        """The trials' deviations (trials, samples), the ``active`` inputs varying."""
        values = np.tile(self.deviation_um, (trials, 1))
        if REPEATABILITY in active:
            values += self.repeatability.draw(streams[REPEATABILITY], trials)
        draw = {name: self.errors[name].sample(streams[name], (trials, 1))
                for name in self.errors if name in active}
        if "device_calibration" in draw:
            values -= draw["device_calibration"] * 1e-3 * self.distance_mm
        if "misalignment" in draw:
            values += 0.5e-9 * np.square(draw["misalignment"]) * self.distance_mm
        if "setup" in draw:
            values -= draw["setup"] * self.distance_mm / self.span_mm
        if "eve" in draw:
            values -= draw["eve"] * self.elapsed
        return values - self._correction_change_um(draw)

    def _correction_change_um(self, draw):
        """How much more the trials' 20 °C correction removes than the case's: the screw's
        expansion at the trials' temperature and expansion coefficient, less the nominal."""
        if not {"machine_temperature", "expansion_coefficient"} & set(draw):
            return 0.0
        alpha = self.correction.expansion_per_K + draw.get("expansion_coefficient", 0.0)
        return self.correction.expansion_um(self.target_mm, alpha, draw.get(
            "machine_temperature", 0.0)) - self.expansion_um

    def sample(self, streams, trials, active, skip=frozenset()):
        """{output: values (trials, ...)}: every figure, and the parameters and the table
        when the case has them (the table not when ``skip`` holds ``"table_um"``)."""
        deviation_um = self.trial_deviations(streams, trials, active)
        outputs = self.figures(deviation_um)
        if self.parameters:
            outputs["parameters"] = self.parameters.of(deviation_um - self.deviation_um)
        if "table_um" not in skip:
            outputs.update(self.table.of(deviation_um, outputs.get("parameters")))
        return outputs

    def linearisation_check(self, deviation_um, linear_parameters, parameter_u):
        """Refit the model on each trial of ``deviation_um`` (trials, samples) and compare
        with the linearised parameters: the largest |refit - linear| in standard
        uncertainties (NaN when the model has no determined parameter)."""
        determined = self.parameters.determined & (parameter_u > 0)
        if not determined.any():
            return float("nan")
        worst = 0.0
        for values, linear in zip(deviation_um, linear_parameters):
            vector = self.parameters.vector(self.refit(values).values)
            worst = max(worst, float(np.max(np.abs(vector - linear)[determined]
                                            / parameter_u[determined])))
        return worst

    def refit(self, deviation_um):
        """The model refitted on the case with the deviations ``deviation_um``."""
        case = self.case.with_samples("positioning", replace(self.case.positioning,
                                                             error_um=deviation_um))
        return fit(self.fitted.model, case, kind="positioning").model

    def refit_sample(self, streams, trials, active, skip=frozenset()):
        """{"parameters", "table_um"} of the model refitted on each trial (the check's
        fallback where the model is not linear enough over the trials' spread)."""
        models = [self.refit(values) for values in self.trial_deviations(streams, trials,
                                                                         active)]
        outputs = {"parameters": np.array([self.parameters.vector(m.values) for m in models])}
        if self.table.included:
            outputs["table_um"] = np.array([self.table.of_model(m) for m in models])
        return outputs


class _Linearisation:
    """The fit's parameters as a linear map of the deviations: θ* = θ̂ + P·(x* - x) with
    P = J⁺, the least-squares pseudo-inverse of the model's Jacobian J (columns scaled to
    unit length, directions below the fit's singular ratio left out, as the fit treats
    them). The fit record gives the parameters' order, their own standard uncertainties
    and the undetermined ones."""

    def __init__(self, case, fitted):
        model = fitted.model
        record = fitted.fitted_model().record
        self.model, self.keys = model, list(record.parameters)
        self.estimate = self.vector(model.values)
        self.gum_u = np.sqrt(np.maximum(np.diag(record.covariance), 0.0))
        self.steps = np.where(self.gum_u > 0, FINITE_STEP * self.gum_u,
                              1e-6 * np.maximum(1.0, np.abs(self.estimate)))
        jacobian = self.derivative(lambda m: m.predict_um(case))
        scale = np.linalg.norm(jacobian, axis=0)
        scale[scale == 0.0] = 1.0
        self.slope = np.linalg.pinv(jacobian / scale, SINGULAR_RATIO) / scale[:, None]
        self.determined = np.array([key not in record.undetermined for key in self.keys])
        self.undetermined = dict(record.undetermined)

    def vector(self, values):
        """The parameters of ``values`` ({effect: {parameter: value}}) in the record's order."""
        return np.array([values[k.split(".", 1)[0]][k.split(".", 1)[1]] for k in self.keys])

    def model_at(self, vector):
        values = {name: {} for name in self.model.names}
        for key, value in zip(self.keys, vector):
            effect, parameter = key.split(".", 1)
            values[effect][parameter] = float(value)
        return self.model.with_values(values)

    def derivative(self, evaluate):
        """∂ evaluate(model) / ∂θ by central differences, one column per parameter."""
        columns = []
        for index, step in enumerate(self.steps):
            shift = np.zeros(self.estimate.size)
            shift[index] = step
            columns.append((np.asarray(evaluate(self.model_at(self.estimate + shift)))
                            - np.asarray(evaluate(self.model_at(self.estimate - shift))))
                           / (2 * step))
        return np.stack(columns, axis=-1)

    def of(self, change_um):
        """The trials' parameters (trials, p) for deviations changed by ``change_um``."""
        return self.estimate + change_um @ self.slope.T


class _TableMap:
    """The compensation table of the case as the trials move it: from the fitted model
    (points every lead / 8 over the targets, as the report shows it), or without a model
    the measured means at the targets (on a grid of at most :data:`MAX_TABLE_TARGETS`
    points for a dense scan). ``values_um`` (points, 2) are its + and - values."""

    def __init__(self, case, fitted, parameters):
        target_mm = case.positioning.target_mm
        self.case, self.parameters = case, parameters
        if fitted is not None:
            self.position_mm = grid_mm(target_mm.min(), target_mm.max(),
                                       default_spacing_mm(case, None))
            table = from_model(case, fitted.model, self.position_mm)
            self.source, self.included = "model", table.included
            if not table.included:
                return
            self.derivative = parameters.derivative(self.of_model).reshape(
                -1, parameters.estimate.size)
        else:
            self.position_mm = target_clusters(target_mm)[0]
            if self.position_mm.size > MAX_TABLE_TARGETS:
                self.position_mm = grid_mm(target_mm.min(), target_mm.max(),
                                           default_spacing_mm(case, MAX_TABLE_TARGETS))
            self.target_mm, self.direction = target_mm, case.positioning.direction
            table = from_measurement(case, self.position_mm)
            self.source, self.included = "measurement", table.included
            self.sides = [sign for sign in (1.0, -1.0)
                          if np.any(case.positioning.direction == sign)]
            self.means_map = self._means_map(case)
        self.values_um = self._values(table)

    def of_model(self, model):
        """The table's values (points, 2) of ``model``."""
        return self._values(from_model(self.case, model, self.position_mm))

    @property
    def size(self):
        """Values of the table (points × 2), 0 without one."""
        return self.values_um.size if self.included else 0

    @staticmethod
    def _values(table):
        return np.stack((table.forward_um, table.reverse_um), axis=-1)

    def _means_map(self, case):
        """The table's values per unit change of each (direction, target) mean, a sparse
        (means, points·2) matrix: the measured-means table is linear in the means (each
        point interpolates between two), so probing them one at a time gives the map."""
        positioning = case.positioning
        _, cluster = target_clusters(positioning.target_mm)
        columns = []
        for sign in self.sides:
            for target in np.unique(cluster[positioning.direction == sign]):
                probe = ((positioning.direction == sign) & (cluster == target)).astype(float)
                probed = case.with_samples("positioning", replace(positioning, error_um=probe))
                columns.append(self._values(from_measurement(probed, self.position_mm)).ravel())
        return sparse.csr_matrix(np.array(columns))

    def of(self, deviation_um, parameters):
        """{"table_um": the trials' table values (trials, points, 2)}, or {} without one."""
        if not self.included:
            return {}
        if self.source == "model":
            change = (parameters - self.parameters.estimate) @ self.derivative.T
            return {"table_um": self.values_um + change.reshape(-1, *self.values_um.shape)}
        means = np.concatenate([per_target(self.target_mm, deviation_um, self.direction,
                                           sign)[1] for sign in self.sides], axis=-1)
        table_um = (self.means_map.T @ means.T).T
        return {"table_um": table_um.reshape(means.shape[0], *self.values_um.shape)}
