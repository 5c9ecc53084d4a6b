"""Parameter covariance of a least-squares fit whose residual is correlated in time.

The textbook covariance ``(J'J)^-1 * redchi`` assumes white residuals: each sample an independent
piece of evidence. A simulation-error residual on real data is mostly model error, correlated over
seconds, and a speed derived from an encoder is a filtered signal, correlated over the filter's
length: the white formula then counts thousands of samples as independent and understates the
standard errors by orders of magnitude (EMPS: +-0.006 N on an offset that moves by 0.3 N between
reasonable criteria).

:func:`block_covariance` is the sandwich estimator with a heteroskedasticity-and-autocorrelation
consistent (HAC) middle term computed by **block sums** (batch means; Kuensch 1989, Politis &
Romano 1994 for the block idea, Newey & West 1987 for HAC):

    cov = H^-1 S H^-1,   H = J'J,   S = B/(B-1) sum_b (g_b - mean g)(g_b - mean g)',
    g_b = sum over the samples of block b of J_t' r_t,

with blocks of consecutive samples longer than the residual's correlation time, one time
window of one log per block (every signal of that log in that window summed into the same
block, since they share the model error). For white residuals it equals the textbook
covariance (blocks of a few samples); for correlated residuals it grows as the effective number of
independent samples shrinks. The block length is four times the residual's integrated
autocorrelation time (Sokal's automatic window), capped so that every log keeps at least
:data:`MIN_BLOCKS` blocks. The estimate is consistent but biased low when a log spans few
correlation times; :class:`CovarianceInfo` then says the errors are lower bounds.

Every fit's covariance is formed here: the textbook one (:func:`white_covariance`), the
sandwich, a simulation-error fit's with prior rows and held parameters
(:func:`parameter_covariance`, :func:`propagated`), from the Jacobian of the cost's smooth
envelope (:func:`envelope_jacobian`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pmdcid.fit.tall import BLOCK_ROWS, TALL_ROWS
from pmdcid.runtime.cpus import pmap

#: fewest blocks per log (a variance from fewer blocks is too noisy to use)
MIN_BLOCKS = 10
#: block length in integrated autocorrelation times (longer: less bias, fewer blocks)
BLOCK_TAUS = 4.0
#: a log shorter than this many correlation times gives standard errors biased low (Monte Carlo
#: of fit-nonlinear: ~0.5x the true spread at 50, 0.8-1.1x at 150, tests/fit/test_covariance.py)
MIN_TAUS = 50.0
#: Sokal's window constant: sum the autocorrelation up to the first lag W >= C * tau(W)
SOKAL_C = 5.0
#: rows of the Jacobian weighted by the residual at a time in the block sums (bounded memory on
#: long logs; each block's sum is the same whatever the chunk)
CHUNK_ROWS = 1 << 16
#: residuals at least this long (a 17-minute log at 1 kHz) have their power spectrum formed in
#: place (:func:`integrated_time`): the same to rounding, without two more spectrum-sized arrays
LEAN_SAMPLES = 1 << 20


@dataclass
class CovarianceInfo:
    """How the covariance was formed: block length [samples], blocks, correlation time [samples],
    whether the standard errors are only lower bounds (the shortest log spans fewer than
    :data:`MIN_TAUS` correlation times, or the block length was capped), and the factor by which
    they exceed the white-residual formula (the largest over parameters)."""

    block: int
    blocks: int
    tau_int: float
    lower_bound: bool
    inflation: float

    def describe(self) -> str:
        """One line for a fit's table."""
        line = (f"standard errors allow for a residual correlated over {self.tau_int:.3g} samples "
                f"({self.blocks} blocks of {self.block}; {self.inflation:.3g}x the "
                "white-residual formula)")
        if self.lower_bound:
            line += ("; the logs span too few correlation times for a sure estimate: read them "
                     "as lower bounds")
        return line

    def as_dict(self) -> dict:
        return {"tau_int_samples": self.tau_int, "block": self.block, "blocks": self.blocks,
                "lower_bound": self.lower_bound, "inflation": self.inflation}


