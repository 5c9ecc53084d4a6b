"""Closed-loop logs: the two routes of fit-nonlinear (docs/identification.md, "Closed-loop logs").

- **logged output** (no ``--controller``): the motor is fitted on the controller's logged output
  as on any log; the noise the loop feeds back into that input is met by an autoregressive noise
  model (:func:`noise_model_for`): the residual is whitened before the cost, so noise coloured
  in time is not explained by the motor (prediction error, consistent in closed loop).
- **controller** (``--controller SPEC``): the closed loop is simulated from the logged reference
  (:mod:`pmdcid.simulate.closedloop`) and the motor's parameters fitted to the measured output
  and the logged controller output together (DIDIM-like: the EMPS authors fit the closed loop's
  simulated torque), started from the logged-output route. By default the residual is the
  controller output alone (the authors' input-error criterion): a loop holds its output on the
  reference whatever the motor, so the output's residual says little and, weighted by its small
  noise, would outweigh the input's; the measured signals are added on request (``signals``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from pmdcid.errors import FitError
from pmdcid.fit.parameters import Parameters
from pmdcid.fit.priors import prior_terms, stage_priors
from pmdcid.fit.problem import noise_level
from pmdcid.fit.simfit import FitOptions, fit_simulation
from pmdcid.fit.solver import blas_single_thread
from pmdcid.identify.nonlinear import (
    DIFF_STEP,
    DZ_CAVEAT,
    REFINE_RANGE,
    NonlinearResult,
    fit_nonlinear,
)
from pmdcid.identify.nonlinear_setup import reference_column
from pmdcid.model import Model
from pmdcid.simulate.closedloop import feedforward_of, reference_of, simulate_closed_loop
from pmdcid.simulate.controller import ControllerSpec

STAGE = "fit-nonlinear"
#: AR order of the noise model on closed-loop logs fitted on their logged output
AR_ORDER = 2


@dataclass
class Route:
    """Which route a fit took and why (printed by the commands)."""

    name: str  # "logged output" or "controller"
    why: str

    def line(self) -> str:
        return f"route: {self.name} ({self.why})"


def closed_loop_logs(logs, spec: ControllerSpec | None = None) -> bool:
    """True when the logs carry a set-point column (the spec's, or one named as a set-point)."""
    return reference_column(logs, (spec.reference,) if spec is not None else None) is not None


def noise_model_for(logs, spec: ControllerSpec | None = None) -> int:
    """AR order for the logged-output route: :data:`AR_ORDER` on closed-loop logs, else 0."""
    return AR_ORDER if closed_loop_logs(logs, spec) else 0


def logged_output_route(logs, spec=None, filters=()) -> Route:
    """The logged-output route's line; ``filters``: the fit's noise filters per residual block
    (:attr:`~pmdcid.fit.results.SimFitResult.noise_filters`)."""
    if not closed_loop_logs(logs, spec):
        return Route("logged output", "open-loop logs: the logged input drives the model")
    ref = spec.reference if spec is not None else reference_column(logs)
    why = (f"closed-loop logs (a set-point column, '{ref}') without "
           "--controller: fitted on the "
           f"controller's logged output, with an AR({AR_ORDER}) noise model so that the sensor "
           "noise the loop feeds back into it is not fitted")
    white = sum(f is None for f in filters)
    if white:
        why += (f"; {white} of {len(filters)} residual blocks left white: no colour there as "
                "fast as a sensor's filter (slower colour is the model's own error, not noise)")
    return Route("logged output", why)


#: a closed loop's measured signal follows its set-point: over a whole log, a least-squares
#: gain of the measured signal on the reference outside this range says they are in different
#: units (a reference in rpm against a speed in rad/s: 0.105; degrees against radians: 0.017)
TRACK_RANGE = (0.5, 2.0)


def reference_scale_warning(log, spec: ControllerSpec) -> str | None:
    """A warning when the measured signal does not follow the spec's reference in scale (the
    gain g of ``measured ~ g reference`` by least squares over the log outside
    :data:`TRACK_RANGE`); None when it does, or the reference never leaves 0."""
    r = reference_of(log, spec)
    y = np.asarray(log[spec.measured], float) if log.has(spec.measured) else None
    if y is None:
        return None
    ok = np.isfinite(r) & np.isfinite(y)
    den = float(np.sum(r[ok] ** 2))
    if den <= 0.0:
        return None
    g = float(np.sum(r[ok] * y[ok])) / den
    if TRACK_RANGE[0] <= g <= TRACK_RANGE[1]:
        return None
    unit = "rad/s" if spec.measured == "omega" else "rad"
    ref = f"{spec.measured}_ref"
    return (f"{log.path}: {spec.measured} follows the controller's reference "
            f"'{spec.reference}' at {g:.3g} times its value, not about 1: a unit apart? The "
            f"controller reads it in {unit}: map it (-c {ref}={spec.reference}*rpm) and set "
            f"reference={ref}")


def loop_simulator(spec: ControllerSpec):
    """``f(log, vals, x0)`` for :func:`fit_simulation`: the closed loop on the log's reference,
    the integrator started at the log's first controller output, an output quantum taken as
    its mean (half a count less): rounded, the simulated output would move by whole counts
    and the cost by steps, which a finite-difference Jacobian reads as flat (the fit stopped
    at its start: bench/closedloop_redteam.py a+)."""

    def sim(log, vals, x0):
        return simulate_closed_loop(log.t, vals, spec, reference_of(log, spec),
                                    log.drive == "tau", x0, logged_u=log.u,
                                    feedforward=feedforward_of(log, spec), mean_quantum=True,
                                    logged_y=log[spec.measured] if log.has(spec.measured)
                                    else None)
    return sim


def fit_closed_loop(logs, model: Model, spec: ControllerSpec, free=None, signals=None,
                    priors: bool = True, max_nfev: int = 100) -> NonlinearResult:
    """The controller route: fit-nonlinear's logged-output fit (the start), then the closed
    loop simulated from each log's reference through ``spec`` and fitted by simulation error
    on the logged controller output (and the measured ``signals`` when given). Returns a
    :class:`NonlinearResult` whose ``route`` says so. The model is not modified."""
    for lg in logs:  # a missing reference column: one clear error before any fit
        reference_of(lg, spec)
        feedforward_of(lg, spec)
    first = fit_nonlinear(logs, model, free=free, signals=signals, priors=priors,
                          noise_model=noise_model_for(logs, spec))
    measured = tuple(signals) if signals else ()
    with blas_single_thread():
        res = _refit(logs, model, spec, first, measured, priors, max_nfev)
    res.warnings.extend(w for w in (reference_scale_warning(lg, spec) for lg in logs) if w)
    return res


def _refit(logs, model, spec, first: NonlinearResult, measured, priors,
           max_nfev) -> NonlinearResult:
    # a dead zone masked by the friction stays so; one bounded by the logged input's levels
    # is refitted: the simulated controller output (its quantum taken as its mean) is smooth
    masked = "dz" in first.estimates and first.estimates["dz"].caveat == DZ_CAVEAT
    free = [n for n in first.estimates if n != "ramp" and not (n == "dz" and masked)]
    start = {n: first.estimates[n].value for n in free}
    work = model.copy()
    for n, e in first.estimates.items():
        if n != "ramp":
            work.set(n, e.value, stage="start")
    if "tau0" in first.estimates:
        work.add_effect("torque_offset")
    signals = (*measured, "u")
    sigma = [_sigma(lg, measured) for lg in logs]
    bounds = {k: (start[k] / REFINE_RANGE, start[k] * REFINE_RANGE)
              for k in ("J", "bv") if k in start and start[k] > 0}
    prior = stage_priors(model, free, STAGE) if priors else {}
    try:
        params = Parameters.of(free, start, bounds, DIFF_STEP, prior_terms(prior))
        fit = fit_simulation(logs, work, params, signals, sigma=sigma,
                             options=FitOptions(max_nfev), simulator=loop_simulator(spec))
    except FitError as exc:
        raise FitError(f"closed-loop fit failed: {exc}") from None
    est = dict(fit.estimates)
    if masked:
        est["dz"] = first.estimates["dz"]
    route = Route("controller", f"--controller given: the loop simulated from the logged "
                  f"reference '{spec.reference}' ({spec.describe()}); fitted on the logged "
                  f"controller output{''.join(', ' + s for s in measured)}")
    res = NonlinearResult(est, fit, signals, first.paths, first.start, start, 0,
                          first.seconds, list(first.warnings),
                          {n: prior[n][0] for n in fit.priors})
    res.route = route
    res.open_loop = first
    return res


def _sigma(log, signals) -> dict[str, float]:
    """Noise std per signal; the controller output's is at least 2 % of its spread (a quantised
    output's second differences are mostly 0, which would weigh it without limit)."""
    out = {s: noise_level(log[s]) for s in signals if log.has(s)}
    u = np.asarray(log.u, float)
    out["u"] = max(noise_level(u), 0.02 * float(np.std(u)) or 1e-12)
    return out
