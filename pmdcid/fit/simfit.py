"""Simulation-error fits of fit-mechanical's joint fit, fit-nonlinear and the real-log stages.

A thin layer over :class:`~pmdcid.fit.problem.Problem`: every sample of the chosen signals of
every log is fitted, each log from its measured start (a log that starts turning has its
starting speed fitted too). The cost is only piecewise smooth (stiction, dead-zone switching):
scipy's trust-region reflective least squares with finite-difference steps large enough to
step over the kernel's event quantisation (:class:`~pmdcid.fit.parameters.Parameter`'s
``step``), started from a global stage done elsewhere (grid / inverse dynamics). Priors,
an autoregressive noise model and the held parameters' own uncertainty enter here; the
covariance is :mod:`pmdcid.fit.covariance`'s.
"""

from __future__ import annotations

import math
import threading
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from pmdcid.errors import FitError
from pmdcid.fit.covariance import (
    block_covariance,
    correlation_time,
    envelope_jacobian,
    parameter_covariance,
    propagated,
    standard_errors,
    white_covariance,
)
from pmdcid.fit.parameters import STEP, Parameters
from pmdcid.fit.problem import Problem, Simulation
from pmdcid.fit.results import FitStats, SimFitResult, correlations, fitted, nrmse
from pmdcid.fit.solver import blas_single_thread, scale_of, solve
from pmdcid.fit.tall import TALL_ROWS
from pmdcid.model import Model
from pmdcid.model.effects import unit_of
from pmdcid.model.effects.sensor_delay import sensor_lag_limit
from pmdcid.runtime.cpus import pmap
from pmdcid.simulate import param_values
from pmdcid.simulate.initial import moving_start
from pmdcid.simulate.layout import NSTATE

#: times a local stage that ran out of evaluations (``max_nfev``) is run on from where it
#: stopped, while that lowers the chi-square: on a two-level +-10 V PRBS with current logged
#: (paper-like motor, 1 kHz, 20 s, 100 levels of 0.2 s; docs/identification.md, "Local
#: stages that run out of evaluations") the joint fit stopped at its 200 evaluations on
#: 2 of 10 seeds with bc at +4.0 and +5.2 of its standard errors; run on, +2.0 and +2.1, and
#: bv's and bc's RMS z over the 10 seeds 2.0, 2.2 -> 1.0, 1.2 (session 22)
CONTINUATIONS = 2


@dataclass(frozen=True)
class FitOptions:
    """How a simulation-error fit runs: at most ``max_nfev`` evaluations; ``nsub`` internal
    steps per sample (None: the kernel's choice); each log from its measured first samples
    (``initial``, :mod:`pmdcid.simulate.initial`) or from rest; ``cov_step``: the relative step
    of the central differences giving the covariance; ``correlated``: the covariance allows
    for a residual correlated in time (block sandwich) or is the white-residual formula
    ``(J'J)^-1 redchi``; ``noise_model``: order p of an autoregressive noise model (0: white):
    after a first fit each residual block's AR(p) whitening filter is estimated and the fit
    repeated on the filtered residual (prediction error; :func:`ar_whitener`), so that noise
    coloured in time that a controller fed back into the input cannot be explained by the
    model; ``continuations``: times a stage that ran out of evaluations is run on
    (:data:`CONTINUATIONS`; 0 for a probe that is meant to stop there)."""

    max_nfev: int = 200
    nsub: int | None = None
    initial: bool = True
    cov_step: float = 1e-2
    correlated: bool = True
    noise_model: int = 0
    continuations: int = CONTINUATIONS


