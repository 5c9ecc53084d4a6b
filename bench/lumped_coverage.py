"""Coverage of the lumped (per-volt) path: voltage + speed logs of SI motors with back-EMF and an
electrical lag L/R of 2-4 ms, identified by ``pmdcid identify`` without --km (issue 24).

    .venv/bin/python -m bench.lumped_coverage --seeds 20 --out lumped.json
    .venv/bin/python -m bench.lumped_coverage --summary lumped.json

Each seed: an SI motor (R = 2 ohm, km = ke moved by +-20 %, L/R uniform in 2-4 ms, the
mechanical time constant 30-60 ms, back-EMF 90 % of the damping, Coulomb friction and a dead
zone 15-35 % above it, as the paper's), sampled at 0.5 or 1 kHz (alternating), speed noise
0.3 % of its range from ``numpy.random.default_rng(seed)``, simulated 64 substeps a sample.
Logs: four steps from rest (2, 4, 6, 8 V, 1.5 s) and a
+-8 V triangle (2 periods of 4 s), columns t, v, omega only (no current: the lumped path).
Identified by :func:`pmdcid.pipeline.identify` (the library function ``pmdcid identify``
calls) with diagnose. Per-volt truth: J' = J R/km, bv' = bv R/km + ke, bc' = bc R/km,
dz' = dz R/km. A row: each parameter's estimate, stderr and z = (estimate - truth)/stderr after
the joint fit and after diagnose, the effects diagnose added, tau_e when the model has it.
Not a test: nothing here asserts; ``--summary`` prints the share of seeds within +-2 stderr,
the mean relative bias, and how often each effect was added.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

import numpy as np

PARAMS = ("J", "bv", "bc", "dz")
#: internal steps per sample of the truth: 20-40 per L/R, finer than any fit (continuous time)
NSUB = 64


def truth_for(seed: int, rate: float | None = None) -> dict:
    """SI parameters of seed's motor, its sample rate (``rate`` [Hz] in place of the seed's
    0.5 or 1 kHz where given) and the per-volt truth."""
    rng = np.random.default_rng(seed)
    R = 2.0
    km = 0.02 * rng.uniform(0.8, 1.2)
    tau_e = rng.uniform(2e-3, 4e-3)
    tau_m = rng.uniform(0.03, 0.06)
    emf = km * km / R  # back-EMF damping [N m s/rad]
    bv = emf * 0.1 / 0.9  # back-EMF dominates: 90 % of the damping
    J = tau_m * (bv + emf)
    bc = 0.3 * km / R * rng.uniform(0.8, 1.2)  # ~0.3 V per volt
    dz = bc * rng.uniform(1.15, 1.35)  # the dead zone above Coulomb, as the paper's motor
    si = {"R": R, "L": tau_e * R, "km": km, "ke": km, "J": J, "bv": bv, "bc": bc, "dz": dz}
    g = R / km
    per_volt = {"J": J * g, "bv": bv * g + km, "bc": bc * g, "dz": dz * g, "tau_e": tau_e,
                "ke_share": km / (bv * g + km)}
    rate = rate or (1000.0 if seed % 2 == 0 else 500.0)
    return {"si": si, "per_volt": per_volt, "rate": rate}


def logs_for_seed(seed: int, si: dict | None = None, rate: float | None = None):
    """(truth, logs): the seed's step and triangle logs, t/v/omega only, simulated from the
    truth's SI values or from ``si`` in their place (bench/pervolt_coverage.py adds a drag),
    sampled at ``rate`` [Hz] where given (:func:`truth_for`)."""
    from pmdcid.io import Log
    from pmdcid.simulate import neutral_values, simulate_values
    from pmdcid.synth import step, triangle

    tr = truth_for(seed, rate)
    vals = {**neutral_values(), **(tr["si"] if si is None else si)}
    rng = np.random.default_rng(10_000 + seed)
    dt = 1.0 / tr["rate"]
    sims = []
    t = np.arange(int(1.5 / dt)) * dt
    for a in (2.0, 4.0, 6.0, 8.0):
        u = step(t, a, 0.2)
        sims.append((f"step_{a:g}V", t, u, simulate_values(t, u, vals, nsub=NSUB).omega))
    tt = np.arange(int(8.0 / dt)) * dt
    u = triangle(tt, 8.0, 4.0)
    sims.append(("triangle", tt, u, simulate_values(tt, u, vals, nsub=NSUB).omega))
    sigma = 0.003 * max(float(np.ptp(s[3])) for s in sims)
    logs = [Log(path=name, t=t_, data={"v": u_, "omega": w + rng.normal(0.0, sigma, w.size)},
                meta={}) for name, t_, u_, w in sims]
    return tr, logs


def _row(model, truth) -> dict:
    out = {}
    for k in (*PARAMS, "tau_e", "ke_share"):
        if not model.has(k):
            continue
        p = model.parameters[k]
        z = (p.value - truth[k]) / p.stderr if p.stderr > 0 else float("inf")
        out[k] = {"value": p.value, "stderr": p.stderr, "rel": p.value / truth[k] - 1, "z": z}
    return out


def run_seed(seed: int) -> dict:
    from pmdcid.model import Model
    from pmdcid.pipeline import identify

    tr, logs = logs_for_seed(seed)
    t0 = time.process_time()
    res = identify(logs, Model(), run_diagnose=True)
    joint = None
    for name, out in res.stages:
        if name.startswith("joint"):
            joint = out
    jm = Model()
    if joint is not None:
        for k, e in joint.estimates.items():
            jm.set(k, e.value, e.stderr)
    m = res.model
    added = list(res.diagnose.summary["added"]) if res.diagnose is not None else []
    return {"seed": seed, "rate": tr["rate"], "tau_e_true": tr["per_volt"]["tau_e"],
            "joint": _row(jm, tr["per_volt"]), "final": _row(m, tr["per_volt"]),
            "effects": list(m.effects), "added": added,
            "delay": m.parameters["delay"].value if m.has("delay") else None,
            "cpu": time.process_time() - t0}


def summary(rows: list[dict]) -> str:
    lines = [f"{len(rows)} seeds"]
    for where in ("joint", "final"):
        for k in (*PARAMS, "tau_e", "ke_share"):
            got = [r[where][k] for r in rows if k in r[where]]
            if not got:
                continue
            inside = sum(abs(g["z"]) <= 2 for g in got)
            rel = np.array([g["rel"] for g in got])
            se = np.array([g["stderr"] / g["value"] for g in got])
            z = np.array([g["z"] for g in got])
            lines.append(f"{where:5s} {k:5s}: within 2 se {inside}/{len(got)}, bias "
                         f"{100 * rel.mean():+.2f} % (spread {100 * rel.std():.2f} %), "
                         f"median se {100 * np.median(se):.2f} %, median |z| "
                         f"{np.median(np.abs(z)):.2f}, max |z| {np.max(np.abs(z)):.1f}")
    added: dict[str, int] = {}
    for r in rows:
        for e in r["added"]:
            added[e] = added.get(e, 0) + 1
    lines.append("diagnose added: " + (", ".join(f"{e} in {n}" for e, n in added.items())
                                       or "nothing"))
    effects: dict[str, int] = {}
    for r in rows:
        for e in r["effects"]:
            effects[e] = effects.get(e, 0) + 1
    lines.append("effects in the final model: " + (
        ", ".join(f"{e} in {n}" for e, n in effects.items()) or "none"))
    lines.append(f"cpu per seed {np.mean([r['cpu'] for r in rows]):.1f} s")
    return "\n".join(lines)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--first", type=int, default=0)
    ap.add_argument("--out", type=Path)
    ap.add_argument("--summary", type=Path, help="print the summary of an earlier run's file")
    a = ap.parse_args(argv)
    if a.summary:
        print(summary(json.loads(a.summary.read_text())))
        return
    os.environ.setdefault("PMDCID_THREADS", "1")
    rows = []
    for seed in range(a.first, a.first + a.seeds):
        rows.append(run_seed(seed))
        print(json.dumps(rows[-1]), flush=True, file=sys.stderr)
        if a.out:
            a.out.write_text(json.dumps(rows, indent=1) + "\n")
    print(summary(rows))


if __name__ == "__main__":
    main()
