"""Model TOML files and user effect files (``--effects FILE.py``)."""
from __future__ import annotations

import contextlib
import importlib.util
import math
import sys
from pathlib import Path

import numpy as np

from ..case import PHYSICAL_RANGE
from ..errors import InputError, finite_value, read_text, read_toml, shown_value
from ..kinds import kind, kinds
from .base import FIT_TABLE, Effect, FitRecord, Model
from .catalog import CATALOG


def load_user_effects(path):
    """Import a Python file and return its effects: module-level :class:`Effect` objects.

    An effect is an instance of an :class:`Effect` subclass or a function wrapped with
    :func:`feedaxis.effects.effect`. Names must not clash with the catalog; each parameter
    needs finite bounds, lower < upper. The file's code runs with its printing sent to
    stderr (stdout carries ``--json``), and an exception or ``sys.exit`` in it is an
    :class:`InputError` naming the file.
    """
    path = Path(path)
    read_text(path, "effects file")
    if path.suffix != ".py":
        raise InputError("an effects file is Python source ending in .py", path=path)
    spec = importlib.util.spec_from_file_location(f"feedaxis_user_effects_{path.stem}", path)
    module = importlib.util.module_from_spec(spec)
    _user_call(path, "could not load the effects file", spec.loader.exec_module, module)
    found = {value.name: value for value in vars(module).values() if isinstance(value, Effect)}
    if not found:
        raise InputError("defines no effect (an Effect instance or an @effect function)",
                         path=path)
    clash = sorted(set(found) & (set(CATALOG) | {FIT_TABLE}))
    if clash:
        raise InputError(f"effect name '{clash[0]}' is taken by the catalog"
                         if clash[0] in CATALOG else f"effect name '{clash[0]}' is reserved "
                         "for the model file's fit record", path=path)
    for user_effect in found.values():
        if user_effect.measurement not in kinds():
            raise InputError(f"effect {user_effect.name} names no registered kind of "
                             f"measurement ({user_effect.measurement!r}): subclass a kind's "
                             "effect base (feedaxis.effects.PositioningEffect) or use @effect",
                             path=path)
        _check_parameters(path, user_effect)
        user_effect.prepare = _checked_prepare(user_effect, path)
        user_effect.guess = _checked_guess(user_effect, path)
    return found


def _check_parameters(path, user_effect):
    """Each parameter's bounds finite numbers with lower < upper; ``linear`` among them."""
    names = [p.name for p in user_effect.parameters]
    for parameter in user_effect.parameters:
        where = f"effect {user_effect.name}, parameter {parameter.name}"
        try:
            lower, upper = finite_value(parameter.lower), finite_value(parameter.upper)
        except ValueError as problem:
            raise InputError(f"{where}: each bound {problem} (lower {parameter.lower!r}, "
                             f"upper {parameter.upper!r}): the fit searches a finite box",
                             path=path) from None
        if not lower < upper:
            raise InputError(f"{where}: the lower bound {lower:g} must be below the upper "
                             f"{upper:g} (a fixed value belongs in the effect's code)",
                             path=path)
        width = upper - lower
        if not (math.isfinite(width) and width > 1e-12 * max(abs(lower), abs(upper))):
            raise InputError(f"{where}: the bounds {lower:g} to {upper:g} are too "
                             f"{'wide' if not math.isfinite(width) else 'narrow'} for a fit "
                             "to search between them", path=path)
    if len(set(names)) != len(names):
        raise InputError(f"effect {user_effect.name} names a parameter twice", path=path)
    unknown = sorted(set(user_effect.linear) - set(names))
    if unknown:
        raise InputError(f"effect {user_effect.name}: linear names '{unknown[0]}', not one of "
                         f"its parameters ({', '.join(names)})", path=path)


def _checked_prepare(user_effect, path):
    """``user_effect.prepare`` held to the contract: one real error_um per sample of its
    kind, within the ±1e5 µm any axis can err; a breach or an exception in the user's
    code is an :class:`InputError` naming the file and the effect."""
    prepare = user_effect.prepare
    what = f"effect {user_effect.name}"
    low_um, high_um = PHYSICAL_RANGE["error_um"]

    def checked(case):
        evaluate = _user_call(path, what, prepare, case)
        size = kind(user_effect.measurement)(case).size

        def run(values):
            error_um = np.asarray(_user_call(path, what, evaluate, values))
            if error_um.shape != (size,):
                raise InputError(f"{what} returned shape {error_um.shape} for {size} samples; "
                                 f"it must return one error_um per {user_effect.measurement} "
                                 "sample",
                                 path=path)
            if error_um.dtype.kind not in "iuf" or not np.all(np.isfinite(error_um)):
                raise InputError(f"{what} returned values that are not finite real numbers "
                                 f"({error_um.dtype}) with {values}", path=path)
            if np.any((error_um < low_um) | (error_um > high_um)):
                worst = float(error_um[np.argmax(np.abs(error_um))])
                raise InputError(f"{what} returned {worst:g} um with {values}: beyond any "
                                 f"physical axis ({low_um:g} to {high_um:g} um)", path=path)
            return error_um.astype(float)

        return run

    return checked


