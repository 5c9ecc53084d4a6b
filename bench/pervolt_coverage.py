"""Coverage of the per-volt path without current on step logs (issue 24, items 3 and 4).

    .venv/bin/python -m bench.pervolt_coverage [--seeds 20] [--cases paper-steps-1k ...]
        [--diagnose] [--drag BQ] [--jobs 2] [--out rows.json]

Cases (columns t, v, omega only: the lumped path of ``pmdcid identify``):

- ``paper-steps-1k``, ``paper-steps-500``: bench/noisy_steps.py's three free-running step logs of
  the paper's motor (back-EMF ke = km, L/R = 7.5 ms) at 1 kHz or 500 Hz, speed noise 0.2 rad/s,
  the voltage as commanded, simulated :data:`NSUB` internal steps a sample;
- ``paper-tri-1k``, ``paper-tri-500``: the same steps plus a +-12 V triangle (period 4 s, 8 s);
  ``paper-tri-only-1k``: the triangle alone (the paper's fit-nonlinear log);
- ``lr-steps``, ``lr-tri``: bench/lumped_coverage.py's motors (L/R 2-4 ms, 0.5 or 1 kHz
  alternating, back-EMF 90 % of the damping): its four steps from rest, with and without its
  triangle; ``lr-tri-only``: its triangle alone (no step: identify starts from a first-order
  fit and tests the lag in the joint fit, :func:`pmdcid.identify.runners.lag_untested`);
  ``lr-aprbs``, ``lr-chirp``: the same motors on one log of random levels, or one swept sine,
  alone (:func:`_lr_rich`); ``lr-encoder``: ``lr-tri``'s logs as an encoder's angle alone
  (:func:`_lr_encoder`: 360 counts a turn, the speed derived as the readers derive it).

``--drag BQ``: a true quadratic drag bq [N m s^2/rad^2] (SI) in every motor; ``--diagnose``:
identify runs diagnose, and the row is the final model's. Per-volt truth: J' = J R/km,
bv' = bv R/km + ke, bc' = bc R/km, dz' = dz R/km, bq' = bq R/km, tau_e = L/R,
ke_share = ke/bv'. Per parameter and case: the share of seeds within +-2 printed standard
errors (a parameter written as an interval: the truth inside it, counted apart), the mean
relative bias and the median standard error; then the seeds whose J standard error is under a
tenth of the case's median (the "100-fold drops") with their joint fit's estimates. Not a test:
it prints; docs/identification.md quotes it.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import warnings
from pathlib import Path

import numpy as np

#: internal steps per sample of the truth: finer than any fit (continuous time, as
#: bench/lumped_coverage.py; the kernel's own choice, 1 at 1 kHz on the paper's motor, left
#: tau_e 10 % and J 1 % off the fine simulation's)
NSUB = 64
PARAMS = ("J", "bv", "bc", "dz", "tau_e", "ke_share", "bq")
CASES = ("paper-steps-1k", "paper-steps-500", "paper-tri-1k", "paper-tri-500", "lr-steps",
         "lr-tri", "lr-tri-only", "paper-tri-only-1k", "lr-aprbs", "lr-chirp", "lr-encoder")


def _paper_truth(rate: float) -> dict:
    from pmdcid.synth import PAPER

    si = {**PAPER, "ke": PAPER["km"]}
    return {"si": si, "rate": rate}


def _per_volt(si: dict) -> dict:
    g = si["R"] / si["km"]
    bv = si["bv"] * g + si["ke"]
    return {"J": si["J"] * g, "bv": bv, "bc": si["bc"] * g, "dz": si["dz"] * g,
            "tau_e": si["L"] / si["R"], "ke_share": si["ke"] / bv, "bq": si.get("bq", 0.0) * g}


def case_logs(case: str, seed: int, bq: float = 0.0, noise: float = 0.2,
              rate: float | None = None):
    """(per-volt truth, logs) of one case and seed (module docstring); ``rate`` [Hz]: the
    ``lr-*`` cases sampled at that rate instead of their seed's 0.5 or 1 kHz."""
    from bench.lumped_coverage import logs_for_seed, truth_for
    from pmdcid.io import Log
    from pmdcid.simulate import neutral_values, simulate_values
    from pmdcid.synth import triangle

    if case.startswith("lr-"):
        tr = truth_for(seed, rate)
        si = {**tr["si"], "bq": bq}
        _, logs = logs_for_seed(seed, si if bq else None, rate)
        if case == "lr-steps":
            logs = [lg for lg in logs if lg.path.startswith("step")]
        elif case == "lr-tri-only":
            logs = [lg for lg in logs if lg.path == "triangle"]
        elif case in ("lr-aprbs", "lr-chirp"):
            logs = [_lr_rich(case, seed, si, tr["rate"])]
        elif case == "lr-encoder":
            logs = [_lr_encoder(lg, seed, si) for lg in logs]
        return _per_volt(si), logs
    rate = 1000.0 if case.endswith("1k") else 500.0
    si = {**_paper_truth(rate)["si"], "bq": bq}
    vals = {**neutral_values(), **si}
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, 4.0, 1.0 / rate)
    logs = []
    for low, high in () if "-only-" in case else ((0.0, 6.0), (3.0, 9.0), (0.0, 12.0)):
        v = np.where((t >= 1.0) & (t < 2.5), high, low)
        w = simulate_values(t, v, vals, False, nsub=NSUB).omega
        w = w + rng.normal(0, noise, t.size)
        logs.append(Log(f"step{high:g}.csv", t, {"v": v, "omega": w}))
    if "-tri-" in case:
        tt = np.arange(0.0, 8.0, 1.0 / rate)
        u = triangle(tt, 12.0, 4.0)
        w = simulate_values(tt, u, vals, False, nsub=NSUB).omega
        logs.append(Log("triangle.csv", tt, {"v": u, "omega": w + rng.normal(0, noise, tt.size)}))
    return _per_volt(si), logs


