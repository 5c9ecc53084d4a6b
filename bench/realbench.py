"""`make realbench`: every real rig in ../shared/data — fit on some logs, predict the others.

For each rig: the held-out speed NRMSE (mean over held-out runs) of the paper's stage sequence
and of ``identify``, against a linear first-order model with an input offset fitted on the same
logs and the rig's repeatability floor (see bench/realdata.py). Target (issue "Real rigs"):
each model <= max(linear / 2, 1.2 x floor) and never above the linear baseline; diagnose never
raises a held-out run's error by more than 5 % (identify's model before diagnose, "base", beside
it: one identify run, diagnose called on its model as identify calls it).

    python bench/realbench.py [--write docs/real-data.md] [--no-diagnose] [--rig NAME]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from bench import closedloop, realdata  # noqa: E402

BEGIN, END = "<!-- realbench:begin -->", "<!-- realbench:end -->"
LABELS = ("paper", "identify")
#: identify's model before diagnose
BASE = "base"


def run(args) -> list[dict]:
    out = []
    for rig in realdata.rigs():
        if args.rig and rig.name != args.rig:
            continue
        t0 = time.perf_counter()
        print(f"... {rig.name}", file=sys.stderr, flush=True)
        try:
            models = {"paper": realdata.paper_sequence(rig),
                      **identify_models(realdata.read(rig, rig.steps + rig.rich), args)}
        except Exception as exc:  # a rig the tool cannot identify is a finding, not a crash
            print(f"{rig.name}: failed: {type(exc).__name__}: {exc}", file=sys.stderr)
            continue
        res = realdata.evaluate(rig, models)
        res["mean"] = realdata.summarise(res, (*LABELS, BASE))
        res["lag"] = realdata.lag_drift(rig, models["identify"])
        res["seconds"] = time.perf_counter() - t0
        print(table([res]).split("\n\n")[0], file=sys.stderr, flush=True)
        out.append(res)
    if args.rig in (None, "micromouse-pid") and closedloop.MICROMOUSE.is_dir():
        out.append(micromouse(args))
    return out


def identify_models(logs, args) -> dict:
    """identify's model ("identify") and, with diagnose, its model before diagnose ("base")."""
    if args.no_diagnose:
        from pmdcid.model import Model
        from pmdcid.pipeline import identify

        model = identify(logs, Model(), run_diagnose=False).model
        return {"identify": model, BASE: model}
    before, after = realdata.identify_before_after(logs)
    return {"identify": after, BASE: before}


def micromouse(args) -> dict:
    """micromouse-pid (loop-timed, closed loop): fitted on the 1 and 10 ms controller periods,
    the 2 and 5 ms runs held out, each simulated from its logged command (bench/closedloop.py;
    the controller route's figures are printed there). 'paper' is fit-nonlinear on the logged
    output (no steps in these logs), 'identify' the whole pipeline; the logs read by pmdcid.io
    (loop-timed: on a uniform grid, the input stepped inside its samples; docs/io.md, 'Clocks')."""
    from pmdcid.identify.runners import per_volt, stage_nonlinear
    from pmdcid.model import Model
    from pmdcid.model.lumped import mark_lumped

    t0 = time.perf_counter()
    print("... micromouse-pid", file=sys.stderr, flush=True)
    fit = [closedloop.uniform_log(closedloop.MICROMOUSE / n)
           for n in closedloop.FIT]
    paper = Model()
    mark_lumped(paper)
    res = stage_nonlinear(fit, paper)
    per_volt(res)
    res.apply(paper)
    models = {"paper": paper, **identify_models(fit, args)}
    lin = realdata.fit_linear(fit)
    rows = []
    for name in closedloop.HELD:
        lg = closedloop.uniform_log(closedloop.MICROMOUSE / name)
        row = {"log": name, "protocol": "other period", "floor": float("nan"),
               "linear": realdata.nrmse(realdata.linear_sim(lin, lg), lg["omega"])}
        row.update({k: realdata.predict(m, lg) for k, m in models.items()})
        rows.append(row)
    out = {"rig": "micromouse-pid", "why": micromouse.__doc__.split(":")[0],
           "fit": list(closedloop.FIT), "rows": rows, "linear_params": lin.tolist()}
    out["mean"] = realdata.summarise(out, (*LABELS, BASE))
    out["lag"] = []
    out["seconds"] = time.perf_counter() - t0
    return out


def table(results) -> str:
    lines = ["| rig | fitted on | held out | linear | floor | target | paper | identify "
             "(before diagnose) |", "|---|---|---|---|---|---|---|---|"]
    for r in results:
        m = r["mean"]
        ok = {k: ("" if m[k] <= max(m["target"], 0) and m[k] <= m["linear"] else " ✗")
              for k in LABELS}
        held = ", ".join(sorted({row["protocol"] for row in r["rows"]}))
        lines.append(f"| {r['rig']} | {', '.join(r['fit'])} | {held} ({len(r['rows'])} runs) "
                     f"| {m['linear']:.3f} | {m['floor']:.3f} | {m['target']:.3f} "
                     f"| {m['paper']:.3f}{ok['paper']} | {m['identify']:.3f}{ok['identify']} "
                     f"({m[BASE]:.3f}) |")
    lines.append("")
    lines.append("Per held-out run (speed NRMSE):")
    lines.append("")
    lines.append("| rig | log | linear | floor | paper | identify (before diagnose) |")
    lines.append("|---|---|---|---|---|---|")
    for r in results:
        for row in r["rows"]:
            lines.append(f"| {r['rig']} | {row['log']} | {row['linear']:.3f} | "
                         f"{row['floor']:.3f} | {row['paper']:.3f} | {row['identify']:.3f} "
                         f"({row[BASE]:.3f}) |")
    lines += ["", "Held-out runs whose error diagnose raised by more than 5 % (the issue's rule):",
              ""]
    rises = [f"- {r['rig']}: {d}" for r in results for d in realdata.diagnose_rises(r, BASE)]
    lines += rises or ["- none"]
    lines += ["", "Held-out runs whose speed lags identify's model by an amount that changes along "
              "the run (pmdcid.diagnose.timing, the warning diagnose gives):", ""]
    drifting = [f"- {r['rig']}: {d}" for r in results for d in r.get("lag", [])]
    lines += drifting or ["- none"]
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--write", type=Path, help="put the table into this markdown file")
    ap.add_argument("--no-diagnose", action="store_true", help="identify without diagnose")
    ap.add_argument("--rig", help="only this rig")
    args = ap.parse_args(argv)
    if not realdata.rigs():
        print(f"no real data under {realdata.SHARED}: nothing to do", file=sys.stderr)
        return 0
    results = run(args)
    text = table(results)
    print(text)
    for r in results:
        print(f"{r['rig']}: {r['seconds']:.1f} s; why these logs: {r['why']}")
    if args.write:
        doc = args.write.read_text()
        a, b = doc.index(BEGIN) + len(BEGIN), doc.index(END)
        args.write.write_text(doc[:a] + "\n" + text + "\n" + doc[b:])
    return 0


if __name__ == "__main__":
    sys.exit(main())
