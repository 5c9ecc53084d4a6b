"""Simulation-error fitting engine shared by fit-nonlinear, diagnose and the real-log stages.

The residual is (simulated - measured) / sigma for each chosen signal of each log, the simulation
being the shared exact kernel from rest on the log's own input. sigma is the signal's noise level,
estimated from the data (second differences, robust) unless given. The cost is only piecewise
smooth (stiction, dead-zone switching): we use scipy's trust-region reflective least squares with
finite-difference steps large enough to step over the kernel's event quantisation
(``diff_step``), started from a global stage done elsewhere (grid / inverse dynamics).
"""

from __future__ import annotations

import math
import threading
from collections.abc import Sequence

import numpy as np

from pmdcid.errors import FitError
from pmdcid.identify.covariance import block_covariance
from pmdcid.identify.cpus import pmap
from pmdcid.identify.results import Estimate, FitStats, SimFitResult, nrmse
from pmdcid.identify.solver import blas_single_thread, solve, white_covariance
from pmdcid.identify.tall import BLOCK_ROWS, TALL_ROWS
from pmdcid.model import Model
from pmdcid.model.effects import bounds_of, unit_of
from pmdcid.simulate import param_values, simulate_values
from pmdcid.simulate.initial import initial_state, moving_start
from pmdcid.simulate.layout import NSTATE


def noise_level(x: np.ndarray) -> float:
    """Robust white-noise std of a signal from its second difference (MAD), same unit as ``x``.

    For a quantised signal (encoder angle) the floor is quantum/sqrt(12).
    """
    from pmdcid.io.derive import noise_std

    x = np.asarray(x, float)
    x = x[np.isfinite(x)]
    if len(x) < 5:
        return 1.0
    s = noise_std(x)
    if s <= 0 or not math.isfinite(s):
        s = max(float(np.std(x)) * 1e-3, 1e-12)
    return s


def _per_parameter(step, free, default: float, extra: int):
    """A relative step: one for all, or per parameter name (``default`` for the others and for
    the ``extra`` starting speeds)."""
    if not isinstance(step, dict):
        return float(step)
    return np.array([float(step.get(n, default)) for n in free] + [default] * extra)


def _bounds(name: str, user: dict | None) -> tuple[float, float]:
    return user[name] if user and name in user else bounds_of(name)


def available_signals(log, signals: Sequence[str]) -> list[str]:
    """The ``signals`` a log can be compared on; ``u`` is its input column (a closed-loop
    simulation computes it: :mod:`pmdcid.simulate.closedloop`)."""
    return [s for s in signals if s == "u" or log.compares(s)]


def _measured(log, s: str) -> np.ndarray:
    return log.u if s == "u" else log[s]


