"""The speed law and the electrical lag on voltage + speed logs: a red team over seeds (issue 24,
"no delay effect added when there is none").

    python bench/lawlag.py --out DIR [--seeds 10 | --seed-list 3,20] [--jobs 2]
                           [--rates 100,500,1000] [--lags 2,4]
                           [--truths none,quadratic_drag,friction_curve,sensor_delay]
                           [--family lawlag,share03,share06,hobby,large,paper,sines]
    python bench/lawlag.py --tally DIR/results.jsonl

A bench motor with back-EMF (tests/diagnose/test_testable.py's: R 1 ohm, km = ke 0.05, J 5e-4,
every parameter moved by up to 20 % per seed) whose L/R is 2 or 4 ms, logged as voltage, speed
and angle (no current: a lumped, per-volt model) at 100 Hz, 500 Hz or 1 kHz with 0.5 rad/s of
speed noise. Two fit logs at different operating points, as in the test: a 5 -> 15 V step
starting while turning and an 8-level staircase from rest. Held out: a 10 V step from rest, a
12 -> 3 V step and a -6 -> -12 V step, predicted from their measured first samples (``simulate
--x0 measured``). Truths: nothing else, a quadratic drag, a friction curve (rising then falling
back: no named law), or a real sensor delay of 2 samples. Each case runs
:func:`pmdcid.pipeline.identify` without diagnose, then its diagnose step on the same logs (what
``pmdcid identify`` does), and records the effects, the held-out errors before and after
diagnose, and J', bv' against the per-volt truth (J R/km, bv R/km + ke) in standard errors.

The tally counts: a delay (``sensor_delay``, ``input_delay``) in the final model where the truth
has none (identify's own, or diagnose's); the wrong speed law (the curve for the drag or the
drag for the curve) and a speed law where the truth has none; a real delay missed; held-out
runs whose error diagnose raised > 5 %; J', bv', bc', dz' within +-2 standard errors (dz'
written as an interval: the truth inside it). Then a table per truth and rate of J', bv', bc',
dz' and tau_e, identify's model before diagnose and the final one: covered / runs, median |z|,
median relative standard error (issue 24's target: each covered in at least 85 % of 20 seeds).

``--family`` (default ``lawlag``: the above, unchanged) measures the same on motors and log
designs the lumped path was not built on (truth ``none``; every parameter still moved by up to
20 % per seed): ``share03`` and ``share06`` the lawlag motor with bv raised so that the back-EMF
is about 0.3 and 0.6 of the per-volt damping bv'; ``hobby`` a small motor (R 5 ohm, km = ke
0.01, J 2e-6, 6 V supply: every voltage of the design times 1/4), ``large`` a larger one (R 0.3
ohm, km = ke 0.1, J 5e-3, 24 V), both with Coulomb friction 2 % and the dead zone 3 % of the
stall torque at the supply and viscous friction 0.4 % of it at the no-load speed (as the
lawlag motor's bv); ``paper`` the lawlag motor logged as the paper's protocol (steps from rest
at 6, 12 and 20 V, 2 s each, and a +-20 V triangle of period 8 s through zero); ``sines`` the
lawlag motor driven by sines (15 V at 0.25 Hz through zero for 8 s; 10 V + 8 V at 0.7 Hz +
4 V at 2.3 Hz for 4 s). The held-out runs are the lawlag ones (voltages scaled with the
supply).
Not a test: nothing here asserts.
"""

from __future__ import annotations

import argparse
import collections
import json
import math
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

MOTOR = {"R": 1.0, "km": 0.05, "J": 5e-4, "bv": 1e-5, "bc": 2e-3, "dz": 3e-3}


def _share_motor(share: float) -> dict:
    """The lawlag motor with bv so that ke/bv' = ``share`` (bv' = bv R/km + ke)."""
    return {**MOTOR, "bv": MOTOR["km"] ** 2 / MOTOR["R"] * (1.0 / share - 1.0)}


def _sized_motor(R: float, k: float, J: float, supply: float) -> dict:
    """A motor of R, km = ke = k, J with friction a fixed share of its stall torque at
    ``supply``: Coulomb 2 %, the dead zone 3 %, viscous 0.4 % at the no-load speed."""
    stall = k * supply / R
    return {"R": R, "km": k, "J": J, "bv": 0.004 * stall / (supply / k), "bc": 0.02 * stall,
            "dz": 0.03 * stall}


