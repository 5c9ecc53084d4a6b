"""Paths in, files out: every command's work on files, and the one place that reads a command's
inputs, guards its outputs and writes them.

Each ``run_*`` function takes paths (or :class:`~pmdcid.io.Log` and
:class:`~pmdcid.model.Model` objects, :func:`logs_of`, :func:`model_of`) and runs the same
steps: **read** (the logs with the column mapping, the model file) -> **call** (the in-memory
function :mod:`pmdcid.api` calls too: :mod:`pmdcid.identify.runners`,
:mod:`pmdcid.diagnose.entry`, :mod:`pmdcid.pipeline`, :mod:`pmdcid.report`) -> **gate** (the
plausibility gate, :mod:`pmdcid.identify.plausibility`: the logs' units before the fit, the
model before it is written; ``force`` turns its refusals into warnings) -> **lock and atomic
write**. Each guard is written once: output-is-an-input (:func:`pmdcid.runtime.outputs.input_at`),
overwrite (:func:`pmdcid.runtime.outputs.check_overwrite`), the model folder's lock
(:func:`pmdcid.runtime.outputs.locked`, held by :func:`update_model`) and the model file's
optimistic locking (:func:`pmdcid.model.save_model` refuses a file changed since it was read).

The command line reaches these through :mod:`pmdcid.api` only; heavy modules are imported
inside the functions, so that a command loads what it needs and no more.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from pathlib import Path

from pmdcid.errors import LogError, ModelError, warn
from pmdcid.model import load_model, save_model
from pmdcid.runtime.outputs import check_overwrite, input_at, locked, matched, same_file


def logs_of(logs, name: str = "logs", mapping=None, defer: bool = False) -> list:
    """``logs`` (a :class:`~pmdcid.io.Log`, a log file's path, or a list of either) as Logs:
    paths read with ``mapping`` (``defer``: their plausibility findings kept in ``log.issues``
    for the gate, not warned about). A wrong type is a TypeError naming ``name``, before any
    work."""
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
    logs = matched(logs)
    if not logs:
        raise LogError("no logs given")
    refuse_repeated_logs(logs)
    return [lg if isinstance(lg, Log) else read_log(lg, mapping, defer) for lg in logs]


def _content_hash(path: str) -> str | None:
    h = hashlib.sha256()
    try:
        with open(path, "rb") as fh:
            for block in iter(lambda: fh.read(1 << 20), b""):
                h.update(block)
    except OSError:
        return None  # read_log says what is wrong with it
    return h.hexdigest()


def _same_log(a: str, b: str) -> str | None:
    """How the log file ``b`` repeats ``a`` (said in the error), or None. Contents are only
    compared between files of one size."""
    if same_file(a, b, planned=True):
        return "given twice" if a == b else f"the same file as {a}, given twice"
    try:
        if not (os.path.isfile(a) and os.path.isfile(b)) or (
                os.path.getsize(a) != os.path.getsize(b)):
            return None
    except OSError:
        return None
    ha = _content_hash(a)
    return (f"a copy of {a} (identical content)" if ha is not None and ha == _content_hash(b)
            else None)


def refuse_repeated_logs(logs) -> None:
    """One log given twice -- the same file under two names (``log1.csv ./log1.csv``), a copy
    of it (identical bytes) or one Log object twice -- would be counted twice and the standard
    errors understated: a one-line :class:`LogError` naming the repeat, before any work."""
    for k, lg in enumerate(logs):
        for earlier in logs[:k]:
            if lg is earlier and not isinstance(lg, (str, os.PathLike)):
                raise LogError("the same Log is given twice: its data would count twice "
                               "(standard errors too small); give each log once",
                               getattr(lg, "path", None))
            if not (isinstance(lg, (str, os.PathLike)) and isinstance(earlier, (str, os.PathLike))):
                continue
            how = _same_log(os.fspath(earlier), os.fspath(lg))
            if how is not None:
                raise LogError(f"{how}: its data would count twice (standard errors too "
                               "small); give each log once", os.fspath(lg))


def model_of(model, name: str = "model", must_exist: bool = True):
    """A working copy of ``model`` (a Model, a model file's path, or None for an empty one)."""
    from pmdcid.model.params import Model

    if model is None:
        return Model()
    if isinstance(model, (str, os.PathLike)):
        return load_model(model, must_exist=must_exist)
    if not isinstance(model, Model):
        hint = (" (pmdcid.model.params.model_from_json(d) makes a Model of a dict)"
                if isinstance(model, dict) else "")
        raise TypeError(f"{name} must be a Model, a model file's path or None, not "
                        f"{type(model).__name__}{hint}")
    return model.copy()


def _paths(logs) -> list[str]:
    items = logs if isinstance(logs, (list, tuple)) else [logs]
    return [os.fspath(p) for p in items if isinstance(p, (str, os.PathLike))]


def _refuse_model_over_a_log(logs, model_path) -> None:
    log = input_at(model_path, _paths(logs))
    if log is not None:
        raise LogError(f"the model file would overwrite the input log {log}; choose another -m",
                       model_path)


def _value(model, name, given=None):
    if given is not None:
        return given
    p = model.parameters.get(name)
    return p.value if p is not None else None


def read_and_gate(logs, model_path, mapping=None, force=False, km=None):
    """read -> gate: the logs (the model file never one of them) and the model file (missing:
    an empty model), the logs' plausibility gate passed. Returns (logs, model)."""
    from pmdcid.identify.plausibility import gate

    _refuse_model_over_a_log(logs, model_path)
    model = load_model(model_path, must_exist=False)
    read = logs_of(logs, mapping=mapping, defer=True)
    gate(read, force, _value(model, "km", km), _value(model, "R"))
    return read, model


def update_model(model_path, write, logs, force=False):
    """lock -> write: under the lock of the model's folder, the model file as it is now (another
    stage may have written it meanwhile), ``write(model)`` applied, the model's plausibility gate
    passed, saved atomically. Returns the model written."""
    from pmdcid.identify.plausibility import gate_result

    with locked(model_path):
        new = load_model(model_path, must_exist=False)
        write(new)
        gate_result(new, logs, force)
        save_model(new, model_path)
    return new


def run_fit(stage: str, logs, model_path, mapping=None, force=False, **opts):
    """``pmdcid fit-STAGE`` (``electrical``, ``mechanical``, ``nonlinear``,
    ``inverse-dynamics``): the stage's parameters into the model file ``model_path`` (created
    when missing, its parent folder must exist; only the stage's own parameters change), written
    in one atomic rename after the fit succeeded. ``opts``: the stage's options
    (:mod:`pmdcid.identify.runners`)."""
    from pmdcid.fit.results import record_notes
    from pmdcid.identify.runners import apply_stage, fit_stage
    from pmdcid.simulate.substeps import bounded_for

    fit = _stage(stage)
    km = opts.get("km")
    read, model = read_and_gate(logs, model_path, mapping, force, km)
    with bounded_for(model_path):
        res = fit_stage(lambda lg, m: fit(lg, m, **opts), read, model)

    def write(new):
        if stage == "inverse-dynamics" and km is not None:  # its result does not carry km
            new.set("km", km, stage="datasheet")
        apply_stage(res, new)
        record_notes(res, new)

    update_model(model_path, write, read, force)
    return res


def _stage(stage: str):
    from pmdcid.identify import runners

    stages = {"electrical": runners.stage_electrical, "mechanical": runners.stage_mechanical,
              "nonlinear": runners.stage_nonlinear,
              "inverse-dynamics": runners.stage_inverse_dynamics}
    if stage not in stages:
        raise ValueError(f"stage must be one of {', '.join(stages)}, not {stage!r}")
    return stages[stage]


def _clean(obj):
    """JSON-safe: non-finite floats become null."""
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: _clean(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_clean(v) for v in obj]
    return obj


def _refuse_diagnose_outputs(logs, model_path, out_path, summary_path) -> None:
    """Neither output may be an input log; the summary may not be a model file."""
    for p in _paths(logs):
        if same_file(p, out_path, planned=True):
            raise LogError(f"NEW_MODEL would overwrite the input log {p}; choose another -o",
                           out_path)
        if summary_path and same_file(p, summary_path, planned=True):
            raise LogError(f"the summary would overwrite the input log {p}; choose another "
                           "--summary", summary_path)
    if summary_path and input_at(summary_path, [model_path, out_path], planned=True):
        raise ModelError("the summary would overwrite a model file; choose another --summary",
                         summary_path)


def run_diagnose(logs, model_path, out_path, summary_path=None, mapping=None, effects=None,
                 force=False, **opts):
    """``pmdcid diagnose``: diagnose ``model_path`` on ``logs``; write ``out_path`` (and the
    summary). ``model_path`` is only rewritten when ``out_path`` is the same file. Both writes
    are atomic, after the whole analysis succeeded."""
    from pmdcid.diagnose import entry
    from pmdcid.identify.plausibility import gate
    from pmdcid.runtime.outputs import atomic_write_text
    from pmdcid.simulate.substeps import bounded_for

    _refuse_diagnose_outputs(logs, model_path, out_path, summary_path)
    check_overwrite(out_path, "model", force)
    if summary_path:
        check_overwrite(summary_path, "summary", force, "--summary")
    model = load_model(model_path)
    read = logs_of(logs, mapping=mapping, defer=True)
    gate(read, force, _value(model, "km"), _value(model, "R"))
    with bounded_for(model_path):
        res = entry.diagnose_logs(read, model, effects=effects, **opts)
    res.record_notes(res.model)  # the model file keeps diagnose's notes and warnings
    with locked(out_path):
        save_model(res.model, out_path)
    if summary_path:
        atomic_write_text(summary_path, json.dumps(_clean(res.summary), indent=2) + "\n")
    return res


def run_identify(logs, model_path, out_dir=None, mapping=None, km=None, run_diagnose=True,
                 priors=True, progress=None, force=False, controller=None):
    """``pmdcid identify`` on files: read, identify (:func:`pmdcid.pipeline.identify`), write
    MODEL atomically, then the report into ``out_dir``."""
    from pmdcid.identify.plausibility import gate, gate_result
    from pmdcid.pipeline import identify
    from pmdcid.simulate.substeps import bounded_for

    _refuse_model_over_a_log(logs, model_path)
    if out_dir is not None:
        from pmdcid.report import check_out_dir, check_report_outputs

        check_out_dir(out_dir)
    model = load_model(model_path, must_exist=False)
    read = logs_of(logs, mapping=mapping, defer=True)
    if out_dir is not None:  # a file in DIR pmdcid did not write: refused before the work
        check_report_outputs(out_dir, read, force)
    gate(read, force, _value(model, "km", km), _value(model, "R"))
    with bounded_for(model_path):
        res = identify(read, model, km=km, run_diagnose=run_diagnose, priors=priors,
                       progress=progress, controller=controller)
    res.model.extra.setdefault("fits", {})["identify"] = {
        "logs": {p.path: {"kind": p.kind, "why": p.why} for p in res.plan},
        "stages": [name for name, _ in res.stages], "notes": res.notes}
    res.record_notes(res.model)
    gate_result(res.model, read, force)
    with locked(model_path):
        save_model(res.model, model_path)
    _identify_report(res, read, out_dir, progress, force)
    return res


def _as_sorted(log, kind: str):
    """``log`` as identify sorted it: a log sorted blocked-rotor by its content (the rotor still
    while current flows, no ``# kind:``) is shown as one, its rotor held and its current
    compared. Before, the report simulated it turning freely (a speed NRMSE of 338 on a lab
    rig's 2 V blocked step) beside a table that called it blocked."""
    if kind != "blocked" or log.blocked:
        return log
    import copy

    shown = copy.copy(log)
    shown.meta = {**log.meta, "kind": "blocked-rotor"}
    return shown


def _identify_report(res, logs, out_dir, progress, force=False) -> None:
    if out_dir is None:
        return
    if not res.model.has("J"):
        res.notes.append(f"report: not written into {out_dir}: the model has no J to simulate "
                         "the logs with (only blocked-rotor logs were given: record free-running "
                         "ones, steps or ramps, for the mechanics)")
        return
    from pmdcid.report import make_report

    summary = res.diagnose.summary if res.diagnose is not None else None
    shown = [_as_sorted(lg, p.kind) for lg, p in zip(logs, res.plan, strict=True)
             if p.kind != "unused"]
    res.report_dir = make_report(shown, res.model, out_dir, summary=summary,
                                 progress=progress, force=force).out_dir


def run_report(logs, model, out_dir, summary=None, before=None, mapping=None, progress=None,
               force=False):
    """``pmdcid report``: ``model`` against ``logs`` into ``out_dir``. ``summary``: a diagnose
    summary (a dict, or its file's path); ``before``: a model (or its path) shown as 'before'."""
    from pmdcid.report import check_out_dir, load_summary, make_report

    check_out_dir(out_dir)
    model = model_of(model)
    before = model_of(before, "before") if before is not None else None
    if isinstance(summary, (str, os.PathLike)):
        summary = load_summary(summary)
    read = logs_of(logs, mapping=mapping, defer=True)
    return make_report(read, model, out_dir, summary=summary, before_model=before,
                       progress=progress, force=force)


def _is_ours(path: str) -> bool:
    from pmdcid.synth import GENERATOR

    try:
        with open(path) as fh:
            head = fh.read(400)
    except OSError:
        return False
    return f"# generator: {GENERATOR}" in head


def _refuse_foreign(output, force: bool) -> None:
    """An existing ``output`` pmdcid did not write is kept unless ``force``."""
    if os.path.exists(output) and not force and not _is_ours(output):
        raise LogError("exists and was not written by pmdcid; use --force to overwrite it", output)


def simulate_file(input_path, model_path, output, mapping=None, noise=None, seed=None,
                  blocked: bool = False, force: bool = False, x0=None, controller=None) -> str:
    """``pmdcid simulate``: read INPUT's t and v/tau, simulate MODEL
    (:func:`pmdcid.synth.simulated_columns`), write OUT (atomically). ``controller`` (a
    :class:`~pmdcid.simulate.controller.ControllerSpec`): the closed loop from INPUT's
    reference instead, its input column the simulated controller's output."""
    from pmdcid.io import read_log, write_log
    from pmdcid.simulate.substeps import bounded_for
    from pmdcid.synth import NoiseSpec, simulated_columns

    for src, what in ((input_path, "input log"), (model_path, "model file")):
        if input_at(output, [src]):
            raise LogError(f"output would overwrite the {what}; choose another -o", output)
    _refuse_foreign(output, force)
    log = read_log(input_path, mapping)
    log.drive  # noqa: B018 - raises a clear error when neither v nor tau is present
    _say_time_unit(log, input_path)
    model = load_model(model_path)
    _say_stiff(model, model_path)
    noise = noise or NoiseSpec()
    with bounded_for(model_path):
        t_out, cols, meta = simulated_columns(log, model, noise, seed, blocked, x0, controller)
    _refuse_blown_up(cols, noise, output)
    meta = {"generator": meta.pop("generator"), "source": os.path.basename(str(input_path)),
            "model": os.path.basename(str(model_path)), **meta}
    write_log(output, t_out, cols, meta)
    return str(output)


def _say_time_unit(log, input_path) -> None:
    """A warning where the input's time looks like ms, us or ns (the fit commands' time-unit
    rule, :func:`~pmdcid.identify.plausibility.time_unit_issue`): simulate has no gate to
    refuse it, and a log in ms simulated as seconds runs a thousand times too long, exit 0."""
    from pmdcid.identify.plausibility import time_unit_issue

    issue = time_unit_issue(log)
    if issue:
        warn(f"{issue}; simulated with t as it stands, in seconds", str(input_path))


def _say_stiff(model, model_path) -> None:
    """A warning where the model's mechanical time constant is shorter than any motor's
    (:data:`~pmdcid.identify.plausibility.MIN_TAU_MECHANICAL`: J in a wrong unit, or a fit the
    logs left J open in): the kernel simulates it (its internal steps are capped,
    :data:`pmdcid.simulate.substeps.MAX_MECH_SUBSTEPS`), the rotor following its torque at once."""
    from pmdcid.identify.plausibility import MIN_TAU_MECHANICAL, mechanical_tau

    tau = mechanical_tau(model)
    if tau < MIN_TAU_MECHANICAL:
        warn(f"the model's mechanical time constant J/(b+km^2/R) = {tau:.3g} s is shorter than "
             f"any motor's ({1e3 * MIN_TAU_MECHANICAL:g} ms): check J (value, unit); simulated "
             "as it stands", str(model_path))


def _refuse_blown_up(cols, noise, output) -> None:
    """A simulated column that reaches 1e30 (or inf) is never written."""
    import numpy as np

    for name, col in cols.items():  # a NaN current (torque-driven) is legitimate, inf is not
        if np.isinf(col).any() or np.nanmax(np.abs(col), initial=0.0) >= 1e30:
            std = {"i": noise.i, "omega": noise.omega}.get(name, 0.0)
            why = (f"the noise std --noise-{name} {std:g} is far too large" if std >= 1e30 else
                   "the model's parameters make it blow up: check their values and units")
            raise LogError(f"simulated column '{name}' reaches {np.nanmax(np.abs(col)):.3g}: {why}"
                           "; nothing written", output)


def simulate_files(input_paths: list[str], model_path, out_dir, **opts) -> list[str]:
    """``pmdcid simulate IN1 IN2 ... -o DIR``: :func:`simulate_file` for each input into
    ``DIR/<input's file name>`` (DIR created if missing), in one process: the start-up of a
    command (~0.3 s) is paid once. Stops at the first input that fails."""
    from pmdcid.runtime.outputs import output_folder

    out = Path(out_dir)
    if out.exists() and not out.is_dir():
        raise LogError("is a file, not a folder: with several INPUTs, -o names a folder", str(out))
    names = [Path(src).name for src in input_paths]
    for k, src in enumerate(input_paths):  # every output checked before the first simulation
        if names[k] in names[:k]:
            raise LogError(f"two INPUTs are named {names[k]}: both would be written to "
                           f"{out / names[k]}; rename one", src)
        _refuse_foreign(str(out / names[k]), opts.get("force", False))
    with output_folder(out):  # removed again if the first write fails
        return [simulate_file(src, model_path, str(out / Path(src).name), **opts)
                for src in input_paths]


__all__ = ["logs_of", "model_of", "read_and_gate", "run_diagnose", "run_fit", "run_identify",
           "run_report", "simulate_file", "simulate_files", "update_model"]
