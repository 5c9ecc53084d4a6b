"""The library's front door: ``import pmdcid`` then ``pmdcid.identify(...)`` and friends.

Every function takes logs as :class:`~pmdcid.io.Log` objects, paths, or a list of either, and a
model as a :class:`~pmdcid.model.Model`, a path, or None (an empty model); the model given is
never modified (each fit returns a result; ``result.apply(model)`` writes it in). Options are
keyword-only. Each function runs exactly what the matching command runs (the CLI's runners
share these steps: :mod:`pmdcid.identify.runners`, :mod:`pmdcid.diagnose.files`), including the
lumped (per-volt) path for voltage+speed logs.

Results follow one protocol (:class:`~pmdcid.identify.results.ResultProtocol`): ``str()`` is
the table, ``_repr_html_()``, ``to_dict()``, ``to_pandas()``, ``apply(model)``.
"""

from __future__ import annotations

import os


def _logs(logs) -> list:
    from pmdcid.errors import LogError
    from pmdcid.io.logs import Log, read_log

    if isinstance(logs, (Log, str, os.PathLike)):
        logs = [logs]
    out = [lg if isinstance(lg, Log) else read_log(lg) for lg in logs]
    if not out:
        raise LogError("no logs given")
    return out


def _model(model):
    """A working copy of ``model`` (a Model, a model file's path, or None for an empty one)."""
    from pmdcid.model.params import Model, load_model

    if model is None:
        return Model()
    if isinstance(model, (str, os.PathLike)):
        return load_model(model)
    return model.copy()


def identify(logs, model=None, *, km: float | None = None, diagnose: bool = True,
             priors: bool = True, progress=None):
    """A whole rig, as ``pmdcid identify``: sort the logs, run each stage that applies, a joint
    fit, then (``diagnose``) the effect search. ``km`` [N m/A]: the datasheet torque constant;
    ``priors``: later stages combine with earlier estimates. ``progress``: None prints stage
    lines on a terminal's stderr, False is silent, a callable receives each stage's name.
    Returns a :class:`~pmdcid.pipeline.IdentifyResult` (``.model`` is the identified model)."""
    from pmdcid.pipeline import identify as run
    from pmdcid.progress import resolve

    return run(_logs(logs), _model(model), km=km, run_diagnose=diagnose, priors=priors,
               progress=resolve(progress))


def fit_electrical(logs, model=None):
    """R [ohm], L [H] from blocked-rotor logs (``t``, ``v``, ``i``, one step each), as
    ``pmdcid fit-electrical``. Returns an :class:`~pmdcid.identify.electrical.ElectricalResult`."""
    from pmdcid.identify.electrical import fit_electrical as fit
    from pmdcid.identify.runners import lumped_if_wanted, per_volt
    from pmdcid.model.lumped import is_lumped

    logs = _logs(logs)
    work = lumped_if_wanted(logs, _model(model))
    res = fit(logs, work)
    if is_lumped(work):
        per_volt(res)
    return res


def fit_mechanical(logs, model, *, km: float | None = None):
    """b, bv, bc, J from free-speed step logs, as ``pmdcid fit-mechanical`` (per volt when the
    logs carry no current and the model no R). ``km`` [N m/A]: datasheet torque constant.
    Returns a :class:`~pmdcid.identify.mechanical.MechanicalResult`."""
    from pmdcid.identify.runners import lumped_if_wanted, per_volt, stage_mechanical
    from pmdcid.model.lumped import is_lumped

    logs = _logs(logs)
    work = lumped_if_wanted(logs, _model(model))
    res = stage_mechanical(logs, work, km)
    if is_lumped(work):
        per_volt(res)
    return res


def fit_nonlinear(logs, model, *, free=None, signals=None, priors: bool = True):
    """J, bv, bc, dz (tau0 for torque logs) by simulation error, as ``pmdcid fit-nonlinear``.

    ``free``: the parameters to fit (names, e.g. ``["J", "bc"]``; the others are held at the
    model's values); ``signals``: the measured signals in the cost (e.g. ``("omega",)``);
    ``priors``: combine with the estimates earlier stages wrote into the model.
    Returns a :class:`~pmdcid.identify.nonlinear.NonlinearResult`."""
    from pmdcid.identify.runners import lumped_if_wanted, per_volt, stage_nonlinear
    from pmdcid.model.lumped import is_lumped

    logs = _logs(logs)
    work = lumped_if_wanted(logs, _model(model))
    opts = {"priors": priors}
    if free is not None:
        opts["free"] = [free] if isinstance(free, str) else list(free)
    if signals is not None:
        opts["signals"] = (signals,) if isinstance(signals, str) else tuple(signals)
    res = stage_nonlinear(logs, work, **opts)
    if is_lumped(work):
        per_volt(res)
    return res


