"""Effect catalog, models built from effects, model files and the user's own effects."""
from .base import BasisEffect, Effect, FitRecord, Model, Needs, Parameter
from .catalog import CATALOG
from .files import available_effects, load_model, load_user_effects
from .positioning import FunctionEffect, PositioningEffect, effect

__all__ = ["CATALOG", "BasisEffect", "Effect", "FitRecord", "FunctionEffect", "Model", "Needs", "Parameter",
           "PositioningEffect", "effect",
           "available_effects", "load_model", "load_user_effects"]
