"""Do plan's predicted errors hold for a lumped motor with its lag? (voltage + speed only)

    PYTHONPATH=$PWD .venv/bin/python -m bench.plan_lumped [--check-seeds 12] [--trip-seeds 5]

Two measurements on bench/lumped_coverage.py's motors (SI, back-EMF 90 % of the damping, L/R
2-4 ms, sampled at 0.5 or 1 kHz):

- ``--check-seeds N``: per seed, ``identify`` (no diagnose) on the seed's five logs, then
  ``plan --check`` (:func:`pmdcid.plan.check.check_logs`) on the same logs at the identified
  model. Per parameter: how often the per-volt truth lies within 2 *predicted* standard errors,
  within 2 of the fit's own, and the median ratio predicted / fit.
- ``--trip-seeds N``: the plan's own round trip on seed 1's motor. Its lumped model is
  identified from seed 1's logs, ``plan`` designs its profiles (defaults: 120 s at 1 kHz), each
  is recorded by the kernel (64 internal steps a sample, as bench/lumped_coverage.py's logs)
  on the SI truth with the plan's speed noise
  (``numpy.random.default_rng(100 * seed + k)``, no current), and ``identify`` (no diagnose)
  fits them from the model the plan was made for (``pmdcid identify rec/*.csv -m model.json``:
  from an empty model, identify frees no lag on a triangle and a PRBS alone, docs/plan.md).
  The z-scores against the plan's predicted errors and the fit's, and their ratio.

Not a test: it prints; docs/plan.md quotes its figures.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from bench.lumped_coverage import NSUB, logs_for_seed  # noqa: E402
from pmdcid.io.kinds import canonical  # noqa: E402

PARAMS = ("J", "bv", "bc", "dz", "tau_e", "ke_share")


def _identified(logs, start=None):
    """identify's model (no diagnose) of ``logs`` from ``start`` (default: an empty model)."""
    from pmdcid.model import Model
    from pmdcid.pipeline import identify

    return identify(logs, start if start is not None else Model(), run_diagnose=False).model


def _row(model, truth: dict, predicted: dict) -> dict:
    """Per parameter: (z against the prediction, z against the fit's error, predicted / fit)."""
    out = {}
    for k in PARAMS:
        if k in predicted and model.has(k) and model.parameters[k].stderr > 0:
            err, fit_se = model.value(k) - truth[k], model.parameters[k].stderr
            out[k] = (err / predicted[k], err / fit_se, predicted[k] / fit_se)
    return out


def check_rows(seeds) -> list[dict]:
    from pmdcid.plan.check import check_logs
    from pmdcid.plan.design import Settings

    rows = []
    for seed in seeds:
        tr, logs = logs_for_seed(seed)
        model = _identified(logs)
        res = check_logs(logs, model, Settings())
        rows.append(_row(model, tr["per_volt"], res.stderr))
        _print(f"check seed {seed}", rows[-1])
    return rows


def trip_rows(seeds) -> list[dict]:
    from pmdcid.io import Log
    from pmdcid.plan.design import Settings, plan_for_model
    from pmdcid.simulate import neutral_values, simulate_values

    tr, logs = logs_for_seed(1)
    model = _identified(logs)
    plan = plan_for_model(model, Settings())
    vals = {**neutral_values(), **tr["si"]}
    rows = []
    for seed in seeds:
        rec = []
        for k, p in enumerate(plan.profiles):
            w = simulate_values(p.t, p.u, vals, nsub=NSUB).omega  # recorded finer than fitted
            noise = np.random.default_rng(100 * seed + k).normal(0.0, plan.noise["omega"], w.size)
            rec.append(Log(f"{p.name}.csv", p.t, {"v": p.u, "omega": w + noise},
                           meta={"kind": canonical(p.kind)}))  # as plan writes it
        rows.append(_row(_identified(rec, model), tr["per_volt"], plan.stderr))
        _print(f"round trip seed {seed}", rows[-1])
    return rows


def _print(head: str, row: dict) -> None:
    print(head + ": " + ", ".join(f"{k} z {v[0]:+.1f} (fit {v[1]:+.1f}, ratio {v[2]:.2f})"
                                  for k, v in row.items()), flush=True)


def summary(rows: list[dict]) -> str:
    lines = ["| parameter | seeds | within 2 predicted se | within 2 fit se | "
             "median predicted / fit |", "|---|---|---|---|---|"]
    for k in PARAMS:
        got = [r[k] for r in rows if k in r]
        if not got:
            continue
        zp, zf, ratio = (np.array(c) for c in zip(*got, strict=True))
        lines.append(f"| {k} | {len(got)} | {int(np.sum(np.abs(zp) <= 2))} | "
                     f"{int(np.sum(np.abs(zf) <= 2))} | {np.median(ratio):.2f} |")
    return "\n".join(lines)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--check-seeds", type=int, default=12)
    ap.add_argument("--trip-seeds", type=int, default=5)
    args = ap.parse_args(argv)
    if args.check_seeds:
        print(summary(check_rows(range(1, args.check_seeds + 1))))
    if args.trip_seeds:
        print(summary(trip_rows(range(1, args.trip_seeds + 1))))


if __name__ == "__main__":
    main()