#: family -> (SI motor, voltage scale of the design, fit-log design)
FAMILIES = {"lawlag": (MOTOR, 1.0, "lawlag"), "share03": (_share_motor(0.3), 1.0, "lawlag"),
            "share06": (_share_motor(0.6), 1.0, "lawlag"),
            "hobby": (_sized_motor(5.0, 0.01, 2e-6, 6.0), 0.25, "lawlag"),
            "large": (_sized_motor(0.3, 0.1, 5e-3, 24.0), 1.0, "lawlag"),
            "paper": (MOTOR, 1.0, "paper"), "sines": (MOTOR, 1.0, "sines")}
#: the truths' effects at a size that matters on this motor (SI; the delay in samples)
DRAG = {"bq": 1e-6}
#: a friction curve with no named law: up to ~0.05 N m by half the top speed, back to 0 at it
CURVE = (0.02, 0.05, 0.03)
DELAY_SAMPLES = 2
TRUTHS = ("none", "quadratic_drag", "friction_curve", "sensor_delay")
LAWS = ("quadratic_drag", "friction_curve")
DELAYS = ("sensor_delay", "input_delay")
NOISE = 0.5  # rad/s
NSUB = 64  # the truth's internal steps per sample at 100 Hz (finer than any fit)


def truth(seed: int, lag_ms: float, rate: float, eff: str, family: str = "lawlag") -> dict:
    """SI values of the seed's motor with its L/R and the effect of the truth."""
    from pmdcid.simulate import neutral_values

    rng = np.random.default_rng(seed)
    motor = FAMILIES[family][0]
    vals = {**neutral_values(), **{k: x * rng.uniform(0.8, 1.2) for k, x in motor.items()}}
    vals["ke"] = vals["km"]
    vals["L"] = vals["R"] * lag_ms * 1e-3
    if eff == "quadratic_drag":
        vals.update(DRAG)
    elif eff == "friction_curve":
        top = 24.0 / vals["km"]  # about the staircase's top speed (back-EMF dominates)
        vals.update({f"fcw{k + 1}": f * top for k, f in enumerate((0.15, 0.4, 0.7, 1.0))})
        vals.update({f"fc{k + 1}": c for k, c in enumerate(CURVE)})
    elif eff == "sensor_delay":
        vals["delay"] = DELAY_SAMPLES / rate
    return vals


def per_volt(vals: dict) -> dict:
    g = vals["R"] / vals["km"]
    return {"J": vals["J"] * g, "bv": vals["bv"] * g + vals["ke"], "bc": vals["bc"] * g,
            "dz": vals["dz"] * g, "tau_e": vals["L"] / vals["R"]}


def levels(t, pts):
    u = np.zeros_like(t)
    for t0, lev in pts:
        u[t >= t0] = lev
    return u


def make_log(name, t, u, vals, rng, start=None):
    from pmdcid.io import Log
    from pmdcid.simulate import simulate_values

    dt = float(t[1] - t[0])
    nsub = max(1, int(round(NSUB * 0.01 / dt)))
    x0 = None
    if start is not None:  # the state after 3 s at ``start`` from rest
        tt = np.arange(0.0, 3.0, 1e-3)
        s = simulate_values(tt, np.full_like(tt, start), vals, nsub=8)
        x0 = np.array([s.i[-1], s.omega[-1], 0.0])
    s = simulate_values(t, u, vals, nsub=nsub, x0=x0)
    w = s.omega + rng.normal(0.0, NOISE, t.size)
    return Log.from_arrays(t, v=u, omega=w, theta=s.theta, name=name)