def fit_simulation(logs, model: Model, params: Parameters | Sequence[str],
                   signals=("omega", "theta"), *,
                   sigma: list[dict[str, float]] | None = None,
                   options: FitOptions = FitOptions(), simulator=None) -> SimFitResult:
    """Fit the varying ``params`` of ``model`` by simulation error on ``logs``.

    ``params``: a :class:`~pmdcid.fit.parameters.Parameters` (start, bounds, prior, step of
    each, a parameter without a value starting from the model's; its fixed ones held for every
    log's simulation beyond the model's values, e.g. fit-nonlinear's ``ramp``, how the input
    varied between samples), or names to fit from the model's values within the catalogue's
    bounds. Other parameters stay at the model's values
    (effects not in ``model.effects`` off). ``sigma`` gives per-log noise std per signal
    (estimated when omitted). Priors add ``(x - mean)/std`` rows to the residual (see
    docs/identification.md). ``simulator``: ``f(log, vals, x0)`` replacing the open-loop
    simulation (:class:`~pmdcid.fit.problem.Simulation`). Returns a :class:`SimFitResult`; the
    model is not modified.
    """
    params = (params if isinstance(params, Parameters) else Parameters.of(params, {})).filled(
        param_values(model, logs[0].drive == "tau"))
    free = params.free
    if not free:
        raise FitError("nothing to fit: no free parameters")
    fixed = {n: p.value for n, p in params.items() if not p.vary}
    base = [{**param_values(model, log.drive == "tau"), **fixed} for log in logs]
    problem = Problem(logs, max_samples=None, plan=["fit"] * len(logs), signals=signals,
                      sigma=sigma, simulation=Simulation(options.nsub, initial=options.initial,
                                                         simulator=simulator))
    return _Fit(problem, params, base, options).run(held_uncertain(model, free, base[0]))


