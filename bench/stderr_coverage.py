"""Do the printed standard errors cover the truth as often as they say? (issue "Real rigs, round
three", honest uncertainty)

    .venv/bin/python bench/stderr_coverage.py [--seeds 20] [--effect stribeck] [--no-diagnose]

Each seed: the paper's motor with every parameter moved by up to 20 % (tests/ident_util.py),
fresh noisy logs of its three protocols (blocked-rotor steps, free-speed steps, a triangle), then
``pmdcid.identify`` with the datasheet km (the whole rig: stages, joint fit, diagnose unless
``--no-diagnose``). ``--effect`` hides one catalogue effect at the tests' visible size
(tests/system/test_diagnose.py). For J, bv, bc, dz, R, L (and the effect's parameters when it was
added) the z-score (estimate - truth)/stderr: the share with |z| <= 2 (95 % for an honest
Gaussian standard error), the mean and RMS of z, and how many seeds added exactly the hidden
effect. A parameter the logs only bound (an interval, no standard error) has no z: how often
the truth lies inside its interval is counted instead. Not a test: it prints;
docs/identification.md quotes its figures.
"""

from __future__ import annotations

import argparse
import math
import os
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
sys.path[:0] = [str(ROOT / "tests"), str(ROOT / "tests" / "system")]  # test_diagnose

BASE = ("R", "L", "J", "bv", "bc", "dz")


def one(seed: int, effect: str | None,
        diagnose: bool) -> tuple[dict[str, float], dict[str, bool], list[str]]:
    """z-scores of one seed's estimates, whether the truth lies in each interval of a parameter
    the logs only bound, and the effects added."""
    import test_diagnose as td
    from ident_util import perturbed_truth

    import pmdcid

    rng = np.random.default_rng(seed)
    truth = perturbed_truth(rng, 0.2, **(td.VISIBLE[effect] if effect else {}))
    logs = _logs(truth, rng)
    res = pmdcid.identify(logs, km=truth["km"], diagnose=diagnose, progress=False)
    z, inside = {}, {}
    names = BASE + tuple(td.VISIBLE[effect]) if effect else BASE
    for name in names:
        par = res.model.parameters.get(name)
        if par is not None and par.interval is not None:
            inside[name] = par.interval[0] <= truth[name] <= par.interval[1]
        if par is None or not (par.stderr and math.isfinite(par.stderr) and par.stderr > 0):
            continue
        z[name] = (par.value - truth[name]) / par.stderr
    return z, inside, list(res.model.effects)


def _logs(truth, rng):
    from ident_util import blocked_logs, step_logs, triangle_log

    return [*blocked_logs(truth, rng), *step_logs(truth, rng), triangle_log(truth, rng)]


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--first", type=int, default=900)
    ap.add_argument("--effect", default=None)
    ap.add_argument("--no-diagnose", action="store_true")
    args = ap.parse_args()
    os.environ.setdefault("PMDCID_THREADS", "1")
    zs: dict[str, list[float]] = {}
    bounded: dict[str, list[bool]] = {}
    right = 0
    for seed in range(args.first, args.first + args.seeds):
        z, inside, added = one(seed, args.effect, not args.no_diagnose)
        right += added == ([args.effect] if args.effect else [])
        for k, v in z.items():
            zs.setdefault(k, []).append(v)
        for k, v in inside.items():
            bounded.setdefault(k, []).append(v)
        print(f"seed {seed}: added {added or 'nothing'}; "
              + ", ".join(f"{k} {v:+.2f}" for k, v in z.items())
              + "".join(f", {k} {'in' if v else 'OUTSIDE'} its interval"
                        for k, v in inside.items()), file=sys.stderr, flush=True)
    what = f"hidden {args.effect}" if args.effect else "no hidden effect"
    print(f"{args.seeds} seeds, {what}, diagnose {'off' if args.no_diagnose else 'on'}: "
          f"the hidden effects exactly in {right} of {args.seeds}")
    print("| parameter | seeds | within ±2 stderr | mean z | RMS z |")
    print("|---|---|---|---|---|")
    for k, v in zs.items():
        a = np.asarray(v)
        print(f"| {k} | {len(a)} | {100 * np.mean(np.abs(a) <= 2):.0f} % | {a.mean():+.2f} "
              f"| {np.sqrt(np.mean(a * a)):.2f} |")
    for k, v in bounded.items():  # written as an interval: no standard error, no z
        print(f"{k}: only bounded in {len(v)} seed(s), the truth inside the interval in {sum(v)}")


if __name__ == "__main__":
    main()