def _checked_guess(user_effect, path):
    """``user_effect.guess`` held to the contract: a finite number for each parameter."""
    guess = user_effect.guess
    what = f"effect {user_effect.name}"

    def checked(case, residual_um):
        values = _user_call(path, f"{what}'s guess()", guess, case, residual_um)
        expected = set(user_effect.parameter_names)
        if not isinstance(values, dict) or set(values) != expected:
            named = sorted(values) if isinstance(values, dict) else type(values).__name__
            raise InputError(f"{what}'s guess() must return {{parameter: value}} for "
                             f"{', '.join(sorted(expected))}; it returned {named}", path=path)
        try:
            return {name: finite_value(_real(value)) for name, value in values.items()}
        except ValueError as problem:
            raise InputError(f"{what}'s guess(): every value {problem}, got {values}",
                             path=path) from None

    return checked


def _real(value):
    """A real NumPy scalar as a Python number; anything else as it is."""
    return value.item() if isinstance(value, np.generic) and value.dtype.kind in "iuf" else value


def _user_call(path, what, function, *arguments):
    """``function(*arguments)`` of the user's code: its printing goes to stderr, and an
    exception or ``sys.exit`` in it becomes an :class:`InputError` naming the file."""
    try:
        with contextlib.redirect_stdout(sys.stderr):
            return function(*arguments)
    except InputError:
        raise
    except SystemExit as stop:
        raise InputError(f"{what} called sys.exit({stop.code!r}); an effects file must not "
                         "end the program", path=path) from None
    except Exception as error:
        raise InputError(f"{what} raised {type(error).__name__}: {error}", path=path) \
            from error


def available_effects(effect_files=()):
    """The catalog plus the effects of every user file, by name."""
    effects = dict(CATALOG)
    for path in effect_files:
        effects.update(load_user_effects(path))
    return effects


def load_model(path, effects):
    """Read a model TOML (one table per effect, and the optional ``[fit]`` record of how
    its values were fitted) against the ``effects`` known by name."""
    path = Path(path)
    _, data = read_toml(path, "model file")
    record = data.pop(FIT_TABLE, None)
    chosen, values = [], {}
    for name, table in data.items():
        if name not in effects or not isinstance(table, dict):
            raise InputError(f"unknown effect [{name}]; known: {', '.join(effects)} "
                             "(load your own with --effects FILE.py)", path=path, column=name)
        chosen.append(effects[name])
        values[name] = _checked_values(path, effects[name], table)
    model = Model(chosen, values)
    if record is None:
        return model
    if not isinstance(record, dict):
        raise InputError("must be a table (the fit record)", path=path, column=FIT_TABLE)
    return model.with_record(FitRecord.from_table(record, path, model.parameter_keys))


def _checked_values(path, effect, table):
    """{parameter: float} of an effect's table: each a finite number within the parameter's
    bounds (the widest any axis allows: what a fit can return), none missing or unknown."""
    parameters = {p.name: p for p in effect.parameters}
    for key, value in table.items():
        column = f"{effect.name}.{key}"
        if key not in parameters:
            raise InputError(f"[{effect.name}] has no parameter '{key}'; expected: "
                             f"{', '.join(effect.parameter_names) or 'none'}", path=path,
                             column=column)
        try:
            number = finite_value(value)
        except ValueError:
            raise InputError(f"[{effect.name}] {key} must be a finite number, got "
                             f"{shown_value(value)}", path=path, column=column) from None
        lower, upper = parameters[key].lower, parameters[key].upper
        if not lower <= number <= upper:
            raise InputError(f"[{effect.name}] {key} = {number:g} is beyond what the effect "
                             f"allows: {lower:g} to {upper:g}", path=path, column=column)
    missing = set(parameters) - set(table)
    if missing:
        raise InputError(f"[{effect.name}] lacks {', '.join(sorted(missing))}", path=path,
                         column=effect.name)
    return {key: float(value) for key, value in table.items()}
