"""diagnose on thin logs (issue #24): a red team through the command line, over seeds.

    python bench/thinlogs.py --out DIR [--seeds 10] [--first 1] [--jobs 2]
                             [--cases a,b2:stribeck,...] [--rate 1000] [--build2]
    python bench/thinlogs.py --tally DIR/results.jsonl

A motor (R 2 ohm, km 0.02, J 1e-4 on a flywheel: a 0.5 s time constant; back-EMF; every
parameter moved by up to 20 % per seed) logged as speed in rpm at 100 Hz with 1 rad/s noise and
the voltage, no current (a lumped model). Each case writes its fit logs as CSV, runs ``pmdcid
identify --no-diagnose`` and ``pmdcid identify`` on them (the CLI of the tree on PYTHONPATH),
then predicts four held-out runs (a 10 V step from rest, a 12 -> 3 V step, a -6 -> -12 V step,
a PI-controlled run with a reversal) from their measured first samples, as ``pmdcid simulate
--x0 measured`` does (``synth.simulated_columns``, the function that command calls). Cases:

- ``a``: one 5 -> 15 V step log starting while turning, no extra effect; ``a2``: the same plus
  a -8 V step from rest (another operating point, not a repeat);
- ``b1:EFFECT``: the one log with a true effect; ``b2:EFFECT``: the two logs with it;
- ``c``, ``c2``, ``c2:EFFECT``: a torque-driven rig (``tau`` column), one or two logs;
- ``d``, ``d:brush_drop``, ``d:input_delay``: the two logs with the current logged, a real
  brush drop, a real 20 ms input latency or none (the latency's case holds no PI run: a late
  input is not simulated in closed loop).

``--rate 1000``: every log at 1 kHz instead of 100 Hz (the same motor, noise per sample).
``--build2`` (issue 24's Build 2): also ``pmdcid diagnose FIT -m BEFORE -o M2 --summary S``
from identify's model before diagnose, then ``simulate LOG -m M2 --x0 measured`` and ``report
FIT -m M2`` on each fit log; their speed NRMSE should equal the summary's "after" figure for
that log (the tally counts a relative difference beyond 1e-3 as a mismatch). The fit logs
start while turning (``stepA``), so a model with a delay is checked from a moving start.

The tally counts false adds (an effect in the final model the truth lacks, by identify's stages
or by diagnose; back-EMF is real on every voltage rig), true effects added from one log (b1),
the friction curve standing in for a named law, misses (the truth's effect absent though leaving
it out of the truth moves a held-out run by more than 2 % NRMSE) and held-out runs whose error
diagnose raised by more than 5 %, and with ``--build2`` the runs whose simulate or report figure
is off the summary's (or that failed).
Not a test: nothing here asserts. About 15 minutes for 10 seeds on 2 free cores (``--build2``
about twice that; 1 kHz several times longer).
"""

from __future__ import annotations

import argparse
import collections
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
RPM = 60 / (2 * np.pi)
RATE = 100.0
MOTOR = {"R": 2.0, "L": 1e-3, "km": 0.02, "J": 1e-4, "bv": 2e-6, "bc": 2e-3, "dz": 1e-3}
TORQUE_RIG = {"J": 2e-3, "bv": 2e-3, "bc": 0.02, "dz": 0.01}
#: true effects at a size that matters on these rigs (SI)
EFFECT = {"stribeck": {"fs": 0.01, "ws": 100.0}, "sensor_delay": {"delay": 0.02},
          "speed_offset": {"omega0": 15.0}, "viscous_asymmetry": {"dbv": 3e-5},
          "quadratic_drag": {"bq": 5e-8}, "brush_drop": {"vb": 0.6},
          "input_delay": {"latency": 0.02}}
