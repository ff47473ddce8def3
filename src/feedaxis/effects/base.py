"""Effects and models: the shape every physical effect, built in or the user's own, takes.

An :class:`Effect` names a physical cause of error, the kind of measurement it acts on, its
parameters (unit, bounds), a starting guess from the data, its evaluation at the samples
of a case, and the FMU parameters it maps to. Effects compose into a :class:`Model` with
``+``, as lmfit models do: ``model = LeadError() + Backlash()``. How a model predicts a
case's samples is the measurement's business (:mod:`feedaxis.measurement`).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import tomli_w

from ..errors import InputError, finite_value
from ..fmu_map import neutral_fmu_parameters
from ..stats.linear import Columns

FIT_TABLE = "fit"  # the model file's table holding its FitRecord: no effect may take the name


@dataclass(frozen=True)
class Parameter:
    """One fitted parameter: name with its unit as suffix, bounds, and what it means."""

    name: str
    unit: str
    lower: float
    upper: float
    meaning: str = ""


@dataclass(frozen=True)
class Needs:
    """What an effect needs from a case: CSV columns, axis.toml keys, a duty.csv."""

    columns: tuple = ()
    screw_keys: tuple = ()
    motor_keys: tuple = ()
    duty: bool = False
    both_directions: bool = False


class Effect:
    """A physical effect, neutral as to the kind of measurement: each kind has its own base
    (:class:`feedaxis.effects.positioning.PositioningEffect`,
    :class:`feedaxis.effects.tracking.TrackingEffect`) naming the kind and what it needs
    of the kind's samples.

    Subclasses set ``name``, ``meaning``, ``parameters`` and ``needs`` and implement
    :meth:`prepare`; :meth:`guess`, :meth:`fmu_parameters`, :meth:`evidence` and
    :meth:`wavelength_mm` have sensible defaults. ``linear`` names the parameters the error
    is linear in (error = base + Σ value·column, base and columns set by the others); the fit
    solves for them exactly at each step (variable projection). ``measurement`` is the kind
    of measurement the effect acts on (a registered kind's name, :mod:`feedaxis.kinds`;
    None: any, as a structure's basis); ``additive`` is False for an effect acting inside the measured
    system (the tracking effects set the closed loop's parameters), whose prediction the
    measurement computes from its values and, to take it out, its ``neutral`` values.
    ``probe`` gives, per parameter, a step for a linearised first guess where the fit has no
    better start (the prediction is not separable in it).
    """

    name = "effect"
    meaning = ""
    parameters: tuple = ()
    linear: tuple = ()
    needs = Needs()
    fmu = None
    measurement = None
    additive = True
    probe: dict = {}
    # an effect acting inside the system is screened by one linearised step before it is
    # fitted (diagnose._screened_residual); False: always fitted (a step from far away)
    screened: bool = True
    # an effect always fitted (screened False) that the diagnosis first screens by its score
    # test at its neutral values where the measurement has exact sensitivities
    # (diagnose.SCREEN_ALPHA): fitted only where the screen passes
    score_screened: bool = False
    # effects fitted beside it when the model lacks them (diagnose._joined): a friction
    # inside a loop whose plant was fitted without it shows only with the plant refitted
    fitted_with: tuple = ()
    axis = None  # the machine axis the effect acts on (circular tests), None for one axis

    @property
    def effect(self):
        """The catalog name (the same on every axis of a machine)."""
        return self.name

    def __add__(self, other):
        return Model((self,)) + other

    def __repr__(self):
        return f"<{type(self).__name__} {self.name}>"

    @property
    def parameter_names(self):
        return tuple(p.name for p in self.parameters)

    def unavailable(self, case):
        """Why this effect cannot be used on ``case`` (None when it can): by default, the
        axis.toml keys it needs; a kind's effect base adds what it needs of its samples."""
        missing = (case.axis.missing("screw", self.needs.screw_keys)
                   + case.axis.missing("motor", self.needs.motor_keys))
        if missing:
            return f"needs {', '.join(missing)} in axis.toml"
        return None

    def prepare(self, case):
        """Return ``f(values) -> error_um`` at the samples of its kind in ``case``."""
        raise NotImplementedError

    def prepare_separable(self, case):
        """Return ``f(values, columns_um) -> base_um`` splitting off the ``linear`` parameters.

        The error is ``base_um + columns_um @ [values[p] for p in linear]``, the columns
        written into ``columns_um`` (samples x linear parameters, the fit's own array: no
        copy of them is made beside it); ``values`` of the linear parameters are ignored;
        ``base_um`` None stands for zero. By default built from :meth:`prepare` (one
        evaluation with the linear parameters at 0, one more per linear parameter at 1) at
        every call: :class:`feedaxis.fit.Problem` splits once per value of the nonlinear
        parameters.
        """
        evaluate = self.prepare(case)

        def separate(values, columns_um):
            zero = {**values, **{name: 0.0 for name in self.linear}}
            base_um = evaluate(zero)
            for index, name in enumerate(self.linear):
                np.subtract(evaluate({**zero, name: 1.0}), base_um, out=columns_um[:, index])
            return base_um

        return separate

    def bounds(self, axis):
        """{parameter: (lower, upper)} on this axis; by default the parameters' own bounds."""
        return {p.name: (p.lower, p.upper) for p in self.parameters}

    def guess(self, case, residual_um):
        """Starting values from the data; by default 0 clipped into the bounds."""
        return {p.name: float(np.clip(0.0, p.lower, p.upper)) for p in self.parameters}

    def wavelength_mm(self, axis):
        """Spatial wavelength of a periodic effect (mm), or None."""
        return None

    def fmu_parameters(self, axis, values):
        """{FMU name: {parameter: value}} that make the FMU reproduce this effect."""
        return {}

    def evidence(self, case, values, contribution_um):
        """One line on what in the data points to this effect."""
        return f"explains {np.std(contribution_um):.3g} µm RMS of the residual"


class BasisEffect(Effect):
    """Fixed linear columns (samples x k) added to any measurement's prediction: a
    structure found in the residual or a nuisance (a drift), refitted with the model.
    ``basis`` is the array, or :class:`Columns` that compute it at each use (a drift's two
    columns at 10^7 samples are 160 MB, kept by every fit's model otherwise)."""

    def __init__(self, name, basis):
        self.name, self._basis = name, basis
        count = basis.count if isinstance(basis, Columns) else basis.shape[1]
        self.parameters = tuple(Parameter(f"c{i}_um", "um", -1e6, 1e6) for i in range(count))
        self.linear = self.parameter_names

    @property
    def basis(self):
        """The columns (samples x k)."""
        return self._basis.write() if isinstance(self._basis, Columns) else self._basis

    def unavailable(self, case):
        return None

    def prepare(self, case):
        return lambda v: self.basis @ np.array([v[p.name] for p in self.parameters])

    def prepare_separable(self, case):
        """The basis itself as the columns (no evaluation), a zero base (None)."""
        def separate(values, columns_um):
            if isinstance(self._basis, Columns):
                self._basis.write(columns_um)
            else:
                columns_um[:] = self._basis

        return separate

    def guess(self, case, residual_um):
        coefficients = np.linalg.lstsq(self.basis, residual_um, rcond=None)[0]
        return {p.name: float(c) for p, c in zip(self.parameters, coefficients)}


@dataclass(frozen=True)
class FitRecord:
    """How a model's values were fitted, saved with the model in its ``[fit]`` table.

    ``parameters`` are ``"effect.parameter"`` keys in the order of ``covariance`` (their
    covariance matrix, in the products of their units); ``undetermined`` maps the keys the
    data could not determine to why (their covariance rows mean nothing); ``rms_um`` and
    ``n_points`` describe the residual of the fit; ``artefacts`` what was fitted or left
    out as the measurement's, not the machine's: ``outlier_rows``, ``transient_rows``,
    ``nuisances`` ({name: coefficients (µm)}, e.g. a drift along the test's clock).
    """

    parameters: tuple
    covariance: np.ndarray
    undetermined: dict
    n_points: int
    rms_um: float
    artefacts: dict = field(default_factory=dict)

    def to_table(self):
        """The record as a TOML table (plain lists and numbers)."""
        table = {"parameters": list(self.parameters),
                 "covariance": [[float(v) for v in row] for row in self.covariance],
                 "undetermined": dict(self.undetermined), "n_points": int(self.n_points),
                 "rms_um": float(self.rms_um)}
        return {**table, "artefacts": self.artefacts} if self.artefacts else table

    @classmethod
    def from_table(cls, table, path, model_keys):
        """The record read back from a model file's ``[fit]`` table, checked against the
        model's parameter keys; :class:`InputError` names the file and key otherwise."""
        def bad(message, key):
            return InputError(message, path=path, column=f"{FIT_TABLE}.{key}")

        expected = {"parameters", "covariance", "undetermined", "n_points", "rms_um"}
        unknown = sorted(set(table) - expected - {"artefacts"})
        if unknown:
            raise bad(f"unknown key; expected {', '.join(sorted(expected))} (and artefacts)",
                      unknown[0])
        artefacts = table.get("artefacts", {})
        if not isinstance(artefacts, dict):
            raise bad("must be a table", "artefacts")
        missing = sorted(expected - set(table))
        if missing:
            raise bad("missing", missing[0])
        parameters = table["parameters"]
        if not (isinstance(parameters, list) and all(isinstance(k, str) for k in parameters)
                and sorted(parameters) == sorted(model_keys)):
            raise bad(f"must list the model's parameters: {', '.join(model_keys)}", "parameters")
        size, rows = len(parameters), table["covariance"]
        square = isinstance(rows, list) and len(rows) == size and all(
            isinstance(row, list) and len(row) == size for row in rows)
        try:
            covariance = np.array(rows, dtype=float).reshape(size, size) if square else None
        except (TypeError, ValueError, OverflowError):
            covariance = None
        if covariance is None or not np.all(np.isfinite(covariance)):
            raise bad(f"must be a {size} x {size} matrix of finite numbers", "covariance")
        undetermined = table["undetermined"]
        if not isinstance(undetermined, dict) or not set(undetermined) <= set(parameters):
            raise bad("must map parameters of the model to reasons", "undetermined")
        n_points, rms_um = table["n_points"], table["rms_um"]
        if isinstance(n_points, bool) or not isinstance(n_points, int) or n_points < 1:
            raise bad("must be a positive integer", "n_points")
        try:
            if finite_value(rms_um) < 0:
                raise ValueError
        except ValueError:
            raise bad("must be a finite number >= 0", "rms_um") from None
        return cls(tuple(parameters), covariance, {k: str(v) for k, v in undetermined.items()},
                   n_points, float(rms_um), artefacts)

    def standard_uncertainty(self, key):
        """Standard uncertainty of one parameter (its unit); NaN when undetermined."""
        if key in self.undetermined:
            return float("nan")
        index = self.parameters.index(key)
        return float(np.sqrt(max(self.covariance[index, index], 0.0)))


class Model:
    """An ordered set of effects with their parameter values; add effects with ``+``.

    ``record`` (a :class:`FitRecord`) is how the values were fitted; a model with other
    effects or values has none.
    """

    def __init__(self, effects=(), values=None, record=None):
        self.effects = tuple(effects)
        names = [e.name for e in self.effects]
        duplicated = {n for n in names if names.count(n) > 1}
        if duplicated:
            raise ValueError(f"effect {sorted(duplicated)[0]!r} appears twice in the model")
        self.values = {e.name: dict((values or {}).get(e.name, {})) for e in self.effects}
        self.record = record

    def __add__(self, other):
        if isinstance(other, Effect):
            other = Model((other,))
        return Model(self.effects + other.effects, {**self.values, **other.values})

    def __contains__(self, name):
        return name in self.names

    def __repr__(self):
        return f"<Model {' + '.join(self.names) or '(empty)'}>"

    @property
    def names(self):
        return tuple(e.name for e in self.effects)

    @property
    def parameter_keys(self):
        """``"effect.parameter"`` of every parameter, in the model's order."""
        return tuple(f"{e.name}.{p.name}" for e in self.effects for p in e.parameters)

    def with_values(self, values):
        """A copy with ``values`` ({effect: {parameter: value}}) replacing the current ones."""
        return Model(self.effects, {**self.values, **values})

    def predict_um(self, case):
        """Total modelled deviation (µm) at the case's samples of the kind the model acts on
        (:mod:`feedaxis.measurement`)."""
        return self._measurement(case).predict_um(self)

    def components(self, case):
        """{effect name: its contribution (µm)} at the case's samples of the model's kind."""
        return self._measurement(case).components(self)

    def _measurement(self, case):
        from ..measurement import kinds_for, measurement_of  # SciPy-heavy: when predicting

        return measurement_of(case, kinds_for([case], self)[0])

    def fmu_parameters(self, axis):
        """{FMU name: {parameter: value}} for the co-simulated axis to reproduce the model."""
        parameters = neutral_fmu_parameters(axis)
        for e in self.effects:
            for fmu, values in e.fmu_parameters(axis, self.values[e.name]).items():
                parameters.setdefault(fmu, {}).update(values)
        return parameters

    def with_record(self, record):
        """This model carrying ``record`` (how its values were fitted)."""
        return Model(self.effects, self.values, record)

    def to_toml(self):
        """The model as TOML text: one table per effect holding its parameter values, then
        the ``[fit]`` table of its :class:`FitRecord` when it has one."""
        header = "# feedaxis model: one table per effect, parameter values with units in names\n"
        tables = {name: self.values[name] for name in self.names}
        if self.record is not None:
            tables[FIT_TABLE] = self.record.to_table()
        return header + tomli_w.dumps(tables)