def integrated_time(r: np.ndarray) -> float:
    """Integrated autocorrelation time [samples] of a residual, 1 for white noise (Sokal's
    window: tau = 1 + 2 sum_{k=1..W} rho_k at the first W >= 5 tau)."""
    x = np.asarray(r, float)
    x = x[np.isfinite(x)]  # a copy: changed in place below
    n = len(x)
    if n:
        x -= x.mean()
    if n < 4 or not np.any(x):
        return 1.0
    nfft = 1 << int(2 * n - 1).bit_length()
    f = np.fft.rfft(x, nfft)
    del x
    if n < LEAN_SAMPLES:
        f = f * np.conj(f)
    else:  # a long residual: the power spectrum in place, a chunk at a time (bounded memory)
        for a in range(0, len(f), CHUNK_ROWS):
            f[a:a + CHUNK_ROWS] *= np.conj(f[a:a + CHUNK_ROWS])
    acf = np.fft.irfft(f, nfft)[:n]
    del f
    acf /= acf[0]
    tau = np.cumsum(acf)  # tau(W) = 1 + 2 sum_{k=1..W} rho_k
    tau *= 2.0
    tau -= 1.0
    w = np.arange(n)
    ok = w >= SOKAL_C * tau
    W = int(np.argmax(ok)) if ok.any() else n - 1
    return float(max(tau[W], 1.0))


def finite_residual(resid: np.ndarray) -> np.ndarray:
    """``resid`` with its non-finite values 0 (a copy only when it has any)."""
    r = np.asarray(resid, float)
    return r if np.isfinite(r).all() else np.where(np.isfinite(r), r, 0.0)


def correlation_time(resid: np.ndarray, segments) -> float:
    """Integrated autocorrelation time [samples] of a residual: the longest of its signal blocks'
    (``segments`` as :func:`block_covariance` takes them; non-finite values count as 0)."""
    r = finite_residual(resid)
    return max((integrated_time(r[a:b]) for _, a, b in segments), default=1.0)