EFFECT_T = {"stribeck": {"fs": 0.03, "ws": 3.0}, "quadratic_drag": {"bq": 1e-5}}
EFFECTS = ("stribeck", "sensor_delay", "speed_offset", "viscous_asymmetry", "quadratic_drag")
CASES = (["a", "a2"] + [f"b1:{e}" for e in EFFECTS] + [f"b2:{e}" for e in EFFECTS]
         + ["c", "c2", "c2:stribeck", "c2:quadratic_drag", "d", "d:brush_drop",
            "d:input_delay"])
#: the friction curve may stand in for these named laws (counted apart, not as a false add)
STANDS_IN = {"quadratic_drag", "stribeck"}


def truth(rng, base: dict, extra: dict, voltage: bool) -> dict:
    from pmdcid.simulate import neutral_values

    vals = {**neutral_values(), **{k: x * rng.uniform(0.8, 1.2) for k, x in base.items()}}
    if voltage:
        vals["ke"] = vals["km"]
    return {**vals, **extra}


def levels(t: np.ndarray, pts) -> np.ndarray:
    """A piecewise-constant input: [(from time, level), ...]."""
    u = np.zeros_like(t)
    for t0, lev in pts:
        u[t >= t0] = lev
    return u


def turning(vals: dict, u0: float, torque: bool) -> np.ndarray:
    """The state after 3 s at ``u0`` from rest."""
    from pmdcid.simulate import simulate_values

    t = np.arange(0, 3.0, 1e-3)
    s = simulate_values(t, np.full_like(t, u0), vals, torque)
    return np.array([0.0 if torque else s.i[-1], s.omega[-1], 0.0])


def step_log(vals, name, pts, rng, torque=False, current=False, start=None):
    from pmdcid.simulate import simulate_values

    t = np.arange(int(4.0 * RATE)) / RATE
    u = levels(t, pts)
    x0 = turning(vals, start, torque) if start is not None else None
    s = simulate_values(t, u, vals, torque, None, x0)
    cols = {("tau" if torque else "v"): u,
            "speed_rpm": (s.omega + rng.normal(0, 1.0, len(t))) * RPM}
    if current and not torque:
        cols["i"] = s.i + rng.normal(0, 0.01, len(t))
    return name, t, cols


def pi_log(vals, rng, torque: bool, wmax: float, umax: float):
    """A PI speed loop tracking 0.4, 0.9, -0.5 and 0.1 x ``wmax``, 8 s."""
    from pmdcid.io import Log
    from pmdcid.simulate.controller import parse_controller
    from pmdcid.synth import NoiseSpec, closed_loop_log

    t = np.arange(int(8.0 * RATE)) / RATE
    ref = levels(t, [(0.5, 0.4 * wmax), (2.5, 0.9 * wmax), (4.5, -0.5 * wmax), (6.5, 0.1 * wmax)])
    gains = (f"kp={20 * vals['J']},ki={60 * vals['J']}" if torque else "kp=0.04,ki=0.4")
    spec = parse_controller(f"type=PI,{gains},ulimit={umax}")
    drive = "tau" if torque else "v"
    log = Log(path="held_pi", t=t, data={drive: np.zeros_like(t), "omega_ref": ref})
    cols, _ = closed_loop_log(log, vals, spec, NoiseSpec(omega=1.0), rng, torque)
    return "held_pi", t, {drive: cols[drive], "speed_rpm": cols["omega"] * RPM}


def scenario(case: str, seed: int):
    """(fit logs, held-out logs, truth values, the truth's effect, how much it matters)."""
    rng = np.random.default_rng(seed)
    kind, _, eff = case.partition(":")
    torque, current = kind.startswith("c"), kind.startswith("d")
    extra = (EFFECT_T if torque else EFFECT).get(eff, {})
    vals = truth(rng, TORQUE_RIG if torque else MOTOR, extra, not torque)
    k = 0.01 if torque else 1.0  # the torque rig: 0.05 .. 0.15 N m
    fit = [step_log(vals, "stepA", [(0.0, 5 * k), (1.0, 15 * k)], rng, torque, current, 5 * k)]
    if kind in ("a2", "b2", "c2", "d"):
        fit.append(step_log(vals, "stepB", [(0.5, -8 * k)], rng, torque, current))
    held = [step_log(vals, "held_up10", [(0.5, 10 * k)], rng, torque, current),
            step_log(vals, "held_down", [(0.0, 12 * k), (1.0, 3 * k)], rng, torque, current,
                     12 * k),
            step_log(vals, "held_neg", [(0.0, -6 * k), (1.0, -12 * k)], rng, torque, current,
                     -6 * k)]
    if eff != "input_delay":  # a late input is not simulated in closed loop
        held.append(pi_log(vals, rng, torque, 40.0 if torque else 500.0, 20 * k))
    return fit, held, vals, eff or None, matters(vals, eff, held, torque)


