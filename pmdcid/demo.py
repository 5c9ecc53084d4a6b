"""``pmdcid demo``: the whole pipeline on the bundled logs that carry an undeclared effect.

The logs are ``fixtures/hidden`` (synthetic, made by ``make fixtures``): the paper's motor plus
Stribeck friction that no stage is told about. The demo runs fit-electrical (blocked-rotor
steps), fit-mechanical (speed steps, km = 50.2e-3 N m/A from the paper's datasheet),
fit-nonlinear (the triangle), diagnose (which should find the Stribeck effect) and report, and
prints what each stage found. Outputs in DIR: ``model.json`` (the three fits),
``model_diagnosed.json`` and ``summary.json`` (diagnose), ``report/report.html``.
"""

from __future__ import annotations

import json
import math
import os
import threading
import time
from pathlib import Path

from pmdcid.errors import PmdcidError

#: the paper's datasheet torque constant [N m/A] (Table I), given to fit-mechanical as --km
DATASHEET_KM = 50.2e-3
#: environment variable naming another folder of demo logs
DATA_ENV = "PMDCID_DEMO_DATA"


def demo_data_dir() -> Path:
    """The folder of the demo logs: $PMDCID_DEMO_DATA, the package's data/hidden, or the
    repository's fixtures/hidden (running from a clone)."""
    need = "blocked_*.csv, step_*.csv and triangle.csv"
    if os.environ.get(DATA_ENV):
        c = Path(os.environ[DATA_ENV])
        if not ((c / "triangle.csv").is_file() and any(c.glob("blocked_*.csv"))
                and any(c.glob("step_*.csv"))):
            raise PmdcidError(f"{DATA_ENV} names a folder without the demo logs ({need})",
                              str(c))
        return c
    here = Path(__file__).resolve().parent
    cands = [here / "data" / "hidden", here.parent / "fixtures" / "hidden"]
    for c in cands:
        if (c / "triangle.csv").is_file():
            return c
    raise PmdcidError("demo logs not found (looked in " + ", ".join(map(str, cands)) +
                      "): run the demo from a clone of the repository, or set "
                      f"{DATA_ENV} to a folder holding {need}")


#: seconds between the "still running" lines of a long stage
TICK_S = 3.0


class _Stage:
    """Prints ``[k/n] what ...`` before a stage, a line every :data:`TICK_S` seconds while it
    runs, and its duration after it."""

    def __init__(self, echo, total: int):
        self.echo, self.total, self.k, self.times = echo, total, 0, {}

    def run(self, name: str, what: str, fn):
        self.k += 1
        self.echo(f"[{self.k}/{self.total}] {name}: {what} ...")
        t0 = time.perf_counter()
        done = threading.Event()

        def tick():
            while not done.wait(TICK_S):
                self.echo(f"      ... {name} running, {time.perf_counter() - t0:.0f} s")

        ticker = threading.Thread(target=tick, daemon=True)
        ticker.start()
        try:
            out = fn()
        finally:
            done.set()
            ticker.join()
        dt = time.perf_counter() - t0
        self.times[name] = dt
        self.echo(f"      done in {dt:.1f} s")
        return out


def _param_table(model, truth: dict[str, float]) -> str:
    from pmdcid.model.tables import in_words

    lines = [f"{'parameter':<10} {'value':>12} {'± stderr':>11} {'unit':<10} {'true':>11} "
             f"{'error':>8} {'/stderr':>7}  stage"]
    for name, p in model.parameters.items():
        se = f"{p.stderr:.2g}" if math.isfinite(p.stderr) else "-"
        tv = truth.get(name)
        err = f"{100 * (p.value - tv) / tv:+.1f} %" if tv else ""
        # the error in standard errors: a parameter the logs cannot pin down (a dead zone below
        # the breakaway torque) carries a wide stderr, and its error is within it
        zs = (f"{abs(p.value - tv) / p.stderr:.1f}"
              if tv and math.isfinite(p.stderr) and p.stderr > 0 else "")
        true = f"{tv:.6g}" if tv is not None else ""
        said = f": {in_words(p.interval, p.unit, p.caveat)}" if p.interval is not None else ""
        lines.append(f"{name:<10} {p.value:>12.6g} {se:>11} {p.unit:<10} {true:>11} {err:>8} "
                     f"{zs:>7}  {p.stage}{said}")
    return "\n".join(lines)


#: file marking a folder as the demo's own output (the demo may rewrite it)
MARKER = ".pmdcid-demo"


def _check_demo_folder(out: Path) -> None:
    """Refuse an existing folder that holds files and is not an earlier demo's output: the demo
    writes model.json, summary.json and report/ there and must not overwrite a user's files."""
    if out.is_dir() and any(out.iterdir()) and not (out / MARKER).is_file():
        raise PmdcidError("folder holds files the demo did not write (it would overwrite "
                          "model.json, summary.json, report/): give -o a new or empty folder",
                          str(out))


