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

Import order (one way): runtime -> io -> model -> simulate -> identify -> diagnose -> report ->
pipeline -> files -> api -> cli (docs/architecture.md).
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
    """The class of the ``pmdcid`` module (docs/architecture.md, "Front-door names").

    Importing the subpackage ``pmdcid.identify`` makes Python bind it as the attribute
    ``identify`` of ``pmdcid`` (``setattr`` on the parent). That binding is declined, so
    ``pmdcid.identify`` stays the plain function :func:`pmdcid.api.identify`; instead the
    function's attribute namespace becomes the subpackage's (a function's ``__dict__`` may be
    any dict, PEP 232), so ``pmdcid.identify.runners``, ``import pmdcid.export as ex;
    ex.PORTED_STATES`` and ``monkeypatch.setattr("pmdcid.simulate.cache.x", ...)`` reach the
    subpackage as before, while the function's own name, signature and docstring stay its own.
    """

    def __setattr__(self, name, value):
        if name in FRONT_DOOR and isinstance(value, types.ModuleType):
            from pmdcid import api

            getattr(api, name).__dict__ = value.__dict__  # the subpackage's namespace
            return
        super().__setattr__(name, value)


sys.modules[__name__].__class__ = _FrontDoor


def __getattr__(name: str):
    import importlib

    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
    elif name in FRONT_DOOR:
        importlib.import_module(f"pmdcid.{name}")  # links the function to its subpackage
        value = getattr(importlib.import_module("pmdcid.api"), name)
    else:
        raise AttributeError(f"module 'pmdcid' has no attribute {name!r}")
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))