def matters(vals, eff, held, torque) -> list[float] | None:
    """Per held-out run, the speed NRMSE of the truth without its effect (noise-free)."""
    if not eff:
        return None
    from pmdcid.model import EFFECTS as CATALOGUE
    from pmdcid.simulate import simulate_values

    off = {**vals, **{p.name: p.neutral for p in CATALOGUE[eff].params}}
    out = []
    for _, t, cols in held:
        u = cols["tau" if torque else "v"]
        a, b = simulate_values(t, u, vals, torque), simulate_values(t, u, off, torque)
        out.append(round(float(np.sqrt(np.mean((a.omega - b.omega) ** 2)) / np.std(a.omega)), 4))
    return out


def write(folder: Path, name: str, t, cols) -> str:
    import pandas as pd

    path = folder / f"{name}.csv"
    pd.DataFrame({"t": t, **cols}).to_csv(path, index=False, float_format="%.6g")
    return str(path)


def pmdcid(*args) -> subprocess.CompletedProcess:
    """The CLI of the tree on PYTHONPATH."""
    code = "import sys; from pmdcid.cli import main; sys.argv = ['pmdcid'] + sys.argv[1:]; main()"
    return subprocess.run([sys.executable, "-c", code, *args], capture_output=True, text=True)


def predict(model_path: str, csv: str) -> float:
    """Speed NRMSE of the model on ``csv`` from its measured first samples (``simulate --x0
    measured``)."""
    from pmdcid.io import read_log
    from pmdcid.io.mapping import parse_mapping
    from pmdcid.model import load_model
    from pmdcid.synth import simulated_columns

    log = read_log(csv, mapping=parse_mapping(["omega=speed_rpm*rpm"]))
    _, cols, _ = simulated_columns(log, load_model(model_path), x0="measured")
    w = np.asarray(log["omega"], float)
    return float(np.sqrt(np.mean((cols["omega"] - w) ** 2)) / np.std(w))


def run_case(out: Path, case: str, seed: int) -> dict:
    from pmdcid.model import load_model

    folder = out / f"{case.replace(':', '-')}_{seed}"
    folder.mkdir(parents=True, exist_ok=True)
    fit, held, vals, eff, mat = scenario(case, seed)
    fp, hp = [write(folder, *x) for x in fit], [write(folder, *x) for x in held]
    before, after = str(folder / "before.json"), str(folder / "after.json")
    t0 = time.time()
    runs = [pmdcid("identify", *fp, "-m", before, "--no-diagnose", "-c", "omega=speed_rpm*rpm"),
            pmdcid("identify", *fp, "-m", after, "-c", "omega=speed_rpm*rpm")]
    row = {"case": case, "seed": seed, "truth": eff, "matters": mat, "rate": RATE,
           "secs": round(time.time() - t0, 1)}
    if any(r.returncode for r in runs):
        row["error"] = " ".join(r.stderr.strip() for r in runs)[-300:]
        return row
    mb, ma = load_model(before), load_model(after)
    row.update(before_effects=list(mb.effects), after_effects=list(ma.effects),
               added=[e for e in ma.effects if e not in mb.effects],
               held_before=[round(predict(before, p), 4) for p in hp],
               held_after=[round(predict(after, p), 4) for p in hp])
    row["rise"] = max(a / b - 1 for a, b in zip(row["held_after"], row["held_before"],
                                                strict=True))
    if "R" in ma.parameters:
        row["R"], row["R_true"] = ma.value("R"), vals["R"]
    if BUILD2[0]:
        row["build2"] = build2(folder, fp, before)
    return row