def _lr_rich(case: str, seed: int, si: dict, rate: float):
    """``lr-aprbs``: 8 s of random levels in +-8 V, each held 0.05-0.3 s (one to ten of the
    motor's time constants); ``lr-chirp``: an 8 V sine swept 0.5 -> 10 Hz over 8 s. Speed
    noise 0.3 % of the speed's range, as bench/lumped_coverage.py's."""
    from pmdcid.io import Log
    from pmdcid.simulate import neutral_values, simulate_values

    rng = np.random.default_rng(20_000 + seed)
    t = np.arange(int(8.0 * rate)) / rate
    if case == "lr-aprbs":
        edges = np.cumsum(rng.uniform(0.05, 0.3, 80))
        levels = rng.uniform(-8.0, 8.0, edges.size + 1)
        u = levels[np.searchsorted(edges, t, side="right")]
    else:
        u = 8.0 * np.sin(2 * np.pi * (0.5 * t + (10.0 - 0.5) * t * t / (2 * 8.0)))
    w = simulate_values(t, u, {**neutral_values(), **si}, nsub=NSUB).omega
    sigma = 0.003 * float(np.ptp(w))
    return Log(path=case, t=t, data={"v": u, "omega": w + rng.normal(0.0, sigma, t.size)},
               meta={})


#: counts a turn of ``lr-encoder``'s encoder (a LEGO motor's; hobby encoders have 12-1024)
ENCODER_COUNTS = 360


def _lr_encoder(log, seed: int, si: dict):
    """``log`` (its t and v) as an encoder's angle alone: the motor's angle simulated from rest,
    shifted by a random place within the first count (a rotor rests anywhere), rounded to
    :data:`ENCODER_COUNTS` a turn; the speed derived from it as a reader does
    (:func:`pmdcid.io.derive.derive_missing`)."""
    from pmdcid.io import Log
    from pmdcid.io.derive import derive_missing
    from pmdcid.simulate import neutral_values, simulate_values

    rng = np.random.default_rng([30_000 + seed, len(log.path), log.n])
    q = 2 * np.pi / ENCODER_COUNTS
    theta = simulate_values(log.t, log["v"], {**neutral_values(), **si}, nsub=NSUB).theta
    theta = np.round((theta + rng.uniform(0.0, q)) / q) * q
    out = Log(path=log.path, t=log.t, data={"v": log["v"], "theta": theta}, meta={})
    derive_missing(out)
    return out


def _entry(par, true: float) -> dict:
    out = {"value": par.value, "stderr": par.stderr, "rel": par.value / true - 1 if true else
           math.nan}
    if par.interval is not None:
        out["interval"] = list(par.interval)
        out["inside"] = bool(par.interval[0] <= true <= par.interval[1])
    elif par.stderr and math.isfinite(par.stderr) and par.stderr > 0:
        out["z"] = (par.value - true) / par.stderr
    return out


