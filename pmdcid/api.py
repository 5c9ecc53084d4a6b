"""The one front door: ``import pmdcid`` then ``pmdcid.identify(...)`` and friends, and every
command of the command line (each ``pmdcid/cli/cmd_*.py`` parses its options and calls one
function here).

Every function takes logs as :class:`~pmdcid.io.Log` objects, paths, or a list of either, and a
model as a :class:`~pmdcid.model.Model`, a path, or None (an empty model); the model given is
never modified (each fit returns a result; ``result.apply(model)`` writes it in). Options are
keyword-only. Each function runs exactly what the matching command runs, including the lumped
(per-volt) path for voltage+speed logs (:mod:`pmdcid.identify.runners`).

Files out, as the commands write them, go through :mod:`pmdcid.files` (read -> call -> gate ->
lock and atomic write): the fits and ``identify`` with ``update=True`` write their result into
the model file given as ``model``; ``diagnose`` with ``output`` (and ``summary``);
:func:`simulate_to` writes simulated logs; ``report``, ``plan`` and ``export`` write their
files always. ``mapping`` applies to the logs given as paths, in any form the command line
takes: a :class:`~pmdcid.io.ColumnMap`, a ``"omega=speed_rpm*rpm"`` string (one ``-c``), a list
of them, a dict ``{"omega": "speed_rpm*rpm"}``, or a mapping file's path (``--map``); anything
else is one :class:`~pmdcid.errors.LogError` line naming the forms.

Results follow one protocol (:class:`~pmdcid.fit.results.ResultProtocol`): ``str()`` is
the table, ``_repr_html_()``, ``to_dict()``, ``to_pandas()``, ``apply(model)``.

An argument of the wrong type (a scalar for a log, a dict for a Model) raises a TypeError naming
the argument before any work (:mod:`pmdcid.io.args`); a value out of range (one the command line
refuses as a usage error) an :class:`~pmdcid.errors.ArgumentError` (a PmdcidError and a
ValueError) naming it.
"""

from __future__ import annotations

import math
import os

from pmdcid.errors import ArgumentError
from pmdcid.io.args import number_arg, path_arg

#: largest budget x rate a plan simulates (samples): 2e7 is 5.5 h at 1 kHz, ~1 GB of sensitivities
MAX_PLAN_SAMPLES = 2e7


def _mapping(mapping):
    """``mapping=`` in any form the command line takes (:func:`pmdcid.io.mapping.as_mapping`):
    a ColumnMap, a ``"CANON=SRC*K+OFF"`` string, a list of them, a dict, a mapping file's path."""
    from pmdcid.io.mapping import as_mapping

    return as_mapping(mapping)


def _logs(logs, name: str = "logs", mapping=None) -> list:
    from pmdcid.files import logs_of

    return logs_of(logs, name, _mapping(mapping))


def _model(model, name: str = "model"):
    """A working copy of ``model`` (a Model, a model file's path, or None for an empty one)."""
    from pmdcid.files import model_of

    return model_of(model, name)


def _file(model, name: str = "model") -> str:
    """The model file a command writes (``update=True``): a path."""
    from pmdcid.io.args import path_arg

    return path_arg(model, f"{name} (update=True writes into it)")


def _controller(controller):
    """None, a :class:`~pmdcid.simulate.controller.ControllerSpec`, a dict of its keys or a spec
    as ``--controller`` takes it."""
    if controller is None:
        return None
    from pmdcid.simulate.controller import ControllerSpec, controller_from_dict, parse_controller

    if isinstance(controller, dict):
        return controller_from_dict(controller)
    if isinstance(controller, ControllerSpec):
        return controller
    return parse_controller(str(controller))