#: the largest relative difference of simulate's and report's NRMSE from the summary's
BUILD2_TOL = 1e-3
#: ``--build2``: run :func:`build2` on every case
BUILD2 = [False]
MAP = ("-c", "omega=speed_rpm*rpm")


def build2(folder: Path, fp: list[str], model: str) -> dict:
    """Issue 24's Build 2: ``diagnose FIT -m MODEL -o M2 --summary S``, then ``simulate LOG -m
    M2 --x0 measured`` and ``report FIT -m M2`` on each fit log: their speed NRMSE against the
    summary's "after" figure for that log (``err``: the largest relative difference)."""
    m2, summ, rep = folder / "diagnosed.json", folder / "summary.json", folder / "report2"
    run = pmdcid("diagnose", *fp, "-m", model, "-o", str(m2), "--summary", str(summ), *MAP)
    if run.returncode:
        return {"error": run.stderr.strip()[-300:]}
    s = json.loads(summ.read_text())
    out = {"effects": list(s["added"]), "model_effects": list(load_effects(m2)), "logs": []}
    rp = pmdcid("report", *fp, "-m", str(m2), "-o", str(rep), *MAP)
    metrics = json.loads((rep / "metrics.json").read_text())["logs"] if not rp.returncode else []
    for k, p in enumerate(fp):
        sim = folder / f"sim2_{Path(p).name}"
        r2 = pmdcid("simulate", p, "-m", str(m2), "--x0", "measured", "-o", str(sim), *MAP)
        row = {"summary": s["logs"][k]["after"].get("omega"),
               "simulate": None if r2.returncode else sim_nrmse(p, sim),
               "report": metrics[k]["signals"]["omega"]["nrmse"] if metrics else None}
        out["logs"].append(row)
    errs = [abs(x / r["summary"] - 1) if x is not None else float("inf")
            for r in out["logs"] for x in (r["simulate"], r["report"])]
    out["err"] = max(errs)
    out["fail"] = [x.stderr.strip()[-200:] for x in (rp,) if x.returncode]
    return out


def load_effects(path) -> list[str]:
    return json.loads(Path(path).read_text()).get("effects", [])


def sim_nrmse(csv: str, sim: Path) -> float:
    """Speed NRMSE of ``simulate``'s output ``sim`` against the log ``csv`` as read."""
    import pandas as pd

    from pmdcid.io import read_log
    from pmdcid.io.mapping import parse_mapping

    w = np.asarray(read_log(csv, mapping=parse_mapping([MAP[1]]))["omega"], float)
    s = pd.read_csv(sim, comment="#")["omega"].to_numpy(float)
    return float(np.sqrt(np.mean((s - w) ** 2)) / np.std(w))


def sweep(out: Path, cases, seeds, run=None) -> None:
    """Each case and seed run by ``run(out, case, seed)`` (default :func:`run_case`), one JSON
    row each appended to OUT/results.jsonl and printed (also used by bench/torquerig.py)."""
    run = run or run_case
    out.mkdir(parents=True, exist_ok=True)
    with open(out / "results.jsonl", "a") as f:
        for seed in seeds:
            for case in cases:
                row = run(out, case, seed)
                f.write(json.dumps(row) + "\n")
                f.flush()
                print(json.dumps(row), flush=True)