def fit_simulation(logs, model: Model, free: Sequence[str], signals=("omega", "theta"),
                   start: dict[str, float] | None = None,
                   bounds: dict[str, tuple[float, float]] | None = None,
                   sigma: list[dict[str, float]] | None = None, max_nfev: int = 200,
                   diff_step: float | dict[str, float] = 1e-3, nsub: int | None = None,
                   cov_step: float = 1e-2, correlated: bool = True,
                   priors: dict[str, tuple[float, float]] | None = None,
                   initial: bool = True,
                   overrides: dict[str, float] | None = None,
                   simulator=None, noise_model: int = 0) -> SimFitResult:
    """Fit ``free`` parameters of ``model`` by simulation error on ``logs``.

    Other parameters stay at the model's values (effects not in ``model.effects`` off).
    ``start`` overrides starting values; ``bounds`` maps name -> (lower, upper) in SI units;
    ``sigma`` gives per-log noise std per signal (estimated when omitted). ``diff_step``: relative
    finite-difference step, one for all or per parameter name (default 1e-3). ``cov_step``: relative
    step of the central differences giving the covariance (standard errors, correlations), one
    for all or per parameter name like ``diff_step``.
    ``correlated``: the covariance allows for a residual correlated in time (block sandwich,
    :mod:`.covariance`); False gives the white-residual formula ``(J'J)^-1 redchi``.
    ``priors``: name -> (mean, std) Gaussian terms from earlier stages (``(x - mean)/std`` rows
    added to the residual; see docs/identification.md). ``initial``: each log starts from its
    measured first samples (:mod:`.initial`), a log that starts turning has its starting speed
    fitted too; False starts every log from rest. ``overrides``: values held for every log's
    simulation beyond the model's (e.g. fit-nonlinear's ``ramp``, how the input varied between
    samples, :mod:`pmdcid.simulate.drive`).
    ``simulator``: ``f(log, vals, x0)`` -> a result with ``.get(signal)`` replacing the
    open-loop simulation of each log (the closed loop, :mod:`pmdcid.simulate.closedloop`).
    ``noise_model``: order p of an autoregressive noise model (0: white, as by default): after a
    first fit each residual block's AR(p) whitening filter is estimated and the fit repeated on
    the filtered residual (prediction error; :func:`ar_whitener`), so that noise coloured in
    time that a controller fed back into the input cannot be explained by the model.
    Returns a :class:`SimFitResult`; the model is not modified.
    """
    free = list(free)
    if not free:
        raise FitError("nothing to fit: no free parameters")
    base = [{**param_values(model, log.drive == "tau"), **(overrides or {})} for log in logs]
    sig_list = sigma or []
    starts = _initial_states(logs, sig_list, initial)
    moving = [k for k, x in enumerate(starts) if moving_start(x)]
    x0, lo, hi = _start_vector(free, start, base[0], [starts[k][1] for k in moving], bounds)
    scale = np.where(np.abs(x0) > 0, np.abs(x0), 1.0)
    npar = len(free)
    prior_rows = [(j, *priors[n]) for j, n in enumerate(free)
                  if priors and n in priors and priors[n][1] > 0 and math.isfinite(priors[n][1])]
    plan, segments = _residual_plan(logs, signals, sig_list)
    ndata = int(sum(np.isfinite(m).sum() for _, _, m, _ in plan))

    def state(x):
        out = [x0k.copy() for x0k in starts]
        for j, k in enumerate(moving):
            out[k][1] = x[npar + j]
        return out

    # the kernel's state buffers, reused across simulations: one set per thread (the Jacobian's
    # columns may run on several), dropped before the covariance
    bufs: dict[int, list] = {}

    def sims(x, held=None):
        """Each log's simulation at ``x`` (``held``: values of held parameters replacing the
        model's); its arrays are valid until this thread's next call."""
        out = []
        xs = state(x)
        tid = threading.get_ident()
        mine = bufs.get(tid)
        if mine is None:  # this thread's first simulation of the fit
            mine = bufs.setdefault(tid, [None] * len(logs))
        for k, log in enumerate(logs):
            vals = dict(base[k])
            vals.update(dict(zip(free, x[:npar], strict=True)))
            vals.update(held or {})
            if simulator is not None:
                out.append(simulator(log, vals, xs[k]))
                continue
            if mine[k] is None:
                mine[k] = np.empty((len(log.t), NSTATE))
            out.append(simulate_values(log.t, log.u, vals, log.drive == "tau", nsub, xs[k],
                                       mine[k]))
        return out

    nrows = segments[-1][2] + len(prior_rows)
    # columns on threads, each with its own kernel buffers: not for a tall residual, whose
    # buffers per thread would cost more memory than the threads save time
    parallel = nrows < TALL_ROWS

    whiten: list = [None] * len(plan)  # per block: the AR whitening filter, once estimated

    def resid(z, out=None, held=None):
        """(simulated - measured) / sigma per block (whitened when a noise model is on), then
        the prior rows; into ``out``."""
        x = z * scale
        ss = sims(x, held)
        out = np.empty(nrows) if out is None else out
        _fill_blocks(out, ss, plan, segments, whiten)
        if prior_rows:
            out[segments[-1][2]:] = [weight[0] * (x[j] - m) / sd for j, m, sd in prior_rows]
        return out

    steps = _per_parameter(diff_step, free, 1e-3, len(moving))
    cov_step = _per_parameter(cov_step, free, 1e-2, len(moving))
    weight = [1.0]  # the prior rows' weight: the data's honest information (below)

    def run(z0):
        s = solve(resid, z0, lo / scale, hi / scale, scale=scale, diff_step=steps, fills=True,
                  max_nfev=max_nfev, what="simulation-error fit", rows=nrows, parallel=parallel)
        s.jac = None  # unused here (the covariance takes wider central differences): frees m x n
        return s

    sol = run(x0 / scale)
    nd = len(sol.fun) - len(prior_rows)  # data rows; the prior rows follow them
    sol = _with_noise_model(run, sol, segments, whiten, noise_model)
    if prior_rows:
        # the data rows are weighted by the noise; when the model leaves a residual many times
        # the noise, correlated in time, the logs carry far less information than that weight
        # says: the priors are weighed against the data's honest information, the reduced
        # chi-square times the correlated-residual inflation squared (docs/identification.md)
        w = _data_discount(resid, sol, nd, segments, lo / scale, hi / scale, cov_step,
                               parallel)
        if w > 1.5:
            weight[0] = w
            sol = run(sol.z)
    x = sol.x
    chisqr = float(np.sum(sol.fun[:nd] ** 2))
    stats = FitStats(ndata, len(x), chisqr, int(sol.nfev), bool(sol.success), str(sol.message))
    # covariance from the Jacobian at the solution, scaled by the reduced chi-square. The
    # solver's forward differences (diff_step) may not cross any switching event for a
    # parameter like dz (a zero column, hence a zero standard error): the covariance uses
    # central differences over a wider step, the slope of the cost's smooth envelope.
    with blas_single_thread():
        Jm = envelope_jacobian(resid, sol.z, sol.fun, lo / scale, hi / scale, cov_step,
                                parallel)
        Jm /= scale[None, :]
        held = _held_columns(resid, sol.z, nrows, held_uncertain(model, free, base[0]),
                             cov_step, parallel)
    bufs.clear()  # no simulation until the last: freed for the covariance
    try:
        extra = propagated(Jm, *held)  # before _covariance, which rescales Jm's columns
        cov, info = _covariance(Jm, sol.fun, nd, segments, stats.redchi, correlated, weight[0])
        cov = cov + extra
        se = np.sqrt(np.clip(np.diag(cov), 0, None))
        with np.errstate(invalid="ignore", divide="ignore"):
            corr = cov / np.outer(se, se)
    except np.linalg.LinAlgError:
        info = None
        se = np.full(len(x), math.nan)
        corr = np.full((len(x), len(x)), math.nan)
    est = {n: Estimate(n, float(v), float(e), unit_of(n))
           for n, v, e in zip(free, x[:npar], se[:npar], strict=True)}
    correl = {a: {b: float(corr[i, j]) for j, b in enumerate(free) if j != i}
              for i, a in enumerate(free)}
    with blas_single_thread():
        errs, sig_out = _per_log(plan, sims(x), len(logs))
    res = SimFitResult(est, stats, correl, errs, sig_out, info)
    res.initial = state(x)
    res.priors = {free[j]: (m, sd) for j, m, sd in prior_rows}
    return res


