"""Monte Carlo check of a plan: record its profiles in simulation with noise, fit, compare.

Each run simulates every free-rotor profile of the plan at the true values with white noise of
the plan's levels (a ``numpy.random.Generator`` passed in), fits J, bv, bc, dz by simulation
error with the tool's engine (:func:`pmdcid.identify.simfit.fit_simulation`, the steps of
fit-nonlinear's local stage; R, L, km held) from a start off the truth, and returns the
estimates. Their spread over runs is the realised standard error the prediction must match.

The fit runs the kernel with internal steps of 50 us (:func:`pmdcid.plan.fisher.internal_steps`,
as the prediction does); the recording :data:`RECORD_FINER` times finer, so that the fit cannot
lock onto switching events placed on the very grid of its own kernel (with the same step for
both, the realised spread of bv came out 0.58x the prediction on a 120 s plan: the cost's
fine-scale steps, not the noise, held it). With the default 1 ms
step, stick-slip and dead-zone events move by whole steps and the cost is a staircase whose
treads, at the paper's noise, are hundreds of chi-square units high, far above the curvature
the noise sets: the fit then stops on a tread 5-10 predicted standard errors from the truth.
"""

from __future__ import annotations

import numpy as np

from pmdcid.io import Log
from pmdcid.model import Model
from pmdcid.plan import fisher as fi
from pmdcid.plan.design import Plan
from pmdcid.simulate import simulate_values

#: parameters fitted, and the factor the fit starts off by
FITTED = ("J", "bv", "bc", "dz")
START_OFF = {"J": 1.05, "bv": 0.95, "bc": 1.1, "dz": 0.9}
#: the recording's internal kernel step is this many times finer than the fit's
RECORD_FINER = 5


def recorded_logs(plan: Plan, vals: dict[str, float], rng: np.random.Generator,
                  nsub: int | None = None) -> list[Log]:
    """The plan's free-rotor profiles as noisy logs (omega, and i for a voltage drive)."""
    logs = []
    nsub = nsub or RECORD_FINER * fi.internal_steps(plan.profiles[-1].t)
    for p in plan.profiles:
        if p.blocked:
            continue
        sim = simulate_values(p.t, p.u, vals, plan.drive.torque_path, nsub)
        data = {plan.drive.column: p.u.copy(),
                "omega": sim.omega + rng.normal(0.0, plan.noise["omega"], len(p.t))}
        if plan.drive.electrical:
            data["i"] = sim.i + rng.normal(0.0, plan.noise["i"], len(p.t))
        logs.append(Log(f"{p.name}.csv", p.t.copy(), data, {"kind": p.kind}))
    return logs


def fit_once(plan: Plan, model: Model, rng: np.random.Generator,
             nsub: int | None = None) -> dict[str, float]:
    """One simulated recording of ``plan`` on ``model`` (the truth) and its fit."""
    from pmdcid.identify.nonlinear import DIFF_STEP
    from pmdcid.identify.simfit import fit_simulation

    vals = fi.model_values(model, plan.drive)
    nsub = nsub or fi.internal_steps(plan.profiles[-1].t)
    logs = recorded_logs(plan, vals, rng, RECORD_FINER * nsub)
    free = [n for n in FITTED if n in plan.names]
    start = {n: vals[n] * START_OFF[n] for n in free}
    sigma = [{"omega": plan.noise["omega"]}] * len(logs)
    res = fit_simulation(logs, model, free, signals=("omega",), start=start, sigma=sigma,
                         diff_step=DIFF_STEP, nsub=nsub, correlated=False)
    return res.values()


def monte_carlo(plan: Plan, model: Model, seeds, nsub: int | None = None) -> dict[str, np.ndarray]:
    """Estimates of each fitted parameter over runs, one run per seed (``default_rng(seed)``)."""
    runs = [fit_once(plan, model, np.random.default_rng(s), nsub) for s in seeds]
    return {n: np.array([r[n] for r in runs]) for n in runs[0]}


__all__ = ["FITTED", "fit_once", "monte_carlo", "recorded_logs"]
