"""``pmdcid report``: the model against measured logs, for a person to look at.

:func:`make_report` simulates the model on each log's input, computes the metrics of
:mod:`pmdcid.report.metrics`, draws the figures of :mod:`pmdcid.report.figures` and writes
``DIR/report.html`` (self-contained), ``DIR/metrics.json`` (every number on the page) and the
figures as ``DIR/*.png``.
"""

from __future__ import annotations

import datetime as _dt
import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from pmdcid.errors import LogError, warn
from pmdcid.fit.results import speed_against
from pmdcid.model import Model
from pmdcid.runtime.outputs import check_folder_outputs


@dataclass
class ReportResult:
    """What :func:`make_report` wrote: paths and the metrics (as in metrics.json)."""

    out_dir: str
    html_path: str
    metrics_path: str
    metrics: dict
    figures: list[str] = field(default_factory=list)

    def __repr__(self) -> str:  # one line: not the metrics (every lag of every residual)
        mean = ", ".join(f"{k.replace('_nrmse', '')} {v:.3g}"
                         for k, v in (self.metrics.get("mean") or {}).items() if v is not None)
        return (f"ReportResult({self.html_path!r}, {len(self.figures)} figures"
                f"{f', mean NRMSE {mean}' if mean else ''})")


def check_out_dir(out_dir) -> Path:
    """Refuse an output folder that is a file or lies under one (one clear line)."""
    p = Path(out_dir)
    if p.exists() and not p.is_dir():
        raise LogError("is a file, not a folder: give -o a folder for the report", str(p))
    up = next((a for a in [p, *p.parents] if a.exists()), None)
    if up is not None and not up.is_dir():
        raise LogError("is a file, not a folder: cannot write the report under it", str(up))
    return p


def make_out_dir(out_dir) -> Path:
    from pmdcid.runtime.outputs import current

    p = check_out_dir(out_dir)
    first_new = next((a for a in reversed([p, *p.parents]) if not a.exists()), None)
    try:
        p.mkdir(parents=True, exist_ok=True)
        if first_new is not None and current() is not None:
            current().created_dir(str(first_new))  # removed again if the report fails
    except OSError as exc:
        raise LogError(f"cannot create the output folder ({exc.strerror or exc})", str(p)) from None
    return p


def write_bytes_atomic(path: Path, data: bytes) -> None:
    """Write ``data`` to ``path`` through a temporary file in the same folder and a rename."""
    from pmdcid.runtime.outputs import atomic_write

    atomic_write(path, lambda fh: fh.write(data), binary=True)


