"""Torque-driven rigs (issue #24): what identify writes, against the truth, over seeds.

    python bench/torquerig.py --out DIR [--seeds 10] [--jobs 2] [--cases c,c2,c2:stribeck,k]
    python bench/torquerig.py --table DIR/results.jsonl

Cases ``c``, ``c2``, ``c2:EFFECT`` are bench/thinlogs.py's torque rig (0.05-0.15 N m, 100 Hz,
one or two step logs, held-out steps and a PI-controlled run); ``k`` is that rig logged at 1 kHz
with a small true torque offset (tau0 = +0.1 bc): the step logs of ``c2`` (both directions).
Per run: ``pmdcid identify --no-diagnose`` and ``pmdcid identify`` on the fit logs (the CLI of
the tree on PYTHONPATH); the torque_offset each wrote (value, standard error, truth), J, bv, bc
against the truth (relative error, within 2 standard errors?), the held-out speed NRMSE of both
models and of the linear first-order-with-offset baseline (bench/realdata.py's) fitted on the
same logs. Not a test: nothing here asserts.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))
from bench import thinlogs  # noqa: E402

CASES = ("c", "c2", "c2:stribeck", "k")
#: the ``k`` case's true offset, a fraction of its Coulomb friction
K_OFFSET = 0.1


def scenario(case: str, seed: int):
    """thinlogs' torque scenario; ``k``: c2's at 1 kHz with a true tau0."""
    if case != "k":
        return thinlogs.scenario(case, seed)
    thinlogs.RATE = 1000.0
    try:
        rng = np.random.default_rng(seed)
        vals = thinlogs.truth(rng, thinlogs.TORQUE_RIG, {}, False)
        vals["tau0"] = K_OFFSET * vals["bc"]
        k = 0.01
        sl = thinlogs.step_log
        fit = [sl(vals, "stepA", [(0.0, 5 * k), (1.0, 15 * k)], rng, True, False, 5 * k),
               sl(vals, "stepB", [(0.5, -8 * k)], rng, True)]
        held = [sl(vals, "held_up10", [(0.5, 10 * k)], rng, True),
                sl(vals, "held_down", [(0.0, 12 * k), (1.0, 3 * k)], rng, True, False, 12 * k),
                sl(vals, "held_neg", [(0.0, -6 * k), (1.0, -12 * k)], rng, True, False, -6 * k),
                thinlogs.pi_log(vals, rng, True, 40.0, 20 * k)]
    finally:
        thinlogs.RATE = 100.0
    return fit, held, vals, None, None


def linear_heldout(fp, hp) -> list[float]:
    """Held-out NRMSE of the first-order-with-offset baseline fitted on the fit logs."""
    from bench.realdata import fit_linear, linear_sim, nrmse
    from pmdcid.io import read_log
    from pmdcid.io.mapping import parse_mapping

    mp = parse_mapping(["omega=speed_rpm*rpm"])
    x = fit_linear([read_log(p, mapping=mp) for p in fp])
    out = []
    for p in hp:
        lg = read_log(p, mapping=mp)
        out.append(round(nrmse(linear_sim(x, lg), np.asarray(lg["omega"], float)), 4))
    return out


def params_of(path: str) -> dict:
    from pmdcid.model import load_model

    m = load_model(path)
    out = {"effects": list(m.effects)}
    for n in ("J", "bv", "bc", "dz", "tau0", "fs", "ws"):
        if m.has(n):
            p = m.parameters[n]
            out[n] = [p.value, p.stderr]
    return out


def run_case(out: Path, case: str, seed: int) -> dict:
    folder = out / f"{case.replace(':', '-')}_{seed}"
    folder.mkdir(parents=True, exist_ok=True)
    fit, held, vals, eff, _ = scenario(case, seed)
    fp = [thinlogs.write(folder, *x) for x in fit]
    hp = [thinlogs.write(folder, *x) for x in held]
    row = {"case": case, "seed": seed,
           "truth": {n: vals.get(n, 0.0) for n in ("J", "bv", "bc", "dz", "tau0", "fs", "ws")}}
    for label, extra in (("before", ["--no-diagnose"]), ("after", [])):
        path = str(folder / f"{label}.json")
        t0 = time.time()
        r = thinlogs.pmdcid("identify", *fp, "-m", path, *extra, "-c", "omega=speed_rpm*rpm")
        row[f"secs_{label}"] = round(time.time() - t0, 1)
        if r.returncode:
            row[f"error_{label}"] = r.stderr.strip()[-300:]
            continue
        row[label] = params_of(path)
        row[f"held_{label}"] = [round(thinlogs.predict(path, p), 4) for p in hp]
    row["held_linear"] = linear_heldout(fp, hp)
    return row


def sweep(out: Path, cases, seeds) -> None:
    thinlogs.sweep(out, cases, seeds, run_case)


def _rel(m: dict, t: dict, n: str) -> str:
    if n not in m:
        return "-"
    v, se = m[n]
    tv = t.get(n, 0.0)
    within = "y" if se is not None and np.isfinite(se) and abs(v - tv) <= 2 * se else "n"
    return f"{(v - tv) / tv:+.0%}{within}" if tv else f"{v:.2g}{within}"


def table(path: Path, which: str = "before") -> None:
    """One line per run: tau0 written (value ± se, truth), J/bv/bc relative error and whether
    within 2 standard errors (y/n), mean held-out NRMSE of identify and of the linear baseline."""
    rows = [json.loads(line) for line in open(path)]
    print(f"{'case':<12}{'seed':>4}  {'tau0 (± se) [truth]':<28}{'J':>9}{'bv':>9}{'bc':>9}"
          f"  {'held':>7} {'held+d':>7} {'linear':>7}  effects")
    agg = {}
    for r in sorted(rows, key=lambda r: (r["case"], r["seed"])):
        m = r.get(which)
        if m is None:
            print(f"{r['case']:<12}{r['seed']:>4}  error {r.get('error_' + which, '')[:80]}")
            continue
        t = r["truth"]
        tau0 = (f"{m['tau0'][0]:+.2e} ± {m['tau0'][1]:.1e}" if "tau0" in m else "none")
        tau0 += f" [{t['tau0']:.1e}]"
        hb, ha, hl = (float(np.mean(r[k])) if r.get(k) else np.nan
                      for k in ("held_before", "held_after", "held_linear"))
        print(f"{r['case']:<12}{r['seed']:>4}  {tau0:<28}{_rel(m, t, 'J'):>9}"
              f"{_rel(m, t, 'bv'):>9}{_rel(m, t, 'bc'):>9}  {hb:7.4f} {ha:7.4f} {hl:7.4f}  "
              f"{','.join(m['effects'])}")
        a = agg.setdefault(r["case"], collections_default())
        a["n"] += 1
        a["tau0"] += "tau0" in m
        a["Jin"] += _rel(m, t, "J").endswith("y")
        a["Jerr"].append(abs(m["J"][0] / t["J"] - 1))
        a["hb"].append(hb)
        a["ha"].append(ha)
        a["hl"].append(hl)
        a["rise"] += any(y > 1.05 * x for x, y in zip(r["held_before"], r["held_after"],
                                                     strict=True))
    print()
    for c, a in agg.items():
        print(f"{c:<12} n {a['n']}: torque_offset written {a['tau0']}, J within 2 se "
              f"{a['Jin']}, |J err| median {np.median(a['Jerr']):.0%} max {max(a['Jerr']):.0%}, "
              f"held-out NRMSE mean {np.mean(a['hb']):.4f} (after diagnose "
              f"{np.mean(a['ha']):.4f}), linear {np.mean(a['hl']):.4f}, runs diagnose raised "
              f">5 % {a['rise']}")


def collections_default() -> dict:
    return {"n": 0, "tau0": 0, "Jin": 0, "Jerr": [], "hb": [], "ha": [], "hl": [], "rise": 0}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path)
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--cases", default=",".join(CASES))
    ap.add_argument("--seed-list", help=argparse.SUPPRESS)
    ap.add_argument("--table", type=Path, help="tabulate a results.jsonl")
    ap.add_argument("--which", default="before", choices=("before", "after"),
                    help="the model tabulated: identify --no-diagnose or identify")
    args = ap.parse_args(argv)
    if args.table:
        table(args.table, args.which)
        return 0
    if args.out is None:
        ap.error("give --out DIR or --table FILE")
    return thinlogs.run_or_split(__file__, sweep, args)


if __name__ == "__main__":
    sys.exit(main())
