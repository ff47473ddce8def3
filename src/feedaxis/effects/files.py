"""Model TOML files and user effect files (``--effects FILE.py``)."""
from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path

import numpy as np

from ..errors import InputError, read_text
from .base import FIT_TABLE, Effect, FitRecord, Model
from .catalog import CATALOG

if sys.version_info >= (3, 11):
    import tomllib
else:
    import tomli as tomllib


def load_user_effects(path):
    """Import a Python file and return its effects: module-level :class:`Effect` objects.

    An effect is an instance of an :class:`Effect` subclass or a function wrapped with
    :func:`feedaxis.effects.effect`. Names must not clash with the catalog.
    """
    path = Path(path)
    read_text(path, "effects file")
    spec = importlib.util.spec_from_file_location(f"feedaxis_user_effects_{path.stem}", path)
    module = importlib.util.module_from_spec(spec)
    try:
        spec.loader.exec_module(module)
    except Exception as error:
        raise InputError(f"could not load the effects file: {type(error).__name__}: {error}",
                         path=path) from None
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
        user_effect.prepare = _checked_prepare(user_effect, path)
    return found


def _checked_prepare(user_effect, path):
    """``user_effect.prepare`` held to the contract: one finite error_um per positioning
    sample; a breach or an exception in the user's code is an :class:`InputError` naming
    the file and the effect."""
    prepare = user_effect.prepare

    def checked(case):
        evaluate = _user_call(user_effect, path, prepare, case)
        size = case.positioning.size

        def run(values):
            error_um = np.asarray(_user_call(user_effect, path, evaluate, values))
            if error_um.shape != (size,):
                raise InputError(f"effect {user_effect.name} returned shape {error_um.shape} "
                                 f"for {size} samples; it must return one error_um per "
                                 "positioning sample", path=path)
            if not np.issubdtype(error_um.dtype, np.number) or not np.all(np.isfinite(error_um)):
                raise InputError(f"effect {user_effect.name} returned values that are not "
                                 f"finite numbers with {values}", path=path)
            return error_um.astype(float)

        return run

    return checked


def _user_call(user_effect, path, function, argument):
    try:
        return function(argument)
    except InputError:
        raise
    except Exception as error:
        raise InputError(f"effect {user_effect.name} raised {type(error).__name__}: {error}",
                         path=path) from error


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
    try:
        data = tomllib.loads(read_text(path, "model file"))
    except tomllib.TOMLDecodeError as error:
        raise InputError(f"not valid TOML: {error}", path=path) from None
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
    expected = set(effect.parameter_names)
    for key, value in table.items():
        if key not in expected:
            raise InputError(f"[{effect.name}] has no parameter '{key}'; expected: "
                             f"{', '.join(effect.parameter_names) or 'none'}", path=path,
                             column=f"{effect.name}.{key}")
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise InputError(f"[{effect.name}] {key} must be a finite number, got {value!r}",
                             path=path, column=f"{effect.name}.{key}")
    missing = expected - set(table)
    if missing:
        raise InputError(f"[{effect.name}] lacks {', '.join(sorted(missing))}", path=path,
                         column=effect.name)
    return {key: float(value) for key, value in table.items()}
