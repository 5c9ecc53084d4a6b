"""The motor model: parameters (with units), the model file, and the effect catalogue."""

from pmdcid.model.effects import EFFECTS, Effect
from pmdcid.model.params import Model, Parameter, load_model, save_model
from pmdcid.model.spec import BASE_PARAMS, ParamSpec

__all__ = [
    "BASE_PARAMS", "EFFECTS", "Effect", "Model", "ParamSpec", "Parameter", "load_model",
    "save_model",
]
