"""Model TOML files and user effect files (``--effects FILE.py``)."""
from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path

from .base import Effect, Model
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
    if not path.is_file():
        raise ValueError(f"{path}: effects file not found")
    spec = importlib.util.spec_from_file_location(f"feedaxis_user_effects_{path.stem}", path)
    module = importlib.util.module_from_spec(spec)
    try:
        spec.loader.exec_module(module)
    except Exception as error:
        raise ValueError(f"{path}: could not load the effects file: "
                         f"{type(error).__name__}: {error}") from None
    found = {value.name: value for value in vars(module).values() if isinstance(value, Effect)}
    if not found:
        raise ValueError(f"{path}: defines no effect (an Effect instance or an @effect function)")
    clash = sorted(set(found) & set(CATALOG))
    if clash:
        raise ValueError(f"{path}: effect name '{clash[0]}' is taken by the catalog")
    return found


def available_effects(effect_files=()):
    """The catalog plus the effects of every user file, by name."""
    effects = dict(CATALOG)
    for path in effect_files:
        effects.update(load_user_effects(path))
    return effects


def load_model(path, effects):
    """Read a model TOML (one table per effect) against the ``effects`` known by name."""
    path = Path(path)
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ValueError(f"{path}: model file not found") from None
    except tomllib.TOMLDecodeError as error:
        raise ValueError(f"{path}: not valid TOML: {error}") from None
    chosen, values = [], {}
    for name, table in data.items():
        if name not in effects or not isinstance(table, dict):
            raise ValueError(f"{path}: unknown effect [{name}]; known: {', '.join(effects)} "
                             "(load your own with --effects FILE.py)")
        chosen.append(effects[name])
        values[name] = _checked_values(path, effects[name], table)
    return Model(chosen, values)


def _checked_values(path, effect, table):
    expected = set(effect.parameter_names)
    for key, value in table.items():
        if key not in expected:
            raise ValueError(f"{path}: [{effect.name}] has no parameter '{key}'; expected: "
                             f"{', '.join(effect.parameter_names) or 'none'}")
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise ValueError(f"{path}: [{effect.name}] {key} must be a finite number, got {value!r}")
    missing = expected - set(table)
    if missing:
        raise ValueError(f"{path}: [{effect.name}] lacks {', '.join(sorted(missing))}")
    return {key: float(value) for key, value in table.items()}