def _with_noise_model(run, sol, segments, whiten: list, order: int):
    """With an AR noise model (``order`` > 0): each block's whitening filter estimated from the
    residual at ``sol`` (into ``whiten``), the fit run again from there, twice; else ``sol``."""
    for _ in range(2 if order > 0 else 0):
        whiten[:] = [ar_whitener(sol.fun[a:b], order, w) for (_, a, b), w
                     in zip(segments, whiten, strict=True)]
        sol = run(sol.z)
    return sol


def _fill_blocks(out, ss, plan, segments, whiten) -> None:
    """The data rows of the residual into ``out``: (simulated - measured) / sigma per block,
    whitened by the block's filter when it has one, non-finite rows 0."""
    for j, ((k, s, meas, sd), (_, a, b)) in enumerate(zip(plan, segments, strict=True)):
        r = out[a:b]
        np.subtract(ss[k].get(s), meas, out=r)
        np.divide(r, sd, out=r)
        r[~np.isfinite(r)] = 0.0
        if whiten[j] is not None:  # the FIR filter A(q): numpy, not scipy.signal (1 s import)
            r[:] = np.convolve(r, whiten[j])[: len(r)]


def ar_whitener(r: np.ndarray, order: int, before=None) -> np.ndarray | None:
    """The filter ``A(q) = 1 + a1 q^-1 + ... + ap q^-p`` that whitens the residual block ``r``
    (least squares on its own past; ``before``: the filter ``r`` was already whitened by,
    undone first, so that the filter is estimated on the raw residual). None when the block is
    too short, the filter not invertible, or the block already white (every |a_j| < 1e-3)."""
    if before is not None:  # r is whitened by ``before``: undo it to estimate on the raw block
        from scipy.signal import lfilter  # only with a noise model: the import costs ~1 s

        r = lfilter([1.0], before, r)
    n = len(r)
    if n < 20 * max(order, 1):
        return None
    X = np.column_stack([r[order - j - 1:n - j - 1] for j in range(order)])
    coef, *_ = np.linalg.lstsq(X, r[order:], rcond=None)
    a = np.concatenate([[1.0], -coef])
    if not np.all(np.isfinite(a)) or np.max(np.abs(np.roots(a))) >= 0.999:
        return None  # not invertible: keep the block white
    return a if np.max(np.abs(coef)) > 1e-3 else None


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


