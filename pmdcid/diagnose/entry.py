"""Diagnose as every entry runs it (the command line through :mod:`pmdcid.files`, the library's
front door, ``identify``): a lumped model's logs seen as torque-driven
(:func:`~pmdcid.simulate.logs_for`), the new model lumped too."""

from __future__ import annotations

from pmdcid.diagnose.loop import diagnose
from pmdcid.model.lumped import is_lumped, mark_lumped
from pmdcid.simulate import logs_for


def diagnose_logs(logs, model, effects=None, **opts):
    """Diagnose ``model`` on ``logs`` (options as :func:`~pmdcid.diagnose.loop.diagnose`); a
    lumped model's result is lumped."""
    res = diagnose(logs_for(logs, model), model, effects=effects, **opts)
    if is_lumped(model):
        mark_lumped(res.model)
    res.fitted_on(logs, model)
    return res


__all__ = ["diagnose_logs"]
