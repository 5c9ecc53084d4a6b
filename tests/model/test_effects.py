"""The catalogue is one module per effect (pmdcid/model/effects/): each module holds one
``EFFECT`` named as the module, every such module is registered, in diagnose's search order."""

from __future__ import annotations

import importlib
import pkgutil

import pmdcid.model.effects as effects_pkg
from pmdcid.model.effects import CATALOGUE, EFFECTS

#: diagnose's search order (its screen, ties and summaries follow it)
ORDER = ("back_emf", "stribeck", "quadratic_drag", "torque_offset", "cogging", "sensor_delay",
         "speed_offset", "voltage_saturation", "brush_drop", "viscous_asymmetry",
         "friction_curve", "input_delay", "lugre")


def _effect_modules() -> list[str]:
    out = []
    for info in pkgutil.iter_modules(effects_pkg.__path__):
        mod = importlib.import_module(f"{effects_pkg.__name__}.{info.name}")
        if hasattr(mod, "EFFECT"):
            out.append(info.name)
    return sorted(out)


def test_every_effect_module_is_registered_under_its_own_name():
    assert _effect_modules() == sorted(m.__name__.rsplit(".", 1)[1] for m in CATALOGUE)
    for mod in CATALOGUE:
        assert mod.EFFECT.name == mod.__name__.rsplit(".", 1)[1]
        assert EFFECTS[mod.EFFECT.name] is mod.EFFECT


def test_registration_order_is_the_search_order():
    assert tuple(EFFECTS) == ORDER