def classify(r: dict) -> dict[str, list[str]]:
    """The tally's findings on one row: category -> what."""
    kind, truth_eff = r["case"].split(":")[0], r["truth"]
    real = {truth_eff} | (set() if kind.startswith("c") else {"back_emf"})
    final = set(r["after_effects"])
    out = collections.defaultdict(list)
    for e in r["after_effects"]:
        if e in real:
            continue
        curve = e == "friction_curve" and truth_eff in STANDS_IN and truth_eff not in final
        by = "identify" if e in r["before_effects"] else "diagnose"
        out["stands in" if curve else f"false add ({by})"].append(e)
    if kind == "b1" and truth_eff in r["added"]:
        out["added from one log"].append(truth_eff)
    standing_in = out.get("stands in")
    if truth_eff and truth_eff not in final and not standing_in and kind != "b1":
        if max(r["matters"]) > 0.02:
            out["missed"].append(truth_eff)
    if r["rise"] > 0.05:
        out["held-out rise"].append(f"{r['rise']:+.0%}")
    b2 = r.get("build2")
    if b2 and ("error" in b2 or b2["fail"]):
        out["build2 error"].append(b2.get("error") or b2["fail"][0])
    elif b2 and b2["err"] > BUILD2_TOL:
        out["build2 mismatch"].append(f"{b2['err']:.1e} {b2['model_effects']}")
    return out


def tally(path: Path) -> None:
    rows = [json.loads(line) for line in open(path)]
    counts = collections.Counter()
    for r in rows:
        if "error" in r:
            counts["error"] += 1
            print(f"error: {r['case']} seed {r['seed']}: {r['error']}")
            continue
        for cat, what in classify(r).items():
            counts[cat] += len(what)
            print(f"{cat}: {r['case']} seed {r['seed']}: {what}; identify {r['before_effects']}"
                  f", diagnose added {r['added']}; held-out {r['held_before']} -> "
                  f"{r['held_after']}")
    print(f"\n{len(rows)} runs: " + ", ".join(f"{k} {v}" for k, v in sorted(counts.items())))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--out", type=Path, help="run the cases, rows into OUT/results.jsonl")
    ap.add_argument("--seeds", type=int, default=10, help="how many seeds")
    ap.add_argument("--first", type=int, default=1, help="the first seed")
    ap.add_argument("--jobs", type=int, default=1, help="processes (seeds split between them)")
    ap.add_argument("--cases", default=",".join(CASES))
    ap.add_argument("--seed-list", help=argparse.SUPPRESS)
    ap.add_argument("--tally", type=Path, help="count a results.jsonl")
    ap.add_argument("--rate", type=float, default=RATE, help="the logs' sample rate [Hz]")
    ap.add_argument("--build2", action="store_true",
                    help="also diagnose, simulate --x0 measured and report each case's fit logs")
    args = ap.parse_args(argv)
    set_options(args)
    if args.tally:
        tally(args.tally)
        return 0
    if args.out is None:
        ap.error("give --out DIR or --tally FILE")
    return run_or_split(__file__, sweep, args)


def set_options(args) -> None:
    """``--rate`` and ``--build2`` for this process's cases."""
    global RATE
    RATE = args.rate
    BUILD2[0] = args.build2


def forwarded(args) -> list[str]:
    """The options a split's processes are given beyond their seeds."""
    out = []
    if getattr(args, "rate", None) not in (None, 100.0):
        out += ["--rate", f"{args.rate:g}"]
    if getattr(args, "build2", False):
        out.append("--build2")
    return out


def run_or_split(script: str, sweep_fn, args) -> int:
    """``--seed-list`` given: run ``sweep_fn(out, cases, seeds)`` here; else split seeds 1 ..
    ``--seeds`` between ``--jobs`` processes of ``script``, each given its part (also used by
    bench/torquerig.py)."""
    cases = args.cases.split(",")
    if args.seed_list:
        sweep_fn(args.out, cases, [int(s) for s in args.seed_list.split(",")])
        return 0
    first = getattr(args, "first", 1)
    seeds = list(range(first, first + args.seeds))
    parts = [seeds[j::args.jobs] for j in range(args.jobs)]
    procs = [subprocess.Popen([sys.executable, script, "--out", str(args.out), "--cases",
                               args.cases, "--seed-list", ",".join(map(str, p)),
                               *forwarded(args)])
             for p in parts if p]
    return max(p.wait() for p in procs)


if __name__ == "__main__":
    sys.exit(main())