def _x0(x0):
    """None, 'measured', a dict of i/omega/theta, or (i, omega, theta): finite numbers."""
    if x0 is None or (isinstance(x0, str) and x0 == "measured"):
        return x0
    if isinstance(x0, dict):
        vals = dict(x0)
        bad = [k for k in vals if k not in ("i", "omega", "theta")]
        if bad:
            raise ArgumentError(f"x0: unknown state {bad[0]!r} (give i, omega, theta)")
    elif isinstance(x0, (list, tuple)) or hasattr(x0, "__array__"):
        seq = list(x0)
        if len(seq) != 3:
            raise ArgumentError(f"x0 must be (i, omega, theta): 3 numbers, not {len(seq)}")
        vals = dict(zip(("i", "omega", "theta"), seq, strict=True))
    else:
        raise TypeError(f"x0 must be None, 'measured', a dict or (i, omega, theta), not "
                        f"{type(x0).__name__}")
    for k, v in vals.items():
        if isinstance(v, bool) or not isinstance(v, (int, float)) and not hasattr(v, "__float__"):
            raise TypeError(f"x0[{k!r}] must be a number, not {type(v).__name__}")
        if not math.isfinite(float(v)):
            raise ArgumentError(f"x0[{k!r}] must be finite, got {v!r}")
    return x0


def identify(logs, model=None, *, km: float | None = None, diagnose: bool = True,
             priors: bool = True, progress=None, controller=None, mapping=None,
             update: bool = False, out_dir=None, force: bool = False):
    """A whole rig, as ``pmdcid identify``: sort the logs, run each stage that applies, a joint
    fit, then (``diagnose``) the effect search. ``km`` [N m/A]: the datasheet torque constant;
    ``priors``: later stages combine with earlier estimates. ``progress``: None prints stage
    lines on a terminal's stderr, False is silent, a callable receives each stage's name.
    ``controller``: closed-loop logs' controller (as :func:`fit_nonlinear`). ``update``: write
    the identified model into the model file ``model`` (created if missing; the plausibility
    gate refuses implausible logs unless ``force``), and with ``out_dir`` the report there.
    Returns a :class:`~pmdcid.pipeline.IdentifyResult` (``.model`` is the identified model)."""
    from pmdcid.io.args import number_arg
    from pmdcid.runtime.progress import resolve

    km = number_arg(km, "km", positive=True)
    opts = dict(km=km, run_diagnose=diagnose, priors=priors, progress=resolve(progress),
                controller=_controller(controller))
    if update:
        from pmdcid.files import run_identify

        return run_identify(logs, _file(model), out_dir, _mapping(mapping), force=force,
                            **opts)
    if out_dir is not None:
        raise TypeError("out_dir: identify writes its report with update=True (the model file "
                        "first)")
    from pmdcid.pipeline import identify as run

    return run(_logs(logs, mapping=mapping), _model(model), **opts)


def _fit(stage: str, fit, logs, model, mapping, update: bool, force: bool, **opts):
    """A stage in memory (the lumped path: :func:`pmdcid.identify.runners.fit_stage`), or with
    ``update`` into the model file ``model`` (:func:`pmdcid.files.run_fit`)."""
    if update:
        from pmdcid.files import run_fit

        return run_fit(stage, logs, _file(model), _mapping(mapping), force, **opts)
    from pmdcid.identify.runners import fit_stage

    logs = _logs(logs, mapping=mapping)
    return fit_stage(lambda lg, m: fit(lg, m, **opts), logs, _model(model))


def fit_electrical(logs, model=None, *, mapping=None, update: bool = False,
                   force: bool = False):
    """R [ohm], L [H] from blocked-rotor logs (``t``, ``v``, ``i``, one step each), as
    ``pmdcid fit-electrical`` (``update``: into the model file ``model``, as the command).
    Returns an :class:`~pmdcid.identify.electrical.ElectricalResult`."""
    from pmdcid.identify.runners import stage_electrical

    return _fit("electrical", stage_electrical, logs, model, mapping, update, force)