class _Fit:
    """One simulation-error fit: the solver's vector (the varying parameters, then each moving
    log's starting speed), its residual, the solve, the covariance."""

    def __init__(self, problem: Problem, params: Parameters, base, options: FitOptions):
        self.problem, self.base, self.options = problem, base, options
        self.free = params.free
        self.moving = [k for k, x in enumerate(problem.x0) if moving_start(x)]
        speeds = [problem.x0[k][1] for k in self.moving]
        lo, hi = params.bounds()
        self.lo = np.concatenate([lo, np.full(len(speeds), -np.inf)])
        self.hi = np.concatenate([hi, np.full(len(speeds), np.inf)])
        start = problem.start(params)
        self.x0 = np.concatenate([start, speeds])
        self.scale = np.concatenate([params.scales(start), scale_of(np.array(speeds, float))])
        self.steps = np.concatenate([params.steps(), np.full(len(speeds), STEP)])
        self.prior_rows = params.prior_rows()
        self.nd = problem.rows("all")  # data rows; the prior rows follow them
        self.nrows = self.nd + len(self.prior_rows)
        # columns on threads, each with its own kernel buffers: not for a tall residual, whose
        # buffers per thread would cost more memory than the threads save time
        self.parallel = self.nrows < TALL_ROWS
        self.whiten: list = [None] * len(problem.blocks("all"))  # per block: the AR filter
        self.weight = 1.0  # the prior rows' weight: the data's honest information (below)
        # the kernel's state buffers, reused across simulations: one set per thread (the
        # Jacobian's columns may run on several), dropped before the covariance
        self.bufs: dict[int, list] = {}

    def state(self, x) -> list[np.ndarray]:
        out = [x0k.copy() for x0k in self.problem.x0]
        for j, k in enumerate(self.moving):
            out[k][1] = x[len(self.free) + j]
        return out

    def sims(self, x, held=None):
        """Each log's simulation at ``x`` (``held``: values of held parameters replacing the
        model's); its arrays are valid until this thread's next call."""
        xs = self.state(x)
        tid = threading.get_ident()
        mine = self.bufs.get(tid)
        if mine is None:  # this thread's first simulation of the fit
            mine = self.bufs.setdefault(tid, [None] * len(self.problem.logs))
        out = []
        for k, log in enumerate(self.problem.logs):
            vals = dict(self.base[k])
            vals.update(dict(zip(self.free, x[:len(self.free)], strict=True)))
            vals.update(held or {})
            if mine[k] is None and self.problem.simulation.simulator is None:
                mine[k] = np.empty((len(log.t), NSTATE))
            out.append(self.problem.simulate(vals, k, x0=xs[k], out=mine[k]))
        return out

    def resid(self, z, out=None, held=None):
        """(simulated - measured) / sigma per block (whitened when a noise model is on), then
        the prior rows; into ``out``."""
        x = z * self.scale
        out = np.empty(self.nrows) if out is None else out
        self.problem.weighted(self.sims(x, held), "all", out, self.whiten)
        if self.prior_rows:
            out[self.nd:] = [self.weight * (x[j] - m) / sd for j, m, sd in self.prior_rows]
        return out

    def solve(self, z0):
        """The local stage from ``z0``, run on from where it stopped when it ran out of
        evaluations, at most ``options.continuations`` times, while that lowers the chi-square
        (its ``nfev`` then counts every run)."""
        s = self._solve_once(z0)
        for _ in range(self.options.continuations):
            if s.success:
                break
            more = self._solve_once(s.z)
            if not np.sum(more.fun ** 2) < np.sum(s.fun ** 2):
                break
            more.nfev += s.nfev
            s = more
        return s

    def _solve_once(self, z0):
        s = solve(self.resid, z0, self.lo / self.scale, self.hi / self.scale, scale=self.scale,
                  diff_step=self.steps, fills=True, max_nfev=self.options.max_nfev,
                  what="simulation-error fit", rows=self.nrows, parallel=self.parallel)
        s.jac = None  # unused here (the covariance takes wider central differences): frees m x n
        return s

    def jacobian(self, sol) -> np.ndarray:
        """The residual's envelope Jacobian at ``sol`` (:func:`envelope_jacobian`), in z."""
        return envelope_jacobian(self.resid, sol.z, sol.fun, self.lo / self.scale,
                                 self.hi / self.scale, self.options.cov_step, self.parallel)

    def run(self, held: dict[str, tuple[float, float]]) -> SimFitResult:
        sol = self.solve(self.x0 / self.scale)
        sol = _with_noise_model(self.solve, sol, self.problem.segments("all"), self.whiten,
                                self.options.noise_model, self.slowest_colour)
        if self.prior_rows:
            # the data rows are weighted by the noise; when the model leaves a residual many
            # times the noise, correlated in time, the logs carry far less information than
            # that weight says: the priors are weighed against the data's honest information,
            # the reduced chi-square times the correlated-residual inflation squared
            # (docs/identification.md)
            w = self.data_discount(sol)
            if w > 1.5:
                self.weight = w
                sol = self.solve(sol.z)
        return self.result(sol, held)

    def slowest_colour(self, sol) -> list[float]:
        """Per residual block: the largest pole modulus a sensor's noise can have at ``sol``
        (its filter no slower than :func:`sensor_lag_limit`, on the block's sample period)."""
        x = sol.z * self.scale
        out = []
        for k, _, _ in self.problem.segments("all"):
            vals = {**self.base[k], **dict(zip(self.free, x[:len(self.free)], strict=True))}
            dt = self.problem.logs[k].dt
            out.append(math.exp(-dt / sensor_lag_limit(vals, dt)))
        return out

    def data_discount(self, sol) -> float:
        """sqrt(reduced chi-square) x the correlated-residual inflation of the data rows at
        ``sol`` (>= 1): by how much the noise weights overstate the logs' information."""
        r = sol.fun[:self.nd]
        redchi = float(np.sum(r**2)) / max(self.nd - len(sol.z), 1)
        with blas_single_thread():
            Jd = self.jacobian(sol)[:self.nd]
        try:
            white = white_covariance(Jd, r)
            _, info = block_covariance(Jd, r, self.problem.segments("all"), white)
            infl = max(float(info.inflation), 1.0)
        except np.linalg.LinAlgError:
            infl = 1.0
        return math.sqrt(max(redchi, 1.0)) * infl

    def result(self, sol, held: dict[str, tuple[float, float]]) -> SimFitResult:
        x, free, npar = sol.x, self.free, len(self.free)
        ndata = int(sum(np.isfinite(ch.meas).sum() for ch in self.problem.channels))
        chisqr = float(np.sum(sol.fun[:self.nd] ** 2))
        stats = FitStats(ndata, len(x), chisqr, int(sol.nfev), bool(sol.success),
                         str(sol.message))
        # covariance from the Jacobian at the solution, scaled by the reduced chi-square. The
        # solver's forward differences may not cross any switching event for a parameter like
        # dz (a zero column, hence a zero standard error): the covariance uses central
        # differences over a wider step, the slope of the cost's smooth envelope. The
        # residual's correlation time first, beside no m-row matrix (the kernel's buffers freed,
        # the Jacobian's simulations take fresh ones): on a long log its FFT's buffers are the
        # fit's largest temporaries.
        self.bufs.clear()
        tau = (correlation_time(sol.fun[:self.nd], self.problem.segments("all"))
               if self.options.correlated else None)
        with blas_single_thread():
            Jm = self.jacobian(sol)
            Jm /= self.scale[None, :]
            hjac, hse = self.held_columns(sol.z, held)
        self.bufs.clear()  # no simulation until the last: freed for the covariance
        se, corr, info, extra, curv = _errors(Jm, sol.fun, self, stats.redchi, hjac, hse, tau)
        est = {n: fitted(n, v, e, unit_of(n))
               for n, v, e in zip(free, x[:npar], se[:npar], strict=True)}
        correl = {a: {b: float(corr[i, j]) for j, b in enumerate(free) if j != i}
                  for i, a in enumerate(free)}
        with blas_single_thread():
            errs, sig_out = _per_log(self.problem, self.sims(x))
        res = SimFitResult(est, stats, correl, errs, sig_out, info)
        res.held_cov = extra[:npar, :npar]
        res.curvature = curv[:npar, :npar]
        res.initial = self.state(x)
        res.priors = {free[j]: (m, sd) for j, m, sd in self.prior_rows}
        res.prior_weight = self.weight
        if self.options.noise_model:
            res.noise_filters = [None if w is None else tuple(map(float, w))
                                 for w in self.whiten]
        return res

    def held_columns(self, z, held: dict[str, tuple[float, float]]):
        """(the residual's derivatives with respect to each held parameter, their standard
        errors): central differences of relative step ``cov_step`` about the held values."""
        names = list(held)
        cols = np.empty((self.nrows, len(names)))
        step = self.options.cov_step

        def column(j):
            v = held[names[j]][0]
            h = step * abs(v)
            up = self.resid(z, held={names[j]: v + h})
            cols[:, j] = up - self.resid(z, held={names[j]: v - h})
            cols[:, j] /= 2 * h

        pmap(column, range(len(names)), self.parallel)
        return cols, np.array([held[n][1] for n in names])