def _held_columns(resid, z, nrows: int, held: dict[str, tuple[float, float]], rel, parallel):
    """(the residual's derivatives with respect to each held parameter, their standard
    errors): central differences of relative step ``rel`` about the held values."""
    names = list(held)
    cols = np.empty((nrows, len(names)))
    step = float(np.max(np.atleast_1d(rel)))

    def column(j):
        v = held[names[j]][0]
        h = step * abs(v)
        up = resid(z, held={names[j]: v + h})
        cols[:, j] = up - resid(z, held={names[j]: v - h})
        cols[:, j] /= 2 * h

    pmap(column, range(len(names)), parallel)
    return cols, np.array([held[n][1] for n in names])


def propagated(jac: np.ndarray, held_jac: np.ndarray, held_se: np.ndarray) -> np.ndarray:
    """The covariance the held parameters' own uncertainty adds to the fitted ones (a two-step
    estimator: the fitted values move by G = -(J'J)^-1 J'J_h per unit of the held ones, so
    cov += G diag(se_h^2) G')."""
    if held_jac.shape[1] == 0:
        return np.zeros((jac.shape[1], jac.shape[1]))
    g = -np.linalg.lstsq(jac, held_jac, rcond=None)[0]
    return (g * held_se**2) @ g.T


def _per_log(plan, final, nlogs: int):
    """Per log: signal -> NRMSE of the final simulation, and signal -> the noise std used."""
    errs: list[dict[str, float]] = [dict() for _ in range(nlogs)]
    sig_out: list[dict[str, float]] = [dict() for _ in range(nlogs)]
    for k, s, meas, sd in plan:
        errs[k][s] = nrmse(final[k].get(s), meas)
        sig_out[k][s] = sd
    return errs, sig_out


def _start_vector(free, start, base, speeds, bounds):
    """Start, lower and upper bounds of the solver's vector: the free parameters [their SI
    units], then each moving log's starting speed [rad/s]; raises when a start is missing."""
    x0 = []
    for name in free:
        v = (start or {}).get(name, base.get(name, math.nan))
        if not math.isfinite(v):
            raise FitError(f"no starting value for '{name}'")
        x0.append(v)
    lo = np.array([_bounds(n, bounds)[0] for n in free] + [-np.inf] * len(speeds))
    hi = np.array([_bounds(n, bounds)[1] for n in free] + [np.inf] * len(speeds))
    return np.clip(np.array(x0 + list(speeds), float), lo, hi), lo, hi


def _residual_plan(logs, signals, sig_list):
    """The residual's blocks: (log index, signal, measured, noise std) each, and their rows
    (log index, first row, end row) in the residual vector."""
    plan = []
    segments = []
    for k, log in enumerate(logs):
        given = sig_list[k] if k < len(sig_list) else {}
        for s in available_signals(log, signals):
            meas = _measured(log, s)
            plan.append((k, s, meas, float(given.get(s, noise_level(meas)))))
            row = segments[-1][2] if segments else 0
            segments.append((k, row, row + len(meas)))
    if not plan:
        raise FitError(f"no log carries any of the signals {', '.join(signals)} to fit")
    return plan, segments


def _initial_states(logs, sig_list, initial: bool) -> list[np.ndarray]:
    """Each log's starting state (:mod:`.initial`), or rest for every log."""
    if not initial:
        return [np.zeros(3) for _ in logs]
    out = []
    for k, log in enumerate(logs):
        given = sig_list[k] if k < len(sig_list) else {}
        out.append(initial_state(log, given.get("omega")))
    return out


def _data_discount(resid, sol, nd, segments, lo, hi, cov_step, parallel=True) -> float:
    """sqrt(reduced chi-square) x the correlated-residual inflation of the data rows at ``sol``
    (>= 1): by how much the noise weights overstate the logs' information."""
    r = sol.fun[:nd]
    redchi = float(np.sum(r**2)) / max(nd - len(sol.z), 1)
    with blas_single_thread():
        Jd = envelope_jacobian(resid, sol.z, sol.fun, lo, hi, cov_step, parallel)[:nd]
    try:
        white = white_covariance(Jd, r)
        _, info = block_covariance(Jd, r, segments, white)
        infl = max(float(info.inflation), 1.0)
    except np.linalg.LinAlgError:
        infl = 1.0
    return math.sqrt(max(redchi, 1.0)) * infl


