"""What diagnose spends its time on: simulations counted, and every refit's evaluations (#16).

    .venv/bin/python bench/diagnose_work.py                 # the demo logs (fixtures/hidden)
    .venv/bin/python bench/diagnose_work.py --fits          # and one line per refit
    .venv/bin/python bench/diagnose_work.py LOG.csv ... --km 0.0502

Runs ``pipeline.identify`` without diagnose to get the model diagnose starts from, then
``diagnose`` on the same logs as ``identify`` does, on one thread (``PMDCID_THREADS=1``) so that
the counts and CPU time do not depend on the machine's spare cores. A simulation is one
``Problem.simulate_all`` (every log once, or as far as the fitted part needs). The count is
machine-independent: compare it before and after a change to diagnose's search. Not a test:
nothing here asserts a number.
"""

from __future__ import annotations

import argparse
import glob
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("logs", nargs="*", help="logs (default: fixtures/hidden/*.csv)")
    ap.add_argument("--km", type=float, default=0.0502, help="torque constant [N m/A]")
    ap.add_argument("--fits", action="store_true", help="one line per least-squares refit")
    args = ap.parse_args(argv)
    os.environ["PMDCID_THREADS"] = "1"

    import numpy as np

    import pmdcid.fit.solver as solver
    from pmdcid import pipeline
    from pmdcid.diagnose.loop import diagnose
    from pmdcid.fit import problem
    from pmdcid.io import read_logs
    from pmdcid.model import Model
    from pmdcid.simulate import logs_for

    paths = args.logs or sorted(glob.glob(str(ROOT / "fixtures" / "hidden" / "*.csv")))
    logs = read_logs(paths)
    res = pipeline.identify(logs, Model(), km=args.km, run_diagnose=False)
    count = [0]
    fits = []
    simulate_all = problem.Problem.simulate_all
    least_squares = solver._least_squares

    def counted(self, vals, part="all"):
        count[0] += 1
        return simulate_all(self, vals, part)

    def traced(fun, z0, *a, **k):
        costs = []

        def f(z):
            r = fun(z)
            costs.append(float(r @ r))
            return r

        sol = least_squares(f, z0, *a, **k)
        fits.append((len(z0), sol.nfev, costs[0], min(costs), sol.message))
        return sol

    problem.Problem.simulate_all = counted
    solver._least_squares = traced
    t0, c0 = time.perf_counter(), time.process_time()
    try:
        out = diagnose(logs_for(logs, res.model), res.model)
    finally:
        problem.Problem.simulate_all = simulate_all
        solver._least_squares = least_squares
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    print(f"diagnose: {count[0]} simulations of all {len(logs)} logs, {len(fits)} refits "
          f"({sum(f[1] for f in fits)} evaluations outside Jacobians); {wall:.2f} s wall, "
          f"{cpu:.2f} s CPU on one thread; added {out.summary['added']}; speed NRMSE after "
          f"{out.summary['after'].get('omega_nrmse', np.nan):.5g}")
    if args.fits:
        for n, nfev, first, best, msg in fits:
            print(f"  {n} free, {nfev:3d} evaluations, chi-square {first:.6g} -> {best:.6g}: "
                  f"{msg[:48]}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
