"""What every kind of measurement provides to the fit, the diagnosis and the analysis.

A :class:`Measurement` holds one case's samples of one kind (read from its ``file``), the
measured deviation ``measured_um`` at each, and the answers to what the one fit engine and
the one diagnosis ask: how a model predicts the samples, which noise model the layout of
the samples supports, which shapes of unexplained structure can show in them, and the
figures ``compare`` gives.

A model's prediction is the sum of two parts. *Additive* effects (``Effect.additive``: the
positioning catalog, a user's effect, a structure's basis) add an error at each sample,
``base_um + columns_um @ linear values``. The others act inside the measured system (the
tracking effects set the closed loop's parameters); the kind's :meth:`Measurement.core`
predicts the deviation they give.
"""
from __future__ import annotations

from abc import ABC, abstractmethod
from pathlib import Path

import numpy as np

from ..errors import InputError


# The optional capabilities a kind may declare in ``Measurement.capabilities``, with the
# hooks each one lets it define; without the capability the hooks keep the base's neutral
# answer (no outlier, no nuisance, no shape, no table).
CAPABILITIES = {
    "outliers": ("outliers", "transients"),
    "nuisances": ("nuisances",),
    "shapes": ("shapes", "irregular", "undetermined", "rival"),
    "tables": ("repeatability",),
    "resolution": ("unresolvable",),
    "core": ("core", "check_start"),
    "correlated": ("noise_gram", "confounded"),
    "setup": ("artefacts",),
}



class NoStart(InputError):
    """The samples give no start for a model (a tracking record no plant makes a stable
    loop for): the message says what is missing. ``diagnose`` reports it as an
    ``undetermined`` verdict; a fit or comparison refuses it."""