def scenario(seed: int, lag_ms: float, rate: float, eff: str, family: str = "lawlag"):
    """(fit logs, held-out logs, SI truth)."""
    vals = truth(seed, lag_ms, rate, eff, family)
    rng = np.random.default_rng(1000 + seed)
    _, k, design = FAMILIES[family]
    t4, t8 = np.arange(int(4 * rate)) / rate, np.arange(int(8 * rate)) / rate
    if design == "lawlag":
        stair = k * np.array([8.0, 18.0, 12.0, 24.0, 6.0, 16.0, 22.0, 10.0])
        fit = [make_log("step_5_15V", t4, levels(t4, [(0, k * 5.0), (1.0, k * 15.0)]), vals,
                        rng, k * 5.0),
               make_log("staircase", t8, stair[np.minimum((t8 // 1).astype(int), 7)], vals,
                        rng)]
    else:
        fit = _fit_logs(design, rate, vals, rng)
    held = [make_log("held_up10", t4, levels(t4, [(0.5, k * 10.0)]), vals, rng),
            make_log("held_down", t4, levels(t4, [(0, k * 12.0), (1.0, k * 3.0)]), vals, rng,
                     k * 12.0),
            make_log("held_neg", t4, levels(t4, [(0, -k * 6.0), (1.0, -k * 12.0)]), vals, rng,
                     -k * 6.0)]
    return fit, held, vals


def _fit_logs(design: str, rate: float, vals: dict, rng) -> list:
    """The fit logs of the ``paper`` and ``sines`` designs (the lawlag motor's voltages)."""
    from pmdcid.synth import triangle

    t2, t4, t8 = (np.arange(int(s * rate)) / rate for s in (2, 4, 8))
    if design == "paper":
        return [*(make_log(f"step_{a:g}V", t2, levels(t2, [(0.2, a)]), vals, rng)
                  for a in (6.0, 12.0, 20.0)),
                make_log("triangle", t8, triangle(t8, 20.0, 8.0), vals, rng)]
    return [make_log("sine_slow", t8, 15.0 * np.sin(2 * np.pi * 0.25 * t8), vals, rng),
            make_log("sine_mix", t4, 10.0 + 8.0 * np.sin(2 * np.pi * 0.7 * t4)
                     + 4.0 * np.sin(2 * np.pi * 2.3 * t4), vals, rng, 10.0)]


def predict(model, log) -> float:
    """Speed NRMSE of ``model`` on ``log`` from its measured first samples."""
    from pmdcid.synth import simulated_columns

    _, cols, _ = simulated_columns(log, model, x0="measured")
    w = np.asarray(log["omega"], float)
    return float(np.sqrt(np.mean((cols["omega"] - w) ** 2)) / np.std(w))


#: the per-volt parameters the tally checks against the truth (issue 24's four, and the lag)
CHECKED = ("J", "bv", "bc", "dz", "tau_e")


def _est(model, name, true) -> dict | None:
    """One parameter of ``model`` against the truth: value, standard error, z (or the interval
    it is written as and whether the truth is inside)."""
    if not model.has(name):
        return None
    p = model.parameters[name]
    out = {"value": p.value, "stderr": p.stderr, "rel": p.value / true - 1}
    if p.interval is not None:
        out["interval"] = list(p.interval)
        out["inside"] = bool(p.interval[0] <= true <= p.interval[1])
    out["z"] = (p.value - true) / p.stderr if p.stderr and p.stderr > 0 else float("inf")
    return out


def _ests(model, pv) -> dict:
    return {k: _est(model, k, pv[k]) for k in CHECKED}


def _z(model, name, true) -> float | None:
    e = _est(model, name, true)
    return None if e is None else e["z"]


def run_case(seed: int, lag_ms: float, rate: float, eff: str, family: str = "lawlag") -> dict:
    from pmdcid.model import Model
    from pmdcid.pipeline import _diagnose, identify

    fit, held, vals = scenario(seed, lag_ms, rate, eff, family)
    t0 = time.time()
    row = {"seed": seed, "lag_ms": lag_ms, "rate": rate, "truth": eff}
    if family != "lawlag":
        row["family"] = family
    try:
        res = identify(fit, Model(), run_diagnose=False)
        before = res.model.copy()
        _diagnose(res, fit)
    except Exception as exc:  # a bench row, not a crash
        row["error"] = f"{type(exc).__name__}: {exc}"[-300:]
        return row
    after, pv = res.model, per_volt(vals)
    summ = res.diagnose.summary if res.diagnose is not None else {}
    row.update(secs=round(time.time() - t0, 1), before_effects=list(before.effects),
               after_effects=list(after.effects), added=list(summ.get("added", [])),
               held_before=[round(predict(before, lg), 4) for lg in held],
               held_after=[round(predict(after, lg), 4) for lg in held],
               tau_e_before=before.value("tau_e") if before.has("tau_e") else None,
               tau_e=after.value("tau_e") if after.has("tau_e") else None,
               delay=after.value("delay") if after.has("delay") else None,
               est_before=_ests(before, pv), est=_ests(after, pv),
               zJ=_z(after, "J", pv["J"]), zbv=_z(after, "bv", pv["bv"]),
               notes=[n for n in summ.get("notes", []) if "delay" in n or "tau_e" in n]
               + [n for n in res.notes if n.startswith("diagnose: skipped")])
    row["rise"] = max(a / b - 1 for a, b in zip(row["held_after"], row["held_before"],
                                                strict=True))
    return row


def cases(args) -> list[tuple]:
    seeds = ([int(s) for s in args.seed_list.split(",")] if args.seed_list
             else range(args.first, args.first + args.seeds))
    return [(s, float(lag), float(rate), eff, fam) for s in seeds
            for lag in args.lags.split(",") for rate in args.rates.split(",")
            for eff in args.truths.split(",") for fam in args.family.split(",")]


def sweep(out: Path, todo) -> None:
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "results.jsonl", "a") as f:
        for c in todo:
            row = run_case(*c)
            f.write(json.dumps(row) + "\n")
            f.flush()
            print(json.dumps(row), flush=True)


def classify(r: dict) -> dict[str, list[str]]:
    final, eff = set(r["after_effects"]), r["truth"]
    out = collections.defaultdict(list)
    if eff != "sensor_delay" and any(e in final for e in DELAYS):
        by = "identify" if any(e in r["before_effects"] for e in DELAYS) else "diagnose"
        out[f"delay where none ({by})"] += [e for e in DELAYS if e in final]
    elif eff == "sensor_delay" and "sensor_delay" not in final:
        out["real delay missed"].append(f"tau_e {r['tau_e']}")
    laws = [e for e in LAWS if e in final]
    if eff in LAWS and eff not in final:
        out["wrong speed law" if laws else "speed law missed"] += laws or [eff]
    elif eff in LAWS and len(laws) > 1:
        out["wrong speed law"] += [e for e in laws if e != eff]
    elif eff not in LAWS and laws:
        out["speed law where none"] += laws
    if any(n.startswith("diagnose: skipped") for n in r["notes"]):
        out["error"].append(r["notes"][-1])
    if r["rise"] > 0.05:
        out["held-out rise > 5 %"].append(f"{r['rise']:+.0%}")
    for k in ("zJ", "zbv"):
        if r[k] is None or not abs(r[k]) <= 2:
            out[f"{k[1:]} outside 2 se"].append(f"{r[k]:.3g}" if r[k] is not None else "none")
    for k in ("bc", "dz"):
        e = r.get("est", {}).get(k)
        if "est" in r and not _covered(e):
            out[f"{k} outside 2 se"].append("none" if e is None else
                                            str(e.get("interval")) if "interval" in e else
                                            f"{e['z']:.3g}")
    return out


def _label(r: dict) -> str:
    """A row's truth, after its family where that is not the default."""
    return f"{r['family']}:{r['truth']}" if "family" in r else r["truth"]


def _order(key: tuple) -> tuple:
    fam, _, eff = key[0].rpartition(":")
    return (list(FAMILIES).index(fam or "lawlag"), TRUTHS.index(eff), key[1])


def tally(path: Path) -> None:
    rows = [json.loads(line) for line in open(path)]
    counts: dict = collections.defaultdict(collections.Counter)
    n = collections.Counter()
    for r in rows:
        key = (_label(r), r["rate"])
        n[key] += 1
        if "error" in r:
            counts[key]["error"] += 1
            print(f"error: {r}")
            continue
        for cat, what in classify(r).items():
            counts[key][cat] += 1
            print(f"{cat}: {_label(r)} {r['rate']:g} Hz L/R {r['lag_ms']:g} ms seed {r['seed']}:"
                  f" {what}; identify {r['before_effects']} tau_e {r['tau_e_before']}, final "
                  f"{r['after_effects']} tau_e {r['tau_e']}; held-out {r['held_before']} -> "
                  f"{r['held_after']}")
    cats = ["delay where none (diagnose)", "delay where none (identify)", "real delay missed",
            "wrong speed law", "speed law missed", "speed law where none", "held-out rise > 5 %",
            "J outside 2 se", "bv outside 2 se", "bc outside 2 se", "dz outside 2 se", "error"]
    print("\n| truth | rate | runs | " + " | ".join(cats) + " |")
    print("|---" * (len(cats) + 3) + "|")
    for key in sorted(n, key=_order):
        print(f"| {key[0]} | {key[1]:g} Hz | {n[key]} | "
              + " | ".join(str(counts[key][c]) for c in cats) + " |")
    tot = collections.Counter()
    for c in counts.values():
        tot.update(c)
    print(f"| all | | {sum(n.values())} | " + " | ".join(str(tot[c]) for c in cats) + " |")
    coverage(rows)


def _covered(e: dict | None) -> bool | None:
    """The truth within +-2 printed standard errors, or inside the interval a parameter is
    written as; None when the model lacks the parameter."""
    if e is None:
        return None
    if "interval" in e:
        return e["inside"]
    return abs(e["z"]) <= 2


def coverage(rows: list[dict]) -> None:
    """Per truth and rate, identify's model (before diagnose) and the final one: for each of
    :data:`CHECKED`, the runs within +-2 se (or inside their interval) of those that have the
    parameter, the runs written as an interval, the median |z| and the median relative se."""
    rows = [r for r in rows if "est" in r]
    print("\n| truth | rate | model | " + " | ".join(CHECKED) + " |")
    print("|---" * (len(CHECKED) + 3) + "|")
    keys = sorted({(_label(r), r["rate"]) for r in rows}, key=_order)
    for key in keys:
        rs = [r for r in rows if (_label(r), r["rate"]) == key]
        for label, field in (("identify", "est_before"), ("final", "est")):
            cells = [_cell([r[field].get(k) for r in rs]) for k in CHECKED]
            print(f"| {key[0]} | {key[1]:g} Hz | {label} | " + " | ".join(cells) + " |")
    print("cells: covered/runs [intervals], median |z|, median relative se (values, not "
          "intervals)")


def _cell(es: list) -> str:
    es = [e for e in es if e is not None]
    if not es:
        return "-"
    cov = sum(bool(_covered(e)) for e in es)
    nint = sum("interval" in e for e in es)
    vals = [e for e in es if "interval" not in e and math.isfinite(e["z"])]
    mz = np.median([abs(e["z"]) for e in vals]) if vals else math.nan
    rse = np.median([e["stderr"] / abs(e["value"]) for e in vals if e["value"]]) if vals \
        else math.nan
    return (f"{cov}/{len(es)}" + (f" [{nint}]" if nint else "")
            + f", {mz:.2g}, {100 * rse:.2g} %")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, help="run the cases, rows into OUT/results.jsonl")
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--first", type=int, default=1)
    ap.add_argument("--seed-list", help="comma-separated seeds (in place of --first, --seeds)")
    ap.add_argument("--jobs", type=int, default=1, help="processes (cases split between them)")
    ap.add_argument("--rates", default="100,500,1000")
    ap.add_argument("--lags", default="2,4", help="L/R [ms]")
    ap.add_argument("--truths", default=",".join(TRUTHS))
    ap.add_argument("--family", default="lawlag",
                    help="comma-separated: " + ",".join(FAMILIES) + " (docstring)")
    ap.add_argument("--part", help=argparse.SUPPRESS)
    ap.add_argument("--tally", type=Path, help="count a results.jsonl")
    args = ap.parse_args(argv)
    if args.tally:
        tally(args.tally)
        return 0
    if args.out is None:
        ap.error("give --out DIR or --tally FILE")
    todo = cases(args)
    if args.part:
        j, k = map(int, args.part.split("/"))
        sweep(args.out, todo[j::k])
        return 0
    if args.jobs == 1:
        sweep(args.out, todo)
        return 0
    passed = [a for a in (argv if argv is not None else sys.argv[1:])]
    procs = [subprocess.Popen([sys.executable, __file__, *passed, "--part", f"{j}/{args.jobs}"])
             for j in range(args.jobs)]
    return max(p.wait() for p in procs)


if __name__ == "__main__":
    sys.exit(main())