def diagnose(logs, model, *, effects=None, progress=None):
    """Search the effect catalogue for what ``model`` lacks on ``logs``, as ``pmdcid diagnose``.
    ``effects``: names to search (default all). Returns a
    :class:`~pmdcid.diagnose.loop.DiagnoseResult` (``.model`` has the effects added)."""
    from pmdcid.diagnose.files import diagnose_logs
    from pmdcid.progress import resolve

    effects = [effects] if isinstance(effects, str) else effects
    return diagnose_logs(_logs(logs), _model(model), effects=effects,
                         progress=resolve(progress))


def simulate(log_or_input, model, *, x0=None):
    """Simulate ``model`` on a log's input (a :class:`~pmdcid.io.Log` or a CSV path) from
    ``x0`` = (i [A], omega [rad/s], theta [rad]) at its first sample (default: rest).
    Returns a :class:`~pmdcid.simulate.SimResult` (t, i, omega, theta; ``to_pandas()``)."""
    from pmdcid.simulate import simulate_log

    (log,) = _logs(log_or_input)
    return simulate_log(log, _model(model), x0=x0)


def report(logs, model, out_dir, *, summary=None, before=None, progress=None):
    """The model against measured logs into ``out_dir`` (report.html, metrics.json, figures),
    as ``pmdcid report``. ``summary``: a diagnose summary dict; ``before``: a model to show as
    'before'. Returns a :class:`~pmdcid.report.ReportResult`."""
    from pmdcid.progress import resolve
    from pmdcid.report import make_report

    return make_report(_logs(logs), _model(model), out_dir, summary=summary,
                       before_model=_model(before) if before is not None else None,
                       progress=resolve(progress))


def plan(model=None, out_dir=None, *, vmax: float | None = None, taumax: float | None = None,
         speed_max: float | None = None, rate: float = 1000.0, budget: float = 120.0,
         noise_omega: float | None = None, noise_i: float | None = None):
    """Input profiles to record, as ``pmdcid plan``: for ``model`` (a Model or a model file's
    path), or, with ``model=None``, a first safe experiment (``--guess``: give ``vmax`` [V] or
    ``taumax`` [N m]). ``speed_max`` [rad/s]: the largest speed the motion may reach; ``rate``
    [Hz]: sampling and input hold rate; ``budget`` [s]: total recording time; ``noise_omega``
    [rad/s] and ``noise_i`` [A]: the sensors' noise std (None: defaults). With ``out_dir`` the
    profiles (CSV), plan.json and plan.md are written there. Returns the
    :class:`~pmdcid.plan.design.Plan` (``.profiles``, ``.stderr``: predicted standard errors)."""
    import math

    from pmdcid.errors import PmdcidError
    from pmdcid.plan.design import Settings, plan_for_model
    from pmdcid.plan.guess import guess_plan
    from pmdcid.plan.output import check_out_dir, write_plan

    if vmax is not None and taumax is not None:
        raise PmdcidError("give vmax or taumax, not both")
    if model is None and vmax is None and taumax is None:
        raise PmdcidError("a plan without a model needs vmax (or taumax): the largest input "
                          "the rig may take")
    settings = Settings(umax=vmax if vmax is not None else taumax,
                        speed_max=speed_max if speed_max is not None else math.inf, rate=rate,
                        budget=budget, noise_omega=noise_omega, noise_i=noise_i,
                        taumax=taumax is not None)
    if out_dir is not None:
        check_out_dir(out_dir)
    out = guess_plan(settings) if model is None else plan_for_model(_model(model), settings)
    if out_dir is not None:
        write_plan(out, out_dir, "pmdcid.plan(...)")
    return out


def export(model, to: str, output, *, force: bool = False) -> list[str]:
    """Code that steps ``model`` exactly as :func:`simulate` does, as ``pmdcid export``:
    ``to`` is ``"python-control"``, ``"c"`` or ``"matlab"``; ``output`` the file to write (C:
    its header beside it; MATLAB: a script beside it); ``force`` overwrites a file pmdcid did
    not write. ``model``: a Model or a model file's path. Returns the paths written."""
    import tempfile

    from pmdcid.export import export_model

    if isinstance(model, (str, os.PathLike)):
        return export_model(str(model), to, str(output), force=force)
    with tempfile.TemporaryDirectory() as tmp:  # the exporters read a model file
        path = os.path.join(tmp, "model.json")
        model.save(path)
        return export_model(path, to, str(output), force=force)


__all__ = ["diagnose", "export", "fit_electrical", "fit_mechanical", "fit_nonlinear", "identify",
           "plan", "report", "simulate"]