def _errors(Jm, fun, fit: _Fit, redchi: float, hjac, hse, tau):
    """(standard errors, correlation matrix, CovarianceInfo or None, the part of the covariance
    the held parameters' errors add, the data rows' inverse curvature ``(J'J)^-1``) of the fit's
    vector; ``tau``: the residual's correlation time (None: not needed or not known)."""
    n = Jm.shape[1]
    extra, curv = np.zeros((n, n)), np.full((n, n), math.nan)
    try:
        extra = propagated(Jm, hjac, hse)  # before the covariance, which rescales Jm's columns
        cov, info, curv = parameter_covariance(Jm, fun, fit.nd, fit.problem.segments("all"),
                                               redchi, fit.options.correlated, fit.weight, tau)
        cov = cov + extra
        se = standard_errors(cov)  # NaN, never 0, where the variance is not positive
        corr = correlations(cov)
    except np.linalg.LinAlgError:
        return np.full(n, math.nan), np.full((n, n), math.nan), None, extra, curv
    return se, corr, info, extra, curv


def _with_noise_model(run, sol, segments, whiten: list, order: int, slowest):
    """With an AR noise model (``order`` > 0): each block's whitening filter estimated from the
    residual at ``sol`` (into ``whiten``; ``slowest(sol)``: each block's largest pole modulus of
    a sensor's noise), the fit run again from there, twice; else ``sol``. Where every block is
    left white the criterion is unchanged and so is ``sol``: no run again."""
    for _ in range(2 if order > 0 else 0):
        before = list(whiten)
        whiten[:] = [ar_whitener(sol.fun[a:b], order, w, z) for (_, a, b), w, z
                     in zip(segments, whiten, slowest(sol), strict=True)]
        if all(w is None for w in whiten) and all(w is None for w in before):
            break
        sol = run(sol.z)
    return sol