def fit_mechanical(logs, model, *, km: float | None = None, mapping=None, update: bool = False,
                   force: bool = False):
    """b, bv, bc, J from free-speed step logs, as ``pmdcid fit-mechanical`` (per volt when the
    logs carry no current and the model no R; in SI with no km from torque step logs, ``tau``).
    ``km`` [N m/A]: datasheet torque constant.
    Returns a :class:`~pmdcid.identify.mechanical.MechanicalResult`."""
    from pmdcid.identify.runners import stage_mechanical
    from pmdcid.io.args import number_arg

    km = number_arg(km, "km", positive=True)
    return _fit("mechanical", stage_mechanical, logs, model, mapping, update, force, km=km)


def fit_nonlinear(logs, model, *, free=None, signals=None, priors: bool = True,
                  controller=None, dead_zone: bool = False, mapping=None, update: bool = False,
                  force: bool = False):
    """J, bv, bc, dz (tau0 for torque logs) by simulation error, as ``pmdcid fit-nonlinear``.

    ``free``: the parameters to fit (names, e.g. ``["J", "bc"]``; the others are held at the
    model's values); ``signals``: the measured signals in the cost (e.g. ``("omega",)``);
    ``priors``: combine with the estimates earlier stages wrote into the model;
    ``controller``: closed-loop logs' controller (a spec as ``--controller`` takes it, a dict of
    its keys, or a :class:`~pmdcid.simulate.controller.ControllerSpec`): the loop is simulated
    from the logged reference and fitted (docs/identification.md, "Closed-loop logs");
    ``dead_zone``: torque-driven logs fit dz too.
    Returns a :class:`~pmdcid.identify.nonlinear.NonlinearResult`."""
    from pmdcid.identify.runners import stage_nonlinear
    from pmdcid.io.args import names_arg

    free, signals = names_arg(free, "free"), names_arg(signals, "signals")
    opts = {"priors": priors}
    if free is not None:
        opts["free"] = free
    if signals is not None:
        opts["signals"] = tuple(signals)
    if dead_zone:
        opts["dead_zone"] = True
    return _fit("nonlinear", stage_nonlinear, logs, model, mapping, update, force,
                controller=_controller(controller), **opts)


def fit_inverse_dynamics(logs, model, *, km: float | None = None, as_published: bool = False,
                         mapping=None, update: bool = False, force: bool = False):
    """J, bv, bc, tau0 by inverse dynamics (linear least squares), as ``pmdcid
    fit-inverse-dynamics``. ``km`` [N m/A]: for voltage logs with a current column;
    ``as_published``: the EMPS authors' IDIM-LS exactly. Returns an
    :class:`~pmdcid.identify.inverse_dynamics.InverseDynamicsResult`."""
    from pmdcid.identify.runners import stage_inverse_dynamics
    from pmdcid.io.args import number_arg

    km = number_arg(km, "km", positive=True)
    return _fit("inverse-dynamics", stage_inverse_dynamics, logs, model, mapping, update, force,
                km=km, as_published=as_published)


def diagnose(logs, model, *, effects=None, progress=None, mapping=None, output=None,
             summary=None, force: bool = False):
    """Search the effect catalogue for what ``model`` lacks on ``logs``, as ``pmdcid diagnose``.
    ``effects``: names to search (default all). ``output``: write the new model there (and the
    summary JSON to ``summary``), as the command does (``model`` then a model file's path,
    rewritten only when ``output`` is the same file; ``force`` overwrites files that are not
    pmdcid's and lets implausible logs through with a warning). Returns a
    :class:`~pmdcid.diagnose.loop.DiagnoseResult` (``.model`` has the effects added)."""
    from pmdcid.io.args import names_arg
    from pmdcid.runtime.progress import resolve

    effects = names_arg(effects, "effects")
    if output is not None:
        from pmdcid.files import run_diagnose
        from pmdcid.io.args import path_arg

        return run_diagnose(logs, path_arg(model, "model (with output)"),
                            path_arg(output, "output"), summary, _mapping(mapping), effects, force,
                            progress=resolve(progress))
    if summary is not None:
        raise TypeError("summary: written with output (the new model's file)")
    from pmdcid.diagnose.entry import diagnose_logs

    return diagnose_logs(_logs(logs, mapping=mapping), _model(model), effects=effects,
                         progress=resolve(progress))


