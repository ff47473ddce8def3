"""Effect catalog, models built from effects, model files and the user's own effects."""
from .base import BasisEffect, Effect, FitRecord, FunctionEffect, Model, Needs, Parameter, effect
from .catalog import CATALOG
from .files import available_effects, load_model, load_user_effects

__all__ = ["CATALOG", "BasisEffect", "Effect", "FitRecord", "FunctionEffect", "Model", "Needs", "Parameter", "effect",
           "available_effects", "load_model", "load_user_effects"]
