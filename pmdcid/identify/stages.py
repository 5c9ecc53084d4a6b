"""Running a fit stage on files: read the logs, load the model, fit, update the model atomically.

One function per command (the click layer calls exactly one of these). The model file is created
when missing (its parent folder must exist), only the stage's own parameters change, and it is
written in one atomic rename after the fit succeeded: a failed fit leaves it untouched.

Before anything is written the plausibility gate (:mod:`pmdcid.identify.plausibility`) checks
the logs' units and the fitted time constants; ``force`` turns its refusals into warnings. The
model's read-modify-write holds a lock (:func:`pmdcid.io.outputs.locked`) and re-reads the file
under it: two stages run at once on one model both land their updates.
"""

from __future__ import annotations

import os

from pmdcid.errors import LogError
from pmdcid.identify.plausibility import gate, gate_result
from pmdcid.io import read_logs
from pmdcid.io.outputs import locked
from pmdcid.model import load_model, save_model
from pmdcid.simulate.kernel import bounded_for


def _load(paths, model_path, mapping):
    for p in paths:
        if os.path.exists(p) and os.path.exists(model_path) and os.path.samefile(p, model_path):
            raise LogError(f"the model file would overwrite the input log {p}; choose another -m",
                           model_path)
    model = load_model(model_path, must_exist=False)
    logs = read_logs(paths, mapping, defer=True)
    return logs, model


def _value(model, name, given=None):
    if given is not None:
        return given
    p = model.parameters.get(name)
    return p.value if p is not None else None


def _save(result, model_path, logs, force, pre=None):
    """Apply ``result`` to the model file as it is now (under the lock), gate it, write it."""
    with locked(model_path):
        new = load_model(model_path, must_exist=False)
        if pre is not None:
            pre(new)
        result.apply(new)
        gate_result(new, logs, force)
        save_model(new, model_path)
    return result


def _run(fit, paths, model_path, mapping, force, km=None):
    logs, model = _load(paths, model_path, mapping)
    gate(logs, force, _value(model, "km", km), _value(model, "R"))
    with bounded_for(model_path):
        return logs, fit(logs, model)


def run_fit_electrical(paths, model_path, mapping=None, force=False):
    """``pmdcid fit-electrical``: R, L from blocked-rotor logs into ``model_path``."""
    from pmdcid.identify.electrical import fit_electrical

    logs, res = _run(fit_electrical, paths, model_path, mapping, force)
    return _save(res, model_path, logs, force)


def run_fit_mechanical(paths, model_path, mapping=None, km=None, force=False):
    """``pmdcid fit-mechanical``: b, bv, bc, J from free-speed step logs into ``model_path``."""
    from pmdcid.identify.mechanical import fit_mechanical

    logs, res = _run(lambda lg, m: fit_mechanical(lg, m, km=km), paths, model_path, mapping,
                     force, km)
    return _save(res, model_path, logs, force)


def run_fit_nonlinear(paths, model_path, mapping=None, force=False, **opts):
    """``pmdcid fit-nonlinear``: J, bv, bc, dz (tau0) by simulation error into ``model_path``."""
    from pmdcid.identify.nonlinear import fit_nonlinear

    logs, res = _run(lambda lg, m: fit_nonlinear(lg, m, **opts), paths, model_path, mapping,
                     force)
    return _save(res, model_path, logs, force)


def run_fit_inverse_dynamics(paths, model_path, mapping=None, as_published=False, km=None,
                             force=False):
    """``pmdcid fit-inverse-dynamics``: J, bv, bc, tau0 by inverse-dynamics least squares (the
    torque regressed on filtered acceleration, speed, sign of speed and 1) into ``model_path``.
    ``as_published``: the EMPS authors' IDIM-LS (every row, torque not centred on the ZOH)."""
    from pmdcid.identify.inverse_dynamics import fit_inverse_dynamics

    def fit(logs, model):
        if km is not None:
            model.set("km", km, stage="datasheet")
        opts = {"rest_fraction": 0.0, "centre_zoh": False} if as_published else {}
        return fit_inverse_dynamics(logs, model, **opts)

    def pre(new):
        if km is not None:
            new.set("km", km, stage="datasheet")

    logs, res = _run(fit, paths, model_path, mapping, force, km)
    return _save(res, model_path, logs, force, pre)
