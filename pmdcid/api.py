"""The library's front door: ``import pmdcid`` then ``pmdcid.identify(...)`` and friends.

Every function takes logs as :class:`~pmdcid.io.Log` objects, paths, or a list of either, and a
model as a :class:`~pmdcid.model.Model`, a path, or None (an empty model); the model given is
never modified (each fit returns a result; ``result.apply(model)`` writes it in). Options are
keyword-only. Each function runs exactly what the matching command runs (the CLI's runners
share these steps: :mod:`pmdcid.identify.runners`, :mod:`pmdcid.diagnose.files`), including the
lumped (per-volt) path for voltage+speed logs.

Results follow one protocol (:class:`~pmdcid.identify.results.ResultProtocol`): ``str()`` is
the table, ``_repr_html_()``, ``to_dict()``, ``to_pandas()``, ``apply(model)``.

An argument of the wrong type (a scalar for a log, a dict for a Model) raises a TypeError naming
the argument before any work (:mod:`pmdcid.io.args`); a bad value a ValueError or PmdcidError.
"""

from __future__ import annotations

import os


def _logs(logs, name: str = "logs") -> list:
    from pmdcid.errors import LogError
    from pmdcid.io.logs import Log, read_log

    if isinstance(logs, (Log, str, os.PathLike)):
        logs = [logs]
    if not isinstance(logs, (list, tuple)):
        hint = " (Log.from_dataframe(df) makes a log of a DataFrame)" if hasattr(
            logs, "columns") or isinstance(logs, dict) else ""
        raise TypeError(f"{name} must be a Log, a log file's path or a list of them, not "
                        f"{type(logs).__name__}{hint}")
    for k, lg in enumerate(logs):
        if not isinstance(lg, (Log, str, os.PathLike)):
            raise TypeError(f"{name}[{k}] must be a Log or a log file's path, not "
                            f"{type(lg).__name__}")
    out = [lg if isinstance(lg, Log) else read_log(lg) for lg in logs]
    if not out:
        raise LogError("no logs given")
    return out


def _model(model, name: str = "model"):
    """A working copy of ``model`` (a Model, a model file's path, or None for an empty one)."""
    from pmdcid.model.params import Model, load_model

    if model is None:
        return Model()
    if isinstance(model, (str, os.PathLike)):
        return load_model(model)
    if not isinstance(model, Model):
        hint = (" (pmdcid.model.params.model_from_json(d) makes a Model of a dict)"
                if isinstance(model, dict) else "")
        raise TypeError(f"{name} must be a Model, a model file's path or None, not "
                        f"{type(model).__name__}{hint}")
    return model.copy()


def _x0(x0):
    """None, 'measured', a dict of i/omega/theta, or (i, omega, theta): finite numbers."""
    import math

    if x0 is None or (isinstance(x0, str) and x0 == "measured"):
        return x0
    if isinstance(x0, dict):
        vals = dict(x0)
        bad = [k for k in vals if k not in ("i", "omega", "theta")]
        if bad:
            raise ValueError(f"x0: unknown state {bad[0]!r} (give i, omega, theta)")
    elif isinstance(x0, (list, tuple)) or hasattr(x0, "__array__"):
        seq = list(x0)
        if len(seq) != 3:
            raise ValueError(f"x0 must be (i, omega, theta): 3 numbers, not {len(seq)}")
        vals = dict(zip(("i", "omega", "theta"), seq, strict=True))
    else:
        raise TypeError(f"x0 must be None, 'measured', a dict or (i, omega, theta), not "
                        f"{type(x0).__name__}")
    for k, v in vals.items():
        if isinstance(v, bool) or not isinstance(v, (int, float)) and not hasattr(v, "__float__"):
            raise TypeError(f"x0[{k!r}] must be a number, not {type(v).__name__}")
        if not math.isfinite(float(v)):
            raise ValueError(f"x0[{k!r}] must be finite, got {v!r}")
    return x0


def identify(logs, model=None, *, km: float | None = None, diagnose: bool = True,
             priors: bool = True, progress=None):
    """A whole rig, as ``pmdcid identify``: sort the logs, run each stage that applies, a joint
    fit, then (``diagnose``) the effect search. ``km`` [N m/A]: the datasheet torque constant;
    ``priors``: later stages combine with earlier estimates. ``progress``: None prints stage
    lines on a terminal's stderr, False is silent, a callable receives each stage's name.
    Returns a :class:`~pmdcid.pipeline.IdentifyResult` (``.model`` is the identified model)."""
    from pmdcid.io.args import number_arg
    from pmdcid.pipeline import identify as run
    from pmdcid.runtime.progress import resolve

    km = number_arg(km, "km", positive=True)
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
    from pmdcid.io.args import number_arg
    from pmdcid.model.lumped import is_lumped

    km = number_arg(km, "km", positive=True)
    logs = _logs(logs)
    work = lumped_if_wanted(logs, _model(model))
    res = stage_mechanical(logs, work, km)
    if is_lumped(work):
        per_volt(res)
    return res


