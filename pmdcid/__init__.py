"""pmdcid: non-linear identification of permanent-magnet DC motors from measured logs.

Library use (docs/api.md)::

    import pmdcid
    logs = [pmdcid.Log.from_csv(p) for p in paths]
    res = pmdcid.identify(logs, km=0.05)
    print(res)            # the table; res.model is a pmdcid.Model

Names are imported on first use (module ``__getattr__``), so ``import pmdcid`` and the command
line stay fast. ``pmdcid.identify``, ``pmdcid.diagnose``, ``pmdcid.simulate`` and
``pmdcid.report`` are also subpackages: calling one runs the function of :mod:`pmdcid.api`.

Import order (one way): io -> model -> simulate -> identify -> diagnose -> report -> cli.
"""

__version__ = "0.1.0"

#: public name -> module that defines it (imported on first access)
_LAZY = {
    "Log": "pmdcid.io.logs",
    "Model": "pmdcid.model.params",
    "PmdcidError": "pmdcid.errors",
    "fit_electrical": "pmdcid.api",
    "fit_mechanical": "pmdcid.api",
    "fit_nonlinear": "pmdcid.api",
}
#: callable subpackages (see :mod:`pmdcid._callable`)
_SUBPACKAGES = ("identify", "diagnose", "simulate", "report")

__all__ = ["Log", "Model", "PmdcidError", "diagnose", "fit_electrical", "fit_mechanical",
           "fit_nonlinear", "identify", "report", "simulate"]


def __getattr__(name: str):
    import importlib

    if name in _LAZY:
        value = getattr(importlib.import_module(_LAZY[name]), name)
        globals()[name] = value
        return value
    if name in _SUBPACKAGES:
        return importlib.import_module(f"pmdcid.{name}")
    raise AttributeError(f"module 'pmdcid' has no attribute {name!r}")


def __dir__():
    return sorted(list(globals()) + __all__)