def _diagnose_available() -> bool:
    try:
        from pmdcid.diagnose import diagnose  # noqa: F401
    except ImportError:
        return False
    return True


def run_demo(out_dir="demo-output", echo=print) -> dict:
    """Run the pipeline; returns paths, the final model, the diagnose summary and timings."""
    from pmdcid.fit.results import record_notes
    from pmdcid.identify.electrical import fit_electrical
    from pmdcid.identify.mechanical import fit_mechanical
    from pmdcid.identify.nonlinear import fit_nonlinear
    from pmdcid.io import read_logs
    from pmdcid.model import Model, save_model
    from pmdcid.report import check_out_dir, make_out_dir, make_report

    _check_demo_folder(check_out_dir(out_dir))
    data = demo_data_dir()
    blocked = sorted(data.glob("blocked_*.csv"))
    steps = sorted(data.glob("step_*.csv"))
    tri = [data / "triangle.csv"]
    truth = {}
    if (data / "truth.json").is_file():
        truth = json.loads((data / "truth.json").read_text()).get("parameters", {})
    has_diag = _diagnose_available()
    out = make_out_dir(out_dir)
    (out / MARKER).write_text("written by pmdcid demo; the demo rewrites this folder\n")
    echo(f"pmdcid demo: logs from {data} (the paper's motor plus an effect no stage is told of)")
    st = _Stage(echo, 5 if has_diag else 4)
    model = Model(path=str(out / "model.json"))
    warnings: list[str] = []

    def fit(fn, paths, **kw):
        res = fn(read_logs([str(p) for p in paths]), model, **kw)
        res.apply(model)
        record_notes(res, model)  # the report shows them beside the numbers
        warnings.extend(getattr(res, "warnings", []))
        return res

    st.run("fit-electrical", f"R, L from {len(blocked)} blocked-rotor current steps",
           lambda: fit(fit_electrical, blocked))
    st.run("fit-mechanical", f"b, J from {len(steps)} speed steps (km = {DATASHEET_KM} N m/A, "
           "datasheet)", lambda: fit(fit_mechanical, steps, km=DATASHEET_KM))
    st.run("fit-nonlinear", "J, bv, bc, dz by simulation error on the triangle",
           lambda: fit(fit_nonlinear, tri))
    save_model(model, out / "model.json")
    result: dict = {"out_dir": str(out), "model_path": str(out / "model.json"), "summary": None}
    final, summary, before = model, None, None
    if has_diag:
        from pmdcid.diagnose import diagnose

        diag_logs = read_logs([str(p) for p in tri + steps])
        res = st.run("diagnose", "what the model lacks, from the residual on the triangle and "
                     "steps; add, refit",
                     lambda: diagnose(diag_logs, model))
        final, summary, before = res.model, res.summary, model
        final.path = str(out / "model_diagnosed.json")
        save_model(final, final.path)
        from pmdcid.runtime.outputs import atomic_write_text

        atomic_write_text(out / "summary.json", json.dumps(summary, indent=2) + "\n")
        result.update(summary=summary, diagnosed_model_path=final.path,
                      summary_path=str(out / "summary.json"))
    rep_logs = read_logs([str(p) for p in tri + steps])
    rep = st.run("report", f"model against {len(rep_logs)} logs, figures and metrics",
                 lambda: make_report(rep_logs, final, out / "report", summary=summary,
                                     before_model=before))
    echo("")
    echo("Parameters (true values: the ones the logs were simulated with)")
    echo(_param_table(final, truth))
    echo("")
    if summary is not None:
        added = ", ".join(summary.get("added", [])) or "nothing significant"
        echo(f"What the loop found: added {added}"
             + (" (true hidden effect: " + ", ".join(_truth_effects(data)) + ")"
                if _truth_effects(data) else ""))
        if summary.get("unexplained"):
            echo("  structure remains in the residual that no catalogue effect explains")
        b, a = summary.get("before", {}), summary.get("after", {})
        for key in ("omega_nrmse", "theta_nrmse"):
            if key in b and key in a and b[key] is not None and a[key] is not None:
                echo(f"  on the triangle and steps: {key.replace('_nrmse', '')} NRMSE before "
                     f"{b[key]:.4g} -> after {a[key]:.4g}")
    else:
        echo("diagnose is not available in this version: the report shows the fitted model")
    if warnings:
        echo("")
        echo("Warnings from the stages:")
        for w in warnings:
            echo(f"  {w}")
    echo("")
    echo(f"Report: {rep.html_path}")
    result.update(report=rep.html_path, metrics=rep.metrics_path, model=final,
                  times=dict(st.times), warnings=warnings)
    return result


def _truth_effects(data: Path) -> list[str]:
    try:
        return list(json.loads((data / "truth.json").read_text()).get("effects", []))
    except (OSError, ValueError):
        return []
