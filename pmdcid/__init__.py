"""pmdcid: non-linear identification of permanent-magnet DC motors from measured logs.

Library use (docs/api.md)::

    import pmdcid
    logs = [pmdcid.Log.from_csv(p) for p in paths]
    res = pmdcid.identify(logs, km=0.05)
    print(res)            # the table; res.model is a pmdcid.Model

Names are imported on first use (module ``__getattr__``), so ``import pmdcid`` and the command
line stay fast. ``pmdcid.identify``, ``.diagnose``, ``.simulate``, ``.report``, ``.plan`` and
``.export`` are the plain functions of :mod:`pmdcid.api`, although subpackages of the same
names hold the stages (docs/architecture.md, "Front-door names").

Import order (one way): io -> model -> simulate -> identify -> diagnose -> report -> cli.
"""

import sys
import types

__version__ = "0.1.0"

#: public name -> module that defines it (imported on first access)
_LAZY = {
    "Log": "pmdcid.io.logs",
    "Model": "pmdcid.model.params",
    "Note": "pmdcid.notes",
    "PmdcidError": "pmdcid.errors",
    "fit_electrical": "pmdcid.api",
    "fit_mechanical": "pmdcid.api",
    "fit_nonlinear": "pmdcid.api",
}
#: functions of :mod:`pmdcid.api` named as subpackages: the package attribute stays the function
FRONT_DOOR = ("identify", "diagnose", "simulate", "report", "plan", "export")

__all__ = ["Log", "Model", "Note", "PmdcidError", "diagnose", "export", "fit_electrical",
           "fit_mechanical", "fit_nonlinear", "identify", "plan", "report", "simulate"]


class _FrontDoor(types.ModuleType):
    """The class of the ``pmdcid`` module: importing the subpackage ``pmdcid.identify`` makes
    Python bind it as the attribute ``identify`` of ``pmdcid`` (``setattr`` on the parent);
    that one binding is declined, so ``pmdcid.identify`` stays :func:`pmdcid.api.identify`.
    The subpackage stays reachable as ``sys.modules['pmdcid.identify']`` and by every import
    form (``from pmdcid.identify import x``, ``import pmdcid.identify.x as x``)."""

    def __setattr__(self, name, value):
        if name in FRONT_DOOR and isinstance(value, types.ModuleType):
            return  # the subpackage being bound by the import system (class docstring)
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _FrontDoor


def __getattr__(name: str):
    import importlib

    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
    elif name in FRONT_DOOR:
        value = getattr(importlib.import_module("pmdcid.api"), name)
    else:
        raise AttributeError(f"module 'pmdcid' has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))