def ar_whitener(r: np.ndarray, order: int, before=None, slowest: float = 1.0
                ) -> np.ndarray | None:
    """The filter ``A(q) = 1 + a1 q^-1 + ... + ap q^-p`` that whitens the residual block ``r``
    (least squares on its own past; ``before``: the filter ``r`` was already whitened by,
    undone first, so that the filter is estimated on the raw residual). Poles of modulus above
    ``slowest`` are left out of it: colour slower than a sensor's filter is the model's own
    error drifting with the motor, not noise, and whitening it would fit the residual's
    increments instead of its level (docs/identification.md, "Closed-loop logs"). None when the
    block is too short, the filter not invertible, or the block white once the slow poles are
    left (every |a_j| < 1e-3)."""
    if before is not None:  # r is whitened by ``before``: undo it to estimate on the raw block
        from scipy.signal import lfilter  # only with a noise model: the import costs ~1 s

        r = lfilter([1.0], before, r)
    n = len(r)
    if n < 20 * max(order, 1):
        return None
    X = np.column_stack([r[order - j - 1:n - j - 1] for j in range(order)])
    coef, *_ = np.linalg.lstsq(X, r[order:], rcond=None)
    a = np.concatenate([[1.0], -coef])
    if not np.all(np.isfinite(a)):
        return None
    poles = np.roots(a)
    if np.max(np.abs(poles)) >= 0.999:
        return None  # not invertible: keep the block white
    kept = poles[np.abs(poles) <= slowest]
    a = np.real(np.poly(kept)) if len(kept) else np.ones(1)
    return a if len(a) > 1 and np.max(np.abs(a[1:])) > 1e-3 else None


def held_uncertain(model: Model, free, kernel_values: dict[str, float]
                   ) -> dict[str, tuple[float, float]]:
    """Parameters a fit holds at the model's values that carry a standard error from the stage
    that identified them (R and L from the blocked rotor; a datasheet km has none) and that the
    simulation uses: name -> (value, standard error)."""
    out = {}
    for name, par in model.parameters.items():
        v = kernel_values.get(name)
        if name in free or v is None or v == 0 or not math.isfinite(v):
            continue
        if math.isfinite(par.stderr) and par.stderr > 0:
            out[name] = (float(v), float(par.stderr))
    return out


def _per_log(problem: Problem, final):
    """Per log: signal -> NRMSE of the final simulation, and signal -> the noise std used."""
    errs: list[dict[str, float]] = [dict() for _ in problem.logs]
    sig_out: list[dict[str, float]] = [dict() for _ in problem.logs]
    for ch in problem.channels:
        errs[ch.log][ch.signal] = nrmse(final[ch.log].get(ch.signal), ch.meas)
        sig_out[ch.log][ch.signal] = ch.sigma
    return errs, sig_out


__all__ = ["FitOptions", "ar_whitener", "fit_simulation", "held_uncertain"]