def run_one(case: str, seed: int, diagnose: bool = False, bq: float = 0.0,
            rate: float | None = None) -> dict:
    """One seed of one case: the final model's per-volt estimates against the truth, and the
    joint fit's estimates (value, stderr) as they came out of it."""
    from pmdcid.model import Model
    from pmdcid.pipeline import identify

    truth, logs = case_logs(case, seed, bq, rate=rate)
    row = {"case": case, "seed": seed}
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            res = identify(logs, Model(), run_diagnose=diagnose, progress=None)
    except Exception as exc:  # noqa: BLE001 - a bench counts failures of any kind
        row["error"] = str(exc)[:200]
        return row
    m = res.model
    row["final"] = {k: _entry(m.parameters[k], truth[k]) for k in PARAMS
                    if m.has(k) and k in truth and truth[k]}
    joint = [out for name, out in res.stages if name.startswith("joint")]
    row["joint"] = ({k: [e.value, e.stderr] for k, e in joint[-1].estimates.items()}
                    if joint else {})
    row["added"] = list(res.diagnose.summary["added"]) if res.diagnose is not None else []
    row["warnings"] = [str(w)[:160] for w in res.warnings if "standard error" in str(w)
                       or "bound" in str(w)]
    return row


def summary(rows: list[dict]) -> str:
    lines = []
    for case in dict.fromkeys(r["case"] for r in rows):
        rs = [r for r in rows if r["case"] == case]
        ok = [r for r in rs if "final" in r]
        lines.append(f"{case}: {len(ok)}/{len(rs)} identified")
        lines.append("| parameter | within 2 se | bias | median se | in interval |")
        lines.append("|---|---|---|---|---|")
        for k in PARAMS:
            got = [r["final"][k] for r in ok if k in r["final"]]
            if not got:
                continue
            zs = [g["z"] for g in got if "z" in g]
            ins = [g["inside"] for g in got if "inside" in g]
            rel = np.array([g["rel"] for g in got])
            se = [g["stderr"] / abs(g["value"]) for g in got if "z" in g and g["value"]]
            lines.append(
                f"| {k} | {sum(abs(z) <= 2 for z in zs)}/{len(zs)} | {100 * rel.mean():+.1f} % "
                f"| {100 * np.median(se) if se else math.nan:.2g} % | "
                f"{f'{sum(ins)}/{len(ins)}' if ins else '-'} |")
        lines += _drops(ok)
        added: dict[str, int] = {}
        for r in ok:
            for e in r.get("added", []):
                added[e] = added.get(e, 0) + 1
        if added:
            lines.append("diagnose added: " + ", ".join(f"{e} {n}" for e, n in added.items()))
        lines.append("")
    return "\n".join(lines)


def _drops(ok: list[dict]) -> list[str]:
    """The seeds whose J standard error is under a tenth of the case's median."""
    se = [(r["seed"], r["final"]["J"]["stderr"]) for r in ok if "z" in r["final"].get("J", {})]
    if not se:
        return []
    med = float(np.median([s for _, s in se]))
    out = []
    for seed, s in se:
        if s < 0.1 * med:
            r = next(r for r in ok if r["seed"] == seed)
            joint = ", ".join(f"{k} {v:.4g} +- {e:.2g}" for k, (v, e) in r["joint"].items())
            out.append(f"J's se drop: seed {seed}, se {s:.3g} (median {med:.3g}); joint: {joint}")
    return out


def _work(args):
    return run_one(*args)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--first", type=int, default=1)
    ap.add_argument("--cases", nargs="+", default=list(CASES), choices=CASES)
    ap.add_argument("--diagnose", action="store_true")
    ap.add_argument("--drag", type=float, default=0.0)
    ap.add_argument("--jobs", type=int, default=1)
    ap.add_argument("--rate", type=float, help="the lr-* cases sampled at this rate [Hz]")
    ap.add_argument("--out", type=Path)
    ap.add_argument("--summary", type=Path, help="print the summary of an earlier run's file")
    a = ap.parse_args(argv)
    if a.summary:
        print(summary(json.loads(a.summary.read_text())))
        return
    os.environ.setdefault("PMDCID_THREADS", "1")
    jobs = [(c, s, a.diagnose, a.drag, a.rate) for c in a.cases
            for s in range(a.first, a.first + a.seeds)]
    if a.jobs > 1:
        from multiprocessing import Pool

        with Pool(a.jobs) as pool:
            rows = pool.map(_work, jobs, chunksize=1)
    else:
        rows = [_work(j) for j in jobs]
    if a.out:
        a.out.write_text(json.dumps(rows, indent=1) + "\n")
    print(summary(rows))


if __name__ == "__main__":
    main()
