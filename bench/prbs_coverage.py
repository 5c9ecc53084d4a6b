"""Do the printed standard errors cover the truth on a two-level PRBS with current logged?

    PYTHONPATH=$PWD .venv/bin/python -m bench.prbs_coverage [--seeds 10] [--levels uniform]

The red-team case of session 20 (docs/identification.md, "A two-level PRBS with current"): a
paper-like motor (R 2.4 ohm, L 18 mH, km 0.05 N m/A, J 3e-3 kg m^2, bv 0.03 N m s/rad, bc
0.005 N m, dz 0.006 N m), 20 s at 1 kHz, the voltage held at -10 or +10 V for 0.2 s at a time
(``--levels uniform``: anywhere between, an APRBS), current noise 0.01 A and speed noise 0.05
rad/s from ``default_rng(seed)`` (OpenBLAS's kernels pinned by bench/__init__.py); then
``pmdcid.identify`` with the datasheet km and no diagnose, as a user runs it. For J, bv and
bc: z = (estimate - truth) / stderr per seed, the share within 2 standard errors and the RMS
of z (1 for an honest standard error). Not a test: it prints.
"""

from __future__ import annotations

import argparse
import math
import sys
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

TRUTH = {"R": 2.4, "L": 0.018, "km": 0.05, "J": 3e-3, "bv": 0.03, "bc": 0.005, "dz": 0.006}
JUDGED = ("J", "bv", "bc")
RATE, SECONDS, HOLD = 1000.0, 20.0, 0.2
NOISE_I, NOISE_OMEGA = 0.01, 0.05


def log_for(seed: int, levels: str):
    """The seed's log: the PRBS (or APRBS) simulated from :data:`TRUTH` with sensor noise."""
    from pmdcid.io import Log
    from pmdcid.simulate import neutral_values, simulate_values

    rng = np.random.default_rng(seed)
    n, hold = int(RATE * SECONDS), int(RATE * HOLD)
    t = np.arange(n) / RATE
    lv = (rng.choice([-10.0, 10.0], size=n // hold + 1) if levels == "prbs"
          else rng.uniform(-10.0, 10.0, size=n // hold + 1))
    v = np.repeat(lv, hold)[:n]
    sim = simulate_values(t, v, {**neutral_values(), **TRUTH})
    cols = {"v": v, "i": sim.i + rng.normal(0.0, NOISE_I, n),
            "omega": sim.omega + rng.normal(0.0, NOISE_OMEGA, n)}
    return Log(f"{levels}_{seed}.csv", t, cols)  # undeclared, as the red team's CSV


def one(seed: int, levels: str) -> dict[str, float]:
    """z of J, bv, bc for one seed (NaN where a parameter has no standard error)."""
    import pmdcid

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        res = pmdcid.identify([log_for(seed, levels)], km=TRUTH["km"], diagnose=False,
                              progress=False)
    out = {}
    for k in JUDGED:
        p = res.model.parameters[k]
        out[k] = (p.value - TRUTH[k]) / p.stderr if p.stderr else math.nan
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--first", type=int, default=0)
    ap.add_argument("--levels", choices=("prbs", "uniform"), default="prbs")
    args = ap.parse_args(argv)
    rows = []
    for seed in range(args.first, args.first + args.seeds):
        z = one(seed, args.levels)
        rows.append(z)
        print(f"seed {seed}: " + ", ".join(f"{k} {v:+.2f}" for k, v in z.items()), flush=True)
    print("| parameter | seeds | within ±2 stderr | RMS z |")
    print("|---|---|---|---|")
    for k in JUDGED:
        z = np.array([r[k] for r in rows], float)
        ok = np.isfinite(z)
        print(f"| {k} | {ok.sum()} | {np.sum(np.abs(z[ok]) <= 2)} | "
              f"{math.sqrt(np.mean(z[ok] ** 2)):.2f} |")


if __name__ == "__main__":
    main()