def simulate(log_or_input, model, *, x0=None):
    """Simulate ``model`` on a log's input (a :class:`~pmdcid.io.Log` or a CSV path) from
    ``x0`` = (i [A], omega [rad/s], theta [rad]) at its first sample (default: rest), or
    ``"measured"``: the log's own first samples. Returns a :class:`~pmdcid.simulate.SimResult`
    (t, i, omega, theta; ``to_pandas()``). :func:`simulate_to` writes the simulated log."""
    from pmdcid.simulate import simulate_log

    logs = _logs(log_or_input, "log_or_input")
    if len(logs) != 1:
        raise TypeError(f"log_or_input must be one log, not {len(logs)}: simulate each")
    return simulate_log(logs[0], _model(model), x0=_x0(x0))


def simulate_to(inputs, model, output, *, x0=None, noise_i: float = 0.0,
                noise_omega: float = 0.0, encoder: int = 0, seed: int | None = None,
                blocked: bool = False, controller=None, mapping=None,
                force: bool = False) -> list[str]:
    """``pmdcid simulate``: the simulated log of each input file (a path, or a list of them)
    written to ``output`` (one input: that file; several: into the folder ``output``, each
    named as its input), with sensor noise ``noise_i`` [A], ``noise_omega`` [rad/s],
    ``encoder`` [counts/rev] from ``seed``; ``blocked``: the rotor held; ``controller``: the
    closed loop from the input's reference (as :func:`fit_nonlinear`); ``x0`` as
    :func:`simulate`; ``force``: overwrite a file pmdcid did not write. ``model``: a model
    file's path. Returns the paths written."""
    from pmdcid.files import simulate_file, simulate_files
    from pmdcid.io.args import path_arg
    from pmdcid.synth import NoiseSpec

    paths = inputs if isinstance(inputs, (list, tuple)) else [inputs]
    paths = [path_arg(p, "inputs") for p in paths]
    noise = NoiseSpec(number_arg(noise_i, "noise_i", nonneg=True),
                      number_arg(noise_omega, "noise_omega", nonneg=True), _count(encoder))
    opts = dict(mapping=_mapping(mapping), noise=noise,
                seed=seed, blocked=blocked, force=force, x0=_x0(x0),
                controller=_controller(controller))
    model, output = path_arg(model, "model"), path_arg(output, "output")
    if len(paths) == 1:
        return [simulate_file(paths[0], model, output, **opts)]
    return simulate_files(paths, model, output, **opts)


def _count(encoder) -> int:
    """``encoder`` [counts/rev]: a whole number >= 0 (0: no encoder)."""
    if isinstance(encoder, bool) or not isinstance(encoder, int) and not (
            hasattr(encoder, "__index__")):
        raise TypeError(f"encoder must be a whole number of counts per rev, not "
                        f"{type(encoder).__name__}")
    if encoder < 0:
        raise ArgumentError(f"encoder must be >= 0 counts per rev, got {encoder!r}")
    return int(encoder)


def report(logs, model, out_dir, *, summary=None, before=None, progress=None, mapping=None,
           force: bool = False):
    """The model against measured logs into ``out_dir`` (report.html, metrics.json, figures),
    as ``pmdcid report``. ``summary``: a diagnose summary (a dict, or its JSON file's path);
    ``before``: a model (or its path) to show as 'before'; ``force``: replace files in
    ``out_dir`` pmdcid did not write. Returns a :class:`~pmdcid.report.ReportResult`."""
    from pmdcid.files import run_report
    from pmdcid.io.args import path_arg
    from pmdcid.runtime.progress import resolve

    out_dir = path_arg(out_dir, "out_dir")
    if summary is not None and not isinstance(summary, (dict, str, os.PathLike)):
        raise TypeError(f"summary must be a diagnose summary (a dict or its file's path) or "
                        f"None, not {type(summary).__name__}")
    return run_report(logs, model, out_dir, summary, before, _mapping(mapping), resolve(progress),
                      force)