def fit_nonlinear(logs, model, *, free=None, signals=None, priors: bool = True,
                  controller=None):
    """J, bv, bc, dz (tau0 for torque logs) by simulation error, as ``pmdcid fit-nonlinear``.

    ``free``: the parameters to fit (names, e.g. ``["J", "bc"]``; the others are held at the
    model's values); ``signals``: the measured signals in the cost (e.g. ``("omega",)``);
    ``priors``: combine with the estimates earlier stages wrote into the model;
    ``controller``: closed-loop logs' controller (a spec as ``--controller`` takes it, a dict of
    its keys, or a :class:`~pmdcid.simulate.controller.ControllerSpec`): the loop is simulated
    from the logged reference and fitted (docs/identification.md, "Closed-loop logs").
    Returns a :class:`~pmdcid.identify.nonlinear.NonlinearResult`."""
    from pmdcid.identify.runners import lumped_if_wanted, per_volt, stage_nonlinear
    from pmdcid.io.args import names_arg
    from pmdcid.model.lumped import is_lumped

    free, signals = names_arg(free, "free"), names_arg(signals, "signals")
    logs = _logs(logs)
    work = lumped_if_wanted(logs, _model(model))
    opts = {"priors": priors}
    if free is not None:
        opts["free"] = free
    if signals is not None:
        opts["signals"] = (signals,) if isinstance(signals, str) else tuple(signals)
    if controller is not None:
        from pmdcid.simulate.controller import (
            ControllerSpec,
            controller_from_dict,
            parse_controller,
        )

        if isinstance(controller, dict):
            controller = controller_from_dict(controller)
        elif not isinstance(controller, ControllerSpec):
            controller = parse_controller(str(controller))
        opts["controller"] = controller
    res = stage_nonlinear(logs, work, **opts)
    if is_lumped(work):
        per_volt(res)
    return res


def diagnose(logs, model, *, effects=None, progress=None):
    """Search the effect catalogue for what ``model`` lacks on ``logs``, as ``pmdcid diagnose``.
    ``effects``: names to search (default all). Returns a
    :class:`~pmdcid.diagnose.loop.DiagnoseResult` (``.model`` has the effects added)."""
    from pmdcid.diagnose.files import diagnose_logs
    from pmdcid.io.args import names_arg
    from pmdcid.runtime.progress import resolve

    effects = names_arg(effects, "effects")
    return diagnose_logs(_logs(logs), _model(model), effects=effects,
                         progress=resolve(progress))


def simulate(log_or_input, model, *, x0=None):
    """Simulate ``model`` on a log's input (a :class:`~pmdcid.io.Log` or a CSV path) from
    ``x0`` = (i [A], omega [rad/s], theta [rad]) at its first sample (default: rest).
    Returns a :class:`~pmdcid.simulate.SimResult` (t, i, omega, theta; ``to_pandas()``)."""
    from pmdcid.simulate import simulate_log

    logs = _logs(log_or_input, "log_or_input")
    if len(logs) != 1:
        raise TypeError(f"log_or_input must be one log, not {len(logs)}: simulate each")
    return simulate_log(logs[0], _model(model), x0=_x0(x0))


def report(logs, model, out_dir, *, summary=None, before=None, progress=None):
    """The model against measured logs into ``out_dir`` (report.html, metrics.json, figures),
    as ``pmdcid report``. ``summary``: a diagnose summary dict; ``before``: a model to show as
    'before'. Returns a :class:`~pmdcid.report.ReportResult`."""
    from pmdcid.io.args import path_arg
    from pmdcid.report import make_report
    from pmdcid.runtime.progress import resolve

    out_dir = path_arg(out_dir, "out_dir")
    if summary is not None and not isinstance(summary, dict):
        raise TypeError(f"summary must be a diagnose summary (dict) or None, not "
                        f"{type(summary).__name__}")
    return make_report(_logs(logs), _model(model), out_dir, summary=summary,
                       before_model=_model(before, "before") if before is not None else None,
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