class Measurement(ABC):
    """One case's samples of one kind: the contract every kind of measurement fulfils.

    A kind must define (abstract): ``kind`` and ``file`` (class attributes), :meth:`read`
    (its file into samples), ``__init__`` taking its samples from a case (through
    :meth:`samples_of`) into ``measured_um`` and ``coordinate``, :attr:`noise`,
    :meth:`subset` and :meth:`figures`. The prediction of a model is this base's
    (:meth:`predictor`: each additive effect's error, plus :meth:`core` when the kind
    declares one). Optional capabilities are named in ``capabilities``
    (:data:`CAPABILITIES`): a kind overriding a hook of a capability it does not name, or
    naming one whose hooks it does not define, is refused when registered
    (:func:`feedaxis.kinds.register`), so no kind inherits another's behaviour by accident.
    Its parts above the fit (``details``, ``views``, ``text``, ``scenarios``,
    ``standards``: the figures of a standard named by ``--standard``) are given as
    callables or values or ``"module:name"`` (:func:`feedaxis.kinds.part`); ``scenarios``
    is a sequence of :class:`feedaxis.cosim.scenarios.base.Scenario` (``feedaxis simulate``
    and ``sweep``), none for a kind with no simulated test.

    ``kind`` is the name effects give in ``Effect.measurement``; ``location_key`` is the
    JSON key placing a structure (``wavelength_mm``, ``frequency_hz``) and
    ``location_unit`` its unit; ``coordinate`` is what the samples are taken along
    (positions, times) and ``coordinate_label`` its axis label; ``reference_label`` names the prediction of a model with no
    effect (the error ladder's first rung); ``stages`` are the diagnosis's stages, over
    which the family-wise error rate is split; ``loose_share``, when set, is the relative
    standard uncertainty beyond which a fitted parameter is reported undetermined.
    """

    kind = ""
    file = ""
    location_key = ""
    location_unit = ""
    coordinate_label = ""
    reference_label = ""
    stages = ()
    loose_share = None
    measured_column = ("", 1.0)
    capabilities = ()
    details = None
    views = None
    text = None
    scenarios = None
    standards = None

    def __init__(self, case):
        self.case = case
        self.measured_um = np.zeros(0)
        self.coordinate = np.zeros(0)

    @classmethod
    def check_contract(cls):
        """Raise TypeError when the kind leaves an abstract method undefined, overrides a
        hook of a capability it does not declare, or declares one it does not define."""
        if getattr(cls, "__abstractmethods__", None):
            raise TypeError(f"kind {cls.__name__} must define "
                            f"{', '.join(sorted(cls.__abstractmethods__))}")
        unknown = set(cls.capabilities) - set(CAPABILITIES)
        if unknown:
            raise TypeError(f"kind {cls.__name__} declares unknown capabilities "
                            f"{sorted(unknown)}; known: {', '.join(CAPABILITIES)}")
        for capability, hooks in CAPABILITIES.items():
            defined = [hook for hook in hooks if _overrides(cls, hook)]
            if capability in cls.capabilities and not defined:
                raise TypeError(f"kind {cls.__name__} declares {capability!r} but defines "
                                f"none of {', '.join(hooks)}")
            if capability not in cls.capabilities and defined:
                raise TypeError(f"kind {cls.__name__} defines {', '.join(defined)} without "
                                f"declaring the capability {capability!r}")

    @classmethod
    @abstractmethod
    def read(cls, folder, axis, duty):
        """The samples of this kind in case ``folder`` (its file, checked row by row against
        ``axis`` and the case's ``duty``), None when the folder holds no such file."""

    @classmethod
    def samples_of(cls, case):
        """This kind's samples in ``case`` (None when it holds none)."""
        return case.samples.get(cls.kind)

    @classmethod
    def holds(cls, case):
        """True when ``case`` holds samples of this kind."""
        return cls.samples_of(case) is not None

    @property
    def size(self):
        return int(self.measured_um.size)

    @property
    def path(self):
        """The samples' file (for messages)."""
        folder = getattr(self.case, "folder", None)
        return Path(folder) / self.file if folder is not None else Path(self.file)

    def __repr__(self):
        return f"<{type(self).__name__} {self.size} samples of {self.path}>"

    # -- model and prediction -----------------------------------------------------------

    def unavailable(self, effect):
        """Why ``effect`` cannot act on these samples (None when it can)."""
        if effect.measurement not in (None, self.kind):
            return f"acts on {effect.measurement}.csv; this diagnosis compares {self.file}"
        return effect.unavailable(self.case)

    def unresolvable(self, effect):
        """Why the samples cannot show ``effect`` apart from the noise even though it can act
        on them (a wavelength the targets alias), None when they can: the diagnosis passes
        over such an effect; a fit asked for it reports its parameters undetermined."""
        return None

    def check(self, model):
        """Raise :class:`InputError` naming the first effect of ``model`` that cannot act
        on these samples."""
        for effect in model.effects:
            reason = self.unavailable(effect)
            if reason:
                raise InputError(f"effect {effect.name} {reason}", path=self.case.folder)

    def excitation(self):
        """Why a parameter the data fix only loosely is so, in the words of what the samples
        are (for ``loose_share``)."""
        return "the measurement does not excite it enough"

    def degenerate(self):
        """Why the samples cannot support any fit beyond their count (None when they can)."""
        return None

    def check_start(self, model, values):
        """Raise :class:`InputError` when ``model`` with ``values``, as a comparison takes
        them or a fit starts from them, cannot describe a working axis; by default every
        value within its effect's bounds can."""

    def core(self, model):
        """``f(values) -> predicted_um`` of the effects that are not additive, or None when
        the model has none (their prediction is 0)."""
        return None

    # Whether a measurement with sensitivities (:meth:`sensitivity`) gives them; False:
    # the fit differences everywhere (the baseline benchmarks/bench_tracking_fit.py and
    # bench_cascade.py time beside them, and the tests' cross-check)
    sensitivities = True

    def sensitivity(self, model):
        """``f(values, slots) -> (core_um, d core_um / d slots)``: the core's prediction
        (:meth:`core`) and its derivatives in the ``(effect, parameter)`` slots of effects
        that are not additive, from one pass (forward-mode sensitivities), or None when the
        measurement has none (the fit then differences). The derivatives are an array of
        their own: the fit negates them in place."""
        return None

    def separable(self, model):
        """``f(values) -> (base_um, columns_um)``: the prediction is ``base_um + columns_um
        @ linear values``, columns in the order ``(effect, parameter) for effect in
        model.effects for parameter in effect.linear``; each call returns new arrays (the
        fit may overwrite them): each effect writes its columns into them as it is split
        (no effect's columns are kept or copied beside them)."""
        core = self.core(model)
        additive = [(e, e.prepare_separable(self.case)) for e in model.effects if e.additive]
        ends = np.cumsum([0] + [len(e.linear) for e, _ in additive])
        size = self.size

        def separate(values):
            base_um = core(values) if core else np.zeros(size)
            owned = core is None  # the core's may be kept by it: added to in a copy
            columns_um = np.empty((size, ends[-1]))
            for (effect, split), start, end in zip(additive, ends[:-1], ends[1:]):
                effect_base_um = split(values[effect.name], columns_um[:, start:end])
                if effect_base_um is not None and owned:
                    base_um += effect_base_um
                elif effect_base_um is not None:
                    base_um, owned = base_um + effect_base_um, True
            return base_um, columns_um

        return separate

    def predictor(self, model):
        """``f(values) -> predicted_um`` with every effect prepared once."""
        core = self.core(model)
        additive = [(e, e.prepare(self.case)) for e in model.effects if e.additive]
        size = self.size

        def predict(values):
            total_um = core(values) if core else np.zeros(size)
            for effect, evaluate in additive:
                total_um = total_um + evaluate(values[effect.name])
            return total_um

        return predict

    def predict_um(self, model):
        """The deviation (µm) ``model`` predicts at the samples, with its own values."""
        return self.predictor(model)(model.values)

    # set by the diagnosis (feedaxis.diagnose.Refitter): refits of these samples with
    # catalog effects added, for hooks that judge a rival with the model refitted
    refitter = None
    # whether those hooks refit what the selection fitted, so the refitter keeps every fit
    # (a fit of a servo loop costs seconds; one of 10^7 positioning samples, whose hooks
    # refit nothing, holds an 80 MB residual)
    refits_selection = False

    def neutral(self, effect):
        """``effect``'s values that switch it off on these samples (its ``neutral``)."""
        return dict(effect.neutral)

    def components(self, model):
        """{effect: its contribution (µm) to the prediction}: an additive effect's error;
        for an effect acting inside the system, the full prediction less the prediction
        with that effect at its neutral values."""
        core = self.core(model)
        full_um = core(model.values) if core else None
        parts = {}
        for effect in model.effects:
            if effect.additive:
                parts[effect.name] = effect.prepare(self.case)(model.values[effect.name])
            else:
                neutral = {**model.values, effect.name: self.neutral(effect)}
                parts[effect.name] = full_um - core(neutral)
        return parts

    # -- fit ------------------------------------------------------------------------------

    def noise_gram(self, jacobian, residual_um, variance):
        """J'ΣJ of a Jacobian block (these samples x parameters) under the noise the
        residual shows: ``variance`` · J'J for white noise (the default); a serially
        correlated measurement widens it (the sandwich covariance's middle)."""
        return variance * (jacobian.T @ jacobian)

    def confounded(self, model, slots, jacobian, residual_um, sigma):
        """{"effect.parameter": why}: fitted parameters the samples cannot separate from a
        measurement artefact the model does not carry (none by default). ``slots`` are the
        (effect, parameter) of the ``jacobian``'s columns (d residual / d parameter at the
        optimum), ``sigma`` the standard uncertainties."""
        return {}

    # -- diagnosis ------------------------------------------------------------------------

    @property
    @abstractmethod
    def noise(self):
        """The noise model the samples support (:mod:`feedaxis.stats.noise`)."""

    def outliers(self, residual_um):
        """Indices (0-based) of samples to keep out as outliers."""
        return np.zeros(0, dtype=int)

    def transients(self, indices):
        """Those of the outlier ``indices`` that follow the motion's start or stop."""
        return np.zeros(0, dtype=int)

    def rows(self, indices):
        """The 1-based data rows of the file (header = row 1) of sample ``indices``."""
        return [int(i) + 2 for i in indices]

    @abstractmethod
    def subset(self, keep):
        """These samples without those where ``keep`` (boolean mask) is False."""

    def nuisances(self):
        """[(name, shape, basis)] fitted with every model before the selection (a drift
        along the test's clock): measurement artefacts, not effects."""
        return []

    def shapes(self, effects):
        """The shapes of unexplained structure to search, for the ``effects`` known."""
        return ()

    def irregular(self, current):
        """A last structure no shape describes (lack of fit beyond the noise), or None:
        (kind, test, fitted_um, evidence)."""
        return None

    def undetermined(self, current, stages):
        """Why the data cannot tell the noise from structure in the residual of ``current``
        (None when they can): the verdict is then ``undetermined``, not ``adequate``."""
        return None

    def recorded_findings(self, left, pending, stages):
        """Effects of ``pending`` these samples cannot show in the deviation but a record
        beside it can (a drive's controller output): [(effect, values, standard
        uncertainties, test, evidence)] of those it names at the policy's level."""
        return []

    def rival(self, effect, left, result):
        """Why ``effect``, significant on top of ``left`` (``result``), is not what the data
        show (None when it is): it would only stand in for a structure of another shape."""
        return None

    def withdrawn(self, final):
        """{name: (why, columns)} of effects named in the selection's ``final`` fit that it
        shows are not what the data show after all, each with the nuisance columns (samples
        x k, or None) fitted in its place (none by default)."""
        return {}

    def artefacts(self, result):
        """What the measurement fitted of its own set-up beside ``result``'s model (a dict
        for ``artefacts`` of ``fit --json``; none by default)."""
        return {}

    def repeatability(self):
        """Repeatability set against the systematic error (a dict for ``--json``), or None."""
        return None

    @abstractmethod
    def figures(self, result):
        """The figures ``compare`` prints for the model of ``result`` (a FitResult on
        these samples), measured against predicted or residual: a dict for ``--json``
        holding ``kind``."""

    def describe(self):
        """One line: the samples (for headers)."""
        return f"{self.size} samples ({self.file})"