def plan(model=None, out_dir=None, *, vmax: float | None = None, taumax: float | None = None,
         speed_max: float | None = None, rate: float = 1000.0, budget: float = 120.0,
         noise_omega: float | None = None, noise_i: float | None = None,
         command: str = "pmdcid.plan(...)", force: bool = False):
    """Input profiles to record, as ``pmdcid plan``: for ``model`` (a Model or a model file's
    path), or, with ``model=None``, a first safe experiment (``--guess``: give ``vmax`` [V] or
    ``taumax`` [N m]). ``speed_max`` [rad/s]: the largest speed the motion may reach; ``rate``
    [Hz]: sampling and input hold rate; ``budget`` [s]: total recording time; ``noise_omega``
    [rad/s] and ``noise_i`` [A]: the sensors' noise std (None: defaults). With ``out_dir`` the
    profiles (CSV), plan.json and plan.md are written there (``command``: how plan.md says the
    plan was made); a file there that pmdcid plan did not write (a recorded log named like a
    profile, your own plan.md) is refused before any work unless ``force``. Returns the
    :class:`~pmdcid.plan.design.Plan` (``.profiles``, ``.stderr``: predicted standard errors)."""
    from pmdcid.errors import PmdcidError
    from pmdcid.plan.design import plan_for_model
    from pmdcid.plan.guess import guess_plan
    from pmdcid.plan.output import check_out_dir, write_plan

    if model is None and vmax is None and taumax is None:
        raise PmdcidError("a plan without a model needs vmax (or taumax): the largest input "
                          "the rig may take")
    settings = _plan_settings(vmax, taumax, speed_max, rate, budget, noise_omega, noise_i)
    if out_dir is not None:
        check_out_dir(out_dir, force=force)
    out = guess_plan(settings) if model is None else plan_for_model(_model(model), settings)
    if out_dir is not None:
        write_plan(out, out_dir, command, force)
    return out


def _plan_settings(vmax, taumax, speed_max, rate, budget, noise_omega, noise_i):
    """:class:`~pmdcid.plan.design.Settings` from the plan functions' keyword options, checked
    as ``pmdcid plan`` checks its options (each a finite number > 0)."""
    from pmdcid.errors import PmdcidError
    from pmdcid.plan.design import Settings

    if vmax is not None and taumax is not None:
        raise PmdcidError("give vmax or taumax, not both")
    vmax, taumax, speed_max, noise_omega, noise_i = (
        number_arg(x, name, positive=True) for x, name in
        ((vmax, "vmax"), (taumax, "taumax"), (speed_max, "speed_max"),
         (noise_omega, "noise_omega"), (noise_i, "noise_i")))
    rate, budget = number_arg(rate, "rate", positive=True), number_arg(budget, "budget",
                                                                         positive=True)
    if rate is None or budget is None:
        raise TypeError(f"{'rate' if rate is None else 'budget'} must be a number, not None")
    if budget * rate > MAX_PLAN_SAMPLES:
        raise ArgumentError(f"budget {budget:g} s at rate {rate:g} Hz is {budget * rate:.3g} "
                            f"samples per profile set: at most {MAX_PLAN_SAMPLES:.0e} (a "
                            f"shorter budget or a lower rate)")
    return Settings(umax=vmax if vmax is not None else taumax,
                    speed_max=speed_max if speed_max is not None else math.inf, rate=rate,
                    budget=budget, noise_omega=noise_omega, noise_i=noise_i,
                    taumax=taumax is not None)


