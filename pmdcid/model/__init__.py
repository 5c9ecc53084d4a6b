"""The motor model: parameters (with units), the model file, and the effect catalogue."""

from pmdcid.model.effects import EFFECTS, Effect, get_effect
from pmdcid.model.params import BASE_PARAMS, Model, Parameter, ParamSpec, load_model, save_model

__all__ = [
    "BASE_PARAMS", "EFFECTS", "Effect", "Model", "ParamSpec", "Parameter", "get_effect",
    "load_model", "save_model",
]