def _overrides(cls, name):
    """True when ``cls`` defines ``name`` itself rather than inheriting the base's."""
    return getattr(cls, name) is not getattr(Measurement, name)


def figure_table(title, width, comparison):
    """The figures of ``compare`` measured, residual and explained, then the RMS, the names
    ``width`` wide (the text of a kind whose figures have that shape)."""
    lines = [f"{title:{width}s} {'measured':>10s} {'residual':>10s} {'explained':>10s}"]
    for figure in comparison["figures"].values():
        explained = figure["explained"]
        name = f"{figure['name']} ({figure['center']})" if "center" in figure else \
            figure["name"]
        lines.append(f"{name:{width}s} {figure['measured_um']:10.4g} "
                     f"{figure['residual_um']:10.4g} "
                     f"{'' if explained is None else f'{100 * explained:9.1f}%':>10s}")
    lines.append(f"{'RMS':{width}s} {comparison['rms_measured_um']:10.4g} "
                 f"{comparison['rms_residual_um']:10.4g}")
    return lines


class Shape:
    """A shape of structure the residual may show: ``kind``, ``extra`` parameters it adds,
    how many distinct shapes its search tries (counted in the family-wise correction),
    its basis at the current fit and what it says.

    :meth:`trial` returns a :class:`Trial` or None when the samples cannot show it.
    """

    kind = ""
    extra = 1

    def trials(self, measurement):
        return 1

    def trial(self, measurement, current):
        raise NotImplementedError

    def search_test(self, measurement, current):
        """The family-wise test of the shape's search where it comes before its basis (a
        search whose own statistic decides, such as a periodogram's maximum), so a search
        that cannot pass is not located; None where the basis is needed for the test."""
        return None

    def amplitude_um(self, measurement, fitted_um, location):
        """The size of the structure: half its peak to valley."""
        return float(np.ptp(fitted_um) / 2)

    def describe(self, measurement, trial, fitted_um):
        raise NotImplementedError


class Trial:
    """A shape fitted at the current residual: its ``basis`` (samples x columns), where it
    sits (``location``: a wavelength or frequency, or None), for a search whose
    significance is family-wise over its own trials its ``test``, and ``extra``: more of
    where it sits (a dict of JSON fields, e.g. ``start_s`` and ``end_s`` of a burst)."""

    def __init__(self, basis, location=None, test=None, extra=None):
        self.basis, self.location, self.test, self.extra = basis, location, test, extra
