"""Monte Carlo check of a plan: record its profiles in simulation with noise, fit, compare.

Each run simulates every free-rotor profile of the plan at the true values with white noise of
the plan's levels (a ``numpy.random.Generator`` passed in) and fits it as the pipeline does, by
simulation error with the tool's engine (:func:`pmdcid.fit.simfit.fit_simulation`): R and
L from the blocked-rotor step's current (``identify``'s fit-electrical: the free profiles'
current is not used for R, so neither here nor in the prediction,
:func:`pmdcid.plan.fisher.staged_stderr`), then J, bv, bc, dz from the speeds with R, L held at
their estimates and km at its value (fit-nonlinear's finite-difference steps), each from a start
2-3 % off the truth (the local stage alone: fit-nonlinear's grid stage finds the valley in
practice, and a start 10 % off dz can lie across a staircase level that the truth does not
cross). The spread of the estimates over runs is the realised standard error the
prediction (R, L's uncertainty included) must match.

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
from pmdcid.simulate import blocked_rotor, simulate_values

#: parameters fitted, and the factor the fit starts off by
FITTED = ("J", "bv", "bc", "dz")  # after R, L
START_OFF = {"J": 1.02, "bv": 0.98, "bc": 1.03, "dz": 0.97, "R": 1.02, "L": 0.98}
#: the recording's internal kernel step is this many times finer than the fit's
RECORD_FINER = 5


def recorded_logs(plan: Plan, vals: dict[str, float], rng: np.random.Generator,
                  nsub: int | None = None) -> list[Log]:
    """The plan's profiles as noisy logs: omega (free rotor), and i for a voltage drive."""
    logs = []
    nsub = nsub or RECORD_FINER * fi.internal_steps(plan.profiles[-1].t)
    for p in plan.profiles:
        v = blocked_rotor(vals) if p.blocked else vals
        sim = simulate_values(p.t, p.u, v, plan.drive.torque_path, nsub)
        data = {plan.drive.column: p.u.copy()}
        if not p.blocked:
            data["omega"] = sim.omega + rng.normal(0.0, plan.noise["omega"], len(p.t))
        if plan.drive.electrical:
            data["i"] = sim.i + rng.normal(0.0, plan.noise["i"], len(p.t))
        logs.append(Log(f"{p.name}.csv", p.t.copy(), data, {"kind": p.kind}))
    return logs


def fit_once(plan: Plan, model: Model, rng: np.random.Generator,
             nsub: int | None = None) -> dict[str, float]:
    """One simulated recording of ``plan`` on ``model`` (the truth) and its fit."""
    from pmdcid.fit.parameters import Parameters
    from pmdcid.fit.simfit import FitOptions, fit_simulation
    from pmdcid.identify.nonlinear import DIFF_STEP

    vals = fi.model_values(model, plan.drive)
    nsub = nsub or fi.internal_steps(plan.profiles[-1].t)
    logs = recorded_logs(plan, vals, rng, RECORD_FINER * nsub)
    out: dict[str, float] = {}
    work = model.copy()
    elec = [n for n in ("R", "L") if n in plan.names]
    if elec:
        # the current's simulation is exact at any internal step (linear, no back-EMF): 1
        held = [lg for lg, p in zip(logs, plan.profiles, strict=True) if p.blocked]
        res = fit_simulation(held, work,
                             Parameters.of(elec, {n: vals[n] * START_OFF[n] for n in elec}),
                             ("i",), sigma=[{"i": plan.noise["i"]}] * len(held),
                             options=FitOptions(nsub=1, correlated=False))
        out.update(res.values())
        for n in elec:
            work.set(n, out[n])
    free = [n for n in FITTED if n in plan.names]
    moving = [lg for lg in logs if lg.has("omega")]
    params = Parameters.of(free, {n: vals[n] * START_OFF[n] for n in free}, steps=DIFF_STEP)
    res = fit_simulation(moving, work, params, ("omega",),
                         sigma=[{"omega": plan.noise["omega"]}] * len(moving),
                         options=FitOptions(nsub=nsub, correlated=False))
    out.update(res.values())
    return out


def monte_carlo(plan: Plan, model: Model, seeds, nsub: int | None = None) -> dict[str, np.ndarray]:
    """Estimates of each fitted parameter over runs, one run per seed (``default_rng(seed)``)."""
    runs = [fit_once(plan, model, np.random.default_rng(s), nsub) for s in seeds]
    return {n: np.array([r[n] for r in runs]) for n in runs[0]}


__all__ = ["FITTED", "fit_once", "monte_carlo", "recorded_logs"]
