"""Running a fit stage on files: read the logs, load the model, fit, update the model atomically.

One function per command (the click layer calls exactly one of these). The model file is created
when missing (its parent folder must exist), only the stage's own parameters change, and it is
written in one atomic rename after the fit succeeded: a failed fit leaves it untouched.
"""

from __future__ import annotations

import os

from pmdcid.errors import LogError
from pmdcid.io import read_logs
from pmdcid.model import load_model, save_model


def _load(paths, model_path, mapping):
    for p in paths:
        if os.path.exists(p) and os.path.exists(model_path) and os.path.samefile(p, model_path):
            raise LogError(f"the model file would overwrite the input log {p}; choose another -m",
                           model_path)
    model = load_model(model_path, must_exist=False)
    logs = read_logs(paths, mapping)
    return logs, model


def _save(result, model, model_path):
    new = model.copy()
    result.apply(new)
    save_model(new, model_path)
    return result


def run_fit_electrical(paths, model_path, mapping=None):
    """``pmdcid fit-electrical``: R, L from blocked-rotor logs into ``model_path``."""
    from pmdcid.identify.electrical import fit_electrical

    logs, model = _load(paths, model_path, mapping)
    return _save(fit_electrical(logs, model), model, model_path)


def run_fit_mechanical(paths, model_path, mapping=None, km=None):
    """``pmdcid fit-mechanical``: b, bv, bc, J from free-speed step logs into ``model_path``."""
    from pmdcid.identify.mechanical import fit_mechanical

    logs, model = _load(paths, model_path, mapping)
    return _save(fit_mechanical(logs, model, km=km), model, model_path)


def run_fit_nonlinear(paths, model_path, mapping=None, **opts):
    """``pmdcid fit-nonlinear``: J, bv, bc, dz (tau0) by simulation error into ``model_path``."""
    from pmdcid.identify.nonlinear import fit_nonlinear

    logs, model = _load(paths, model_path, mapping)
    return _save(fit_nonlinear(logs, model, **opts), model, model_path)


def run_fit_inverse_dynamics(paths, model_path, mapping=None, as_published=False, km=None):
    """``pmdcid fit-inverse-dynamics``: J, bv, bc, tau0 by inverse-dynamics least squares (the
    torque regressed on filtered acceleration, speed, sign of speed and 1) into ``model_path``.
    ``as_published``: the EMPS authors' IDIM-LS (every row, torque not centred on the ZOH)."""
    from pmdcid.identify.inverse_dynamics import fit_inverse_dynamics

    logs, model = _load(paths, model_path, mapping)
    if km is not None:
        model.set("km", km, stage="datasheet")
    opts = {"rest_fraction": 0.0, "centre_zoh": False} if as_published else {}
    result = fit_inverse_dynamics(logs, model, **opts)
    new = model.copy()
    result.apply(new)
    save_model(new, model_path)
    return result