def _clean(x):
    """JSON-safe copy: NaN/inf -> None, tuples -> lists, numpy scalars -> Python."""
    if isinstance(x, dict):
        return {str(k): _clean(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_clean(v) for v in x]
    if isinstance(x, bool) or x is None or isinstance(x, str):
        return x
    if isinstance(x, int):
        return x
    try:
        v = float(x)
    except (TypeError, ValueError):
        return str(x)
    return v if math.isfinite(v) else None


def load_summary(path) -> dict:
    """Read a diagnose summary file (JSON object) given with ``--summary``."""
    from pmdcid.errors import PmdcidError
    from pmdcid.io.text import read_text

    try:
        obj = json.loads(read_text(path))
    except FileNotFoundError:
        raise PmdcidError("no such summary file", str(path)) from None
    except (OSError, UnicodeDecodeError) as exc:
        raise PmdcidError(f"cannot read summary ({exc})", str(path)) from None
    except json.JSONDecodeError as exc:
        raise PmdcidError(f"summary is not valid JSON (line {exc.lineno}: {exc.msg})",
                          str(path)) from None
    except RecursionError:
        raise PmdcidError("summary is nested too deeply to be a diagnose summary; give the "
                          "file diagnose --summary wrote", str(path)) from None
    if not isinstance(obj, dict):
        raise PmdcidError("summary must hold a JSON object (diagnose --summary)", str(path))
    bad = _summary_shape_error(obj)
    if bad:
        raise PmdcidError(f"summary {bad}: give the file diagnose --summary wrote", str(path))
    return obj


def _is_num(x) -> bool:
    return x is None or (isinstance(x, (int, float)) and not isinstance(x, bool))


def _summary_shape_error(obj: dict) -> str | None:
    """What in a diagnose summary has the wrong type (None: fields as in docs/cli.md)."""
    added = obj.get("added", [])
    if not isinstance(added, list) or not all(isinstance(a, str) for a in added):
        return "field 'added' must be a list of effect names"
    cands = obj.get("candidates", [])
    if not isinstance(cands, list) or not all(
            isinstance(c, dict) and isinstance(c.get("effect", ""), str)
            and _is_num(c.get("delta_bic")) and _is_num(c.get("omega_nrmse")) for c in cands):
        return "field 'candidates' must be a list of {effect, delta_bic, ...} objects"
    for key in ("before", "after"):
        v = obj.get(key, {})
        if v is not None and (not isinstance(v, dict) or not all(
                _is_num(x) for k, x in v.items() if k.endswith("nrmse"))):
            return f"field '{key}' must be an object of error names -> numbers"
    if not isinstance(obj.get("unexplained", False), bool):
        return "field 'unexplained' must be true or false"
    return None


def parameter_table(model: Model) -> dict:
    out = {}
    for name, par in model.parameters.items():
        rel = abs(par.stderr / par.value) * 100 if par.value and math.isfinite(par.stderr) else None
        out[name] = {"value": par.value, "stderr": par.stderr, "rel_stderr_percent": rel,
                     "unit": par.unit, "stage": par.stage}
        if par.interval is not None:  # the logs only bound it: said in words on the page
            out[name]["interval"] = list(par.interval)
        if par.caveat:
            out[name]["caveat"] = par.caveat
    return out


def _comparable(logs, model: Model) -> list:
    """The logs the model can be compared on: a blocked-rotor log measures only the current,
    which a lumped (per-volt) model does not simulate; such logs are left out with a warning
    (all of them: an error saying so)."""
    from pmdcid.simulate.measured import predicts_current

    if predicts_current(model):
        return list(logs)
    kept = [lg for lg in logs if not lg.blocked]
    left = [str(lg.path) for lg in logs if lg.blocked]
    if not kept:
        raise LogError("are blocked-rotor logs (current only), and the model is lumped (per "
                       "volt: it simulates no current): nothing to compare; give logs where the "
                       "rotor turns, or a model in SI (--km)", ", ".join(left))
    if left:
        warn("blocked-rotor log(s) left out of the report: the model is lumped (per volt) and "
             "simulates no current, all they measure (give --km for an SI model)",
             ", ".join(left))
    return kept


def _before_after(logs, names, model: Model, before_model: Model | None) -> dict | None:
    from pmdcid.report.compare import mean_errors, model_errors

    if before_model is None:
        if not model.effects:
            return None
        before_model = model.copy()
        before_model.effects = []
        label = "the same parameters with effects = []"
    else:
        label = "the model given as 'before'"
    before = model_errors(logs, before_model)
    after = model_errors(logs, model)
    change = [{s: (100.0 * (a[s] - b[s]) / b[s] if a.get(s) is not None and b.get(s)
                   else None) for s in a} for b, a in zip(before, after, strict=True)]
    return {"effects": [e for e in model.effects if e not in before_model.effects],
            "before_label": label, "logs": names, "before": before, "after": after,
            "change_percent": change, "mean_before": mean_errors(before),
            "mean_after": mean_errors(after)}


def make_report(logs, model: Model, out_dir, summary: dict | None = None,
                before_model: Model | None = None, progress=None,
                force: bool = False) -> ReportResult:
    """Compare ``model`` with every log and write the report into ``out_dir`` (see module doc).

    ``summary`` is a diagnose summary (docs/cli.md) shown on the page; without it a
    ``diagnose`` record in ``model.extra`` is used. When the model carries effects (or
    ``before_model`` is given) the page shows the error before and after them.
    ``progress(msg)`` is called before each log's simulation and before the figures.
    An existing report.html, metrics.json or figure pmdcid did not write is replaced only with
    ``force`` (:func:`pmdcid.runtime.outputs.check_folder_outputs`).
    """
    from pmdcid import __version__
    from pmdcid.report import html
    from pmdcid.report.compare import compare_log, mean_errors
    from pmdcid.report.metrics import LOW_SPEED_FRACTION, MAX_LAG
    from pmdcid.report.notes import report_notes
    from pmdcid.report.parallel import FigureDrawer
    from pmdcid.runtime.outputs import output_folder

    if not logs:
        raise LogError("no log files given")
    logs = _comparable(logs, model)
    names = check_report_outputs(out_dir, logs, force)  # before the work, and again below
    say = progress or (lambda msg: None)
    # started before the simulations: the workers' imports overlap them (report/parallel.py)
    with FigureDrawer(2 * len(logs) + 2) as drawer:
        cmps = []
        for k, (log, name) in enumerate(zip(logs, names, strict=True)):
            say(f"report: simulating {name} ({k + 1}/{len(logs)})")
            cmps.append(compare_log(log, model, name))
        ba = _before_after(logs, names, model, before_model)
        against = speed_against([(c.sim.omega, np.asarray(c.log["omega"], float))
                                 for c in cmps if c.log.has("omega") and not c.blocked])
        if against:
            warn(against, ", ".join(str(lg.path) for lg in logs))
        say("report: figures")
        figs = drawer.draw(figure_jobs(cmps, ba, names))
    if summary is None:
        rec = model.extra.get("diagnose") or model.extra.get("fits", {}).get("diagnose")
        summary = rec if isinstance(rec, dict) and "added" in rec else None
    metrics = _clean({
        "version": __version__,
        "created": _dt.datetime.now(_dt.timezone.utc).strftime("%Y-%m-%d %H:%M UTC"),
        "model_path": model.path or "(in memory)",
        "model_name": os.path.basename(model.path) if model.path else "model",
        "effects": list(model.effects),
        "parameters": parameter_table(model),
        "low_speed_fraction": LOW_SPEED_FRACTION,
        "low_speed_percent": 100 * LOW_SPEED_FRACTION,
        "max_lag": MAX_LAG,
        "cross_lags": 2 * MAX_LAG + 1,
        "logs": [c.metrics for c in cmps],
        "mean": mean_errors(model_errors_from(cmps)),
        "before_after": ba,
        "summary": summary,
        "notes": report_notes(model, summary, logs, [against] if against else []),
        "lumped": model.extra.get("lumped") is True,
        "figures": sorted(figs),
    })
    page = html.render(metrics, figs)
    _refuse_overwriting_inputs(out_dir, [*figs, "metrics.json", "report.html"],
                               [str(lg.path) for lg in logs] + [model.path or ""])
    check_folder_outputs(out_dir, [*figs, "metrics.json", "report.html"], force)
    with output_folder(out_dir) as out:  # removed again if a write fails
        for name, png in figs.items():
            write_bytes_atomic(out / name, png)
        metrics_path = out / "metrics.json"
        html_path = out / "report.html"
        write_bytes_atomic(metrics_path, (json.dumps(metrics, indent=1) + "\n").encode())
        write_bytes_atomic(html_path, page.encode("utf-8"))
    return ReportResult(str(out), str(html_path), str(metrics_path), metrics, sorted(figs))


def figure_jobs(cmps, ba: dict | None, names: list[str]) -> list:
    """The report's figures as jobs (report/parallel.py): each log's overlay and residual (one
    reused figure per layout), the fit per log, the error before and after when there is one."""
    from pmdcid.report import figures
    from pmdcid.report.compare import figure_view
    from pmdcid.report.parallel import FigureJob

    jobs = []
    for c in cmps:
        c.metrics["figures"] = [f"{c.name}_overlay.png", f"{c.name}_residual.png"]
        view, size = figure_view(c)
        args = (view,)  # one tuple for both: sent once
        jobs += [FigureJob(c.metrics["figures"][0], figures.overlay_figure, args, True, size),
                 FigureJob(c.metrics["figures"][1], figures.residual_figure, args, True, size)]
    jobs.append(FigureJob("fit.png", figures.fit_figure,
                          ([(c.name, c.metrics["signals"]) for c in cmps],)))
    if ba is not None:
        jobs.append(FigureJob("before_after.png", figures.before_after_figure,
                              (names, ba["before"], ba["after"])))
    return jobs


def unique_names(logs) -> list[str]:
    """Short labels for the logs (file names, made unique)."""
    names: list[str] = []
    for log in logs:
        base = os.path.splitext(os.path.basename(str(log.path)))[0] or "log"
        name, k = base, 2
        while name in names:
            name, k = f"{base}-{k}", k + 1
        names.append(name)
    return names


def check_report_outputs(out_dir, logs, force: bool = False) -> list[str]:
    """Refuse, before any work, an output folder that is a file, and a file a report of
    ``logs`` would replace in it that pmdcid did not write (unless ``force``). Returns the
    logs' names on the page."""
    check_out_dir(out_dir)
    names = unique_names(logs)
    check_folder_outputs(out_dir, _file_names(names), force)
    return names


def _file_names(names: list[str]) -> list[str]:
    """The files a report of logs ``names`` writes (as :func:`figure_jobs` names them)."""
    figs = [f"{n}_{kind}.png" for n in names for kind in ("overlay", "residual")]
    return [*figs, "fit.png", "before_after.png", "metrics.json", "report.html"]


def _refuse_overwriting_inputs(out_dir, names, inputs) -> None:
    """An input log or the model file must never be one of the report's outputs."""
    from pmdcid.runtime.outputs import input_at

    for name in names:
        src = input_at(Path(out_dir) / name, inputs)
        if src is not None:
            raise LogError(f"the report would overwrite this input ({name}); choose another -o",
                           src)


def model_errors_from(cmps) -> list[dict]:
    """Per log: signal -> NRMSE, from the comparisons already made."""
    return [{s: sm["nrmse"] for s, sm in c.metrics["signals"].items()} for c in cmps]


__all__ = ["ReportResult", "check_out_dir", "check_report_outputs", "load_summary", "make_report",
           "unique_names"]