def _covariance(Jm, fun, nd, segments, redchi, correlated, weight=1.0):
    """Parameter covariance: the data rows' (white or correlated-residual sandwich), combined
    with the prior rows' information: ``(Hd + P)^-1 (Sd + w^2 P) (Hd + P)^-1`` where ``Sd`` is
    the data score's covariance (``Hd cov_d Hd``), ``P`` the (weighted) prior rows' precision
    and ``w`` their weight (the prior means' own variance, scaled like their rows).

    Computed with the Jacobian's columns scaled to unit norm (``Jm`` is scaled in place) and
    scaled back (the same covariance): parameters of very different sizes (LuGre's sigma0 ~
    1e2 N m/rad beside bc ~ 1e-3 N m) would otherwise give J'J a condition number past the
    pseudo-inverse's cut-off, which then zeroes the small direction's variance."""
    norms = _column_norms(Jm)
    d = np.where(norms > 0, 1.0 / np.where(norms > 0, norms, 1.0), 1.0)
    Jm *= d  # in place: the caller's matrix, not used after (no m x n copy on long logs)
    cov, info = _scaled_covariance(Jm, fun, nd, segments, redchi, correlated, weight)
    return cov * np.outer(d, d), info


def _column_norms(J: np.ndarray) -> np.ndarray:
    """Euclidean norm of each column; on a tall matrix a block of rows at a time (no m x n
    square), which agrees with ``np.linalg.norm(J, axis=0)`` to rounding."""
    if len(J) < TALL_ROWS:
        return np.linalg.norm(J, axis=0)
    ss = np.zeros(J.shape[1])
    for a in range(0, len(J), BLOCK_ROWS):
        ss += np.einsum("ij,ij->j", J[a:a + BLOCK_ROWS], J[a:a + BLOCK_ROWS])
    return np.sqrt(ss)


def _scaled_covariance(Jm, fun, nd, segments, redchi, correlated, weight):
    Jd = Jm[:nd]
    Hd = Jd.T @ Jd
    cov = np.linalg.pinv(Hd) * redchi
    info = None
    if correlated:
        cov, info = block_covariance(Jd, fun[:nd], segments, cov)
    if nd == len(fun):
        return cov, info
    Jp = Jm[nd:]
    P = Jp.T @ Jp
    Sd = Hd @ cov @ Hd
    Hinv = np.linalg.pinv(Hd + P)
    return Hinv @ (Sd + weight**2 * P) @ Hinv, info


def envelope_jacobian(fun, z, f0, lo, hi, rel, parallel: bool = True) -> np.ndarray:
    """Central-difference Jacobian of ``fun`` at ``z`` with relative step ``rel`` (one for all or
    one per column; one-sided at a bound); columns that still come out zero fall back to a 5x
    wider step. With ``parallel`` the columns are shared with the spare CPUs
    (:func:`pmdcid.identify.cpus.pmap`): ``fun`` must be safe to call from several threads;
    the same bits for any number of threads."""
    J = np.empty((len(f0), len(z)))  # filled column by column: no list of columns to stack
    rels = np.broadcast_to(np.asarray(rel, float), (len(z),))

    def column(j):
        for r in (rels[j], 5 * rels[j]):
            h = r * max(abs(z[j]), 1e-12)
            up, dn = min(z[j] + h, hi[j]), max(z[j] - h, lo[j])
            if up <= dn:
                J[:, j] = 0.0
                break
            zu, zd = z.copy(), z.copy()
            zu[j], zd[j] = up, dn
            fu = fun(zu) if up > z[j] else f0
            fd = fun(zd) if dn < z[j] else f0
            d = fu - fd  # then divided in place: one temporary of the residual's length
            d /= up - dn
            J[:, j] = d
            del d
            if np.any(J[:, j] != 0):
                break

    pmap(column, range(len(z)), parallel)
    return J


def format_estimates(estimates, width: int = 10) -> list[str]:
    """Table lines ``name  value ± stderr  unit`` (``fixed`` when the parameter did not vary;
    a bounded one in words, ``name  between LOW and HIGH UNIT (why)``)."""
    from pmdcid.model.tables import in_words

    lines = [f"{'parameter':<{width}} {'value':>13}   {'± stderr':<11} unit"]
    for e in estimates:
        if e.interval is not None:
            lines.append(f"{e.name:<{width}} {in_words(e.interval, e.unit, e.caveat)}")
            continue
        if not e.vary:
            se = "(fixed)"
        elif math.isfinite(e.stderr):
            se = f"± {e.stderr:.2g}"
        else:
            se = "± ?"
        why = f"  ({e.caveat})" if e.caveat else ""
        lines.append(f"{e.name:<{width}} {e.value:13.6g}   {se:<11} {e.unit}".rstrip() + why)
    return lines