def block_covariance(jac: np.ndarray, resid: np.ndarray, segments, white_cov: np.ndarray,
                     tau: float | None = None):
    """HAC covariance of the parameters by block sums (module docstring).

    ``jac``: (n, p) Jacobian of the residual vector with respect to the parameters, ``resid``:
    (n,) residual at the solution, ``segments``: one (log index, start, stop) per signal block
    of the residual vector, in the order of the vector (the rows ``start:stop`` are that
    signal's samples of that log, in time order). ``white_cov``: the textbook covariance, for
    the reported inflation. ``tau``: the residual's :func:`correlation_time` when the caller
    has it (a long fit takes it before its Jacobian exists: the FFT's buffers and an m x n
    matrix never live together). Returns ``(cov, CovarianceInfo)``; ``cov`` is ``white_cov``
    when the blocks are too few to estimate anything.
    """
    jac = np.asarray(jac, float)
    r = finite_residual(resid)
    logs: dict[int, list[tuple[int, int]]] = {}
    for k, a, b in segments:
        logs.setdefault(k, []).append((a, b))
    lengths = [min(b - a for a, b in parts) for parts in logs.values()]
    tau = correlation_time(r, segments) if tau is None else tau
    want = max(1, math.ceil(BLOCK_TAUS * tau))
    cap = max(1, min(lengths) // MIN_BLOCKS) if lengths else 1
    block = min(want, cap)
    short = want > cap or (min(lengths) < MIN_TAUS * tau if lengths else True)
    p = jac.shape[1]
    sums = []
    for parts in logs.values():
        m = min(b - a for a, b in parts) // block  # whole blocks of this log
        g = np.zeros((m, p))
        step = max(1, CHUNK_ROWS // block)  # whole blocks at a time: no n x p temporary
        for a, _ in parts:  # every signal of the log adds to the same time blocks
            for c in range(0, m, step):
                k = min(step, m - c)
                rows = slice(a + c * block, a + (c + k) * block)
                g[c:c + k] += (jac[rows] * r[rows, None]).reshape(k, block, p).sum(axis=1)
        sums.append(g)
    G = np.concatenate(sums) if sums else np.zeros((0, p))
    nb = len(G)
    if nb <= p + 1:
        return white_cov, CovarianceInfo(block, nb, tau, short, 1.0)
    G = G - G.mean(axis=0)
    S = G.T @ G * nb / (nb - 1)
    Hinv = information_inverse(jac.T @ jac)
    cov = Hinv @ S @ Hinv
    cov = 0.5 * (cov + cov.T)
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = standard_errors(cov) / np.sqrt(np.diag(white_cov))
    ratio = ratio[np.isfinite(ratio)]
    inflation = float(ratio.max()) if len(ratio) else 1.0
    return cov, CovarianceInfo(block, nb, tau, short, inflation)


def standard_errors(cov) -> np.ndarray:
    """Each parameter's standard error [its unit] from the covariance ``cov`` (n x n): the
    square root of a finite, positive variance; NaN where the variance is zero, negative or not
    finite: the data do not determine that parameter (a zero Jacobian column, a pseudo-inverse's
    dropped direction, a sum with a propagated part that is not positive semidefinite). Never 0,
    which would read as a parameter known exactly."""
    var = np.diag(np.asarray(cov, float))
    ok = np.isfinite(var) & (var > 0)
    return np.where(ok, np.sqrt(np.where(ok, var, 1.0)), math.nan)


def standard_error(var: float) -> float:
    """One quantity's standard error [its unit] from its variance ``var`` [unit^2] (a
    propagated ``g' cov g``, one diagonal entry): :func:`standard_errors`' rule for a scalar,
    the square root of a finite, positive variance, else NaN (not determined; never 0)."""
    return float(standard_errors(np.array([[var]], float))[0])


def white_covariance(jac: np.ndarray, resid: np.ndarray, dof: int | None = None) -> np.ndarray:
    """Textbook covariance ``(J'J)^+ s^2``, ``s^2 = sum(r^2) / dof`` (``dof`` default: rows minus
    columns, at least 1). Raises numpy's LinAlgError when J'J cannot be pseudo-inverted."""
    r = np.asarray(resid, float)
    dof = max(len(r) - jac.shape[1], 1) if dof is None else max(dof, 1)
    return information_inverse(jac.T @ jac) * float(r @ r) / dof


def information_inverse(H: np.ndarray) -> np.ndarray:
    """The pseudo-inverse of ``H = J'J`` taken with its rows and columns scaled to a unit
    diagonal (the Jacobian's columns to unit norm) and scaled back: the same matrix where
    ``H`` is well conditioned, and no direction dropped for its parameters' units alone. Taken
    as it stands, parameters of very different sizes (an input latency ~1e-3 s beside an
    inductance at its floor, 1e-13 H) gave ``H`` a condition number past the pseudo-inverse's
    cut-off, which dropped part of the latency's variance: 0.93 ms printed +- 1e-25 s, "4.6e+23
    standard errors" (bench/newrigs.py freerun-vmeas seed 20). A zero column keeps a zero
    variance (not determined: NaN in :func:`standard_errors`)."""
    H = np.asarray(H, float)
    diag = np.diag(H)
    norms = np.sqrt(np.where(np.isfinite(diag) & (diag > 0), diag, 0.0))
    d = np.where(norms > 0, 1.0 / np.where(norms > 0, norms, 1.0), 1.0)
    dd = np.outer(d, d)
    return np.linalg.pinv(H * dd) * dd


def correlated_covariance(jac: np.ndarray, resid: np.ndarray, segments):
    """``(cov, CovarianceInfo)``: the block sandwich (:func:`block_covariance`) started from the
    textbook covariance of ``jac`` and ``resid``."""
    return block_covariance(jac, resid, segments, white_covariance(jac, resid))


def parameter_covariance(jac, fun, nd, segments, redchi, correlated, weight=1.0, tau=None):
    """Parameter covariance of a simulation-error fit: the data rows' (the first ``nd`` rows of
    ``jac`` and ``fun``; white or correlated-residual sandwich), combined with the prior rows'
    information: ``(Hd + P)^-1 (Sd + w^2 P) (Hd + P)^-1`` where ``Sd`` is the data score's
    covariance (``Hd cov_d Hd``), ``P`` the (weighted) prior rows' precision and ``w`` their
    weight (the prior means' own variance, scaled like their rows); ``tau``: the data rows'
    :func:`correlation_time` when known. Returns ``(cov, info, curv)``, ``curv`` the data
    rows' ``Hd^-1`` (the cost's own curvature, inverted: the direction a profile follows).

    Computed with the Jacobian's columns scaled to unit norm (``jac`` is scaled in place) and
    scaled back (the same covariance): parameters of very different sizes (LuGre's sigma0 ~
    1e2 N m/rad beside bc ~ 1e-3 N m) would otherwise give J'J a condition number past the
    pseudo-inverse's cut-off, which then zeroes the small direction's variance."""
    norms = column_norms(jac)
    d = np.where(norms > 0, 1.0 / np.where(norms > 0, norms, 1.0), 1.0)
    jac *= d  # in place: the caller's matrix, not used after (no m x n copy on long logs)
    cov, info, curv = _scaled_covariance(jac, fun, nd, segments, redchi, correlated, weight,
                                         tau)
    return cov * np.outer(d, d), info, curv * np.outer(d, d)


def column_norms(J: np.ndarray) -> np.ndarray:
    """Euclidean norm of each column; on a tall matrix a block of rows at a time (no m x n
    square), which agrees with ``np.linalg.norm(J, axis=0)`` to rounding."""
    if len(J) < TALL_ROWS:
        return np.linalg.norm(J, axis=0)
    ss = np.zeros(J.shape[1])
    for a in range(0, len(J), BLOCK_ROWS):
        ss += np.einsum("ij,ij->j", J[a:a + BLOCK_ROWS], J[a:a + BLOCK_ROWS])
    return np.sqrt(ss)


def _scaled_covariance(Jm, fun, nd, segments, redchi, correlated, weight, tau):
    Jd = Jm[:nd]
    Hd = Jd.T @ Jd
    curv = np.linalg.pinv(Hd)
    cov = curv * redchi
    info = None
    if correlated:
        cov, info = block_covariance(Jd, fun[:nd], segments, cov, tau)
    if nd == len(fun):
        return cov, info, curv
    Jp = Jm[nd:]
    P = Jp.T @ Jp
    Sd = Hd @ cov @ Hd
    Hinv = np.linalg.pinv(Hd + P)
    return Hinv @ (Sd + weight**2 * P) @ Hinv, info, curv


def propagated(jac: np.ndarray, held_jac: np.ndarray, held_se: np.ndarray) -> np.ndarray:
    """The covariance the held parameters' own uncertainty adds to the fitted ones (a two-step
    estimator: the fitted values move by G = -(J'J)^-1 J'J_h per unit of the held ones, so
    cov += G diag(se_h^2) G')."""
    if held_jac.shape[1] == 0:
        return np.zeros((jac.shape[1], jac.shape[1]))
    g = -np.linalg.lstsq(jac, held_jac, rcond=None)[0]
    return (g * held_se**2) @ g.T


def envelope_jacobian(fun, z, f0, lo, hi, rel, parallel: bool = True) -> np.ndarray:
    """Central-difference Jacobian of ``fun`` at ``z`` with relative step ``rel`` (one for all or
    one per column; one-sided at a bound); columns that still come out zero fall back to a 5x
    wider step: the slope of the cost's smooth envelope, where the solver's forward differences
    may cross no switching event (a zero column, hence a zero standard error). With
    ``parallel`` the columns are shared with the spare CPUs (:func:`pmap`): ``fun`` must be safe
    to call from several threads; the same bits for any number of threads."""
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
            np.subtract(fu, fd, out=J[:, j])  # straight into the column: no temporary
            J[:, j] /= up - dn
            if np.any(J[:, j] != 0):
                break

    pmap(column, range(len(z)), parallel)
    return J


__all__ = ["CovarianceInfo", "block_covariance", "column_norms", "correlated_covariance",
           "correlation_time", "envelope_jacobian", "finite_residual", "information_inverse",
           "integrated_time", "parameter_covariance", "propagated", "white_covariance"]