def check_plan(logs, model, out_dir=None, *, vmax: float | None = None,
               taumax: float | None = None, speed_max: float | None = None,
               rate: float = 1000.0, budget: float = 120.0, noise_omega: float | None = None,
               noise_i: float | None = None, mapping=None, force: bool = False):
    """What recorded ``logs`` can identify of ``model``, as ``pmdcid plan --check``: the
    predicted standard errors, the parameters they leave undetermined, which of diagnose's
    effects they could test and what to record for the others (docs/plan.md). With
    ``out_dir``, check.json is written there (one pmdcid did not write refused unless
    ``force``). Options as :func:`plan`. Returns the check's
    result (``.lines()``: the text, ``.as_dict()``: check.json)."""
    import json

    from pmdcid.plan.check import check_logs
    from pmdcid.plan.output import check_out_dir
    from pmdcid.runtime.outputs import atomic_write_text, output_folder

    settings = _plan_settings(vmax, taumax, speed_max, rate, budget, noise_omega, noise_i)
    if out_dir is not None:
        check_out_dir(out_dir, ["check.json"], force)
    res = check_logs(_checked_logs(logs, mapping), _model(model), settings)
    if out_dir is not None:
        with output_folder(out_dir) as d:
            atomic_write_text(d / "check.json", json.dumps(res.as_dict(), indent=2) + "\n")
    return res


def _checked_logs(logs, mapping) -> list:
    """plan --check's logs: read with their findings deferred, then warned about, unless a log's
    time unit is wrong (check_logs refuses it: one line, not the warnings it causes first)."""
    from pmdcid.errors import warn
    from pmdcid.files import logs_of
    from pmdcid.identify.plausibility import time_unit_issue

    read = logs_of(logs, "logs", _mapping(mapping), defer=True)
    if not any(time_unit_issue(lg) for lg in read):
        for lg in read:
            for msg in getattr(lg, "issues", []):
                warn(msg, lg.path)
    return read


def export(model, to: str, output, *, force: bool = False, note=None) -> list[str]:
    """Code that steps ``model`` exactly as :func:`simulate` does, as ``pmdcid export``:
    ``to`` is ``"python-control"``, ``"c"``, ``"matlab"``, ``"mujoco"`` or ``"fmu"``; ``output``
    the file to write (C: its header beside it; MATLAB: a script beside it); ``force``
    overwrites a file pmdcid did not write; ``note``: told each approximation (MuJoCo).
    ``model``: a Model or a model file's path. Returns the paths written."""
    import tempfile

    from pmdcid.export import export_model

    if not isinstance(to, str):
        raise TypeError(f"to must be a format name (str), not {type(to).__name__}")
    output = path_arg(output, "output")
    if isinstance(model, (str, os.PathLike)):
        return export_model(os.fspath(model), to, output, force=force, note=note)
    model = _model(model)  # a Model (a copy), or the TypeError naming what it must be
    with tempfile.TemporaryDirectory() as tmp:  # the exporters read a model file
        path = os.path.join(tmp, "model.json")
        model.save(path)
        return export_model(path, to, output, force=force, note=note)


def channels(path) -> list:
    """The signals a log file holds (any format pmdcid reads), as ``pmdcid channels``: a list
    of :class:`~pmdcid.io.formats.Channel` (name, samples, rate, unit)."""
    from pmdcid.io.formats import channels as read_channels

    return read_channels(path_arg(path, "path"))


def run_demo(out_dir="demo-output", echo=print) -> dict:
    """``pmdcid demo``: the whole pipeline on the bundled example logs, the report into
    ``out_dir``; ``echo`` prints each line. Returns paths, the final model, the diagnose summary
    and timings."""
    from pmdcid.demo import run_demo as run

    return run(out_dir, echo=echo)


def run_fleet(manifest, out_dir, **options):
    """``pmdcid fleet``: every unit of the manifest identified on a Dask cluster
    (docs/fleet.md; ``options`` as :func:`pmdcid.fleet.run.run_fleet`). Returns a
    :class:`~pmdcid.fleet.run.FleetResult`."""
    from pmdcid.fleet.run import run_fleet as run

    return run(manifest, out_dir, **options)


__all__ = ["channels", "check_plan", "diagnose", "export", "fit_electrical", "fit_inverse_dynamics",
           "fit_mechanical", "fit_nonlinear", "identify", "plan", "report", "run_demo", "run_fleet",
           "simulate", "simulate_to"]
