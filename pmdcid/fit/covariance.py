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
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: fewest blocks per log (a variance from fewer blocks is too noisy to use)
MIN_BLOCKS = 10
#: block length in integrated autocorrelation times (longer: less bias, fewer blocks)
BLOCK_TAUS = 4.0
#: a log shorter than this many correlation times gives standard errors biased low (Monte Carlo
#: of fit-nonlinear: ~0.5x the true spread at 50, 0.8-1.1x at 150, tests/test_covariance.py)
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


def block_covariance(jac: np.ndarray, resid: np.ndarray, segments, white_cov: np.ndarray):
    """HAC covariance of the parameters by block sums (module docstring).

    ``jac``: (n, p) Jacobian of the residual vector with respect to the parameters, ``resid``:
    (n,) residual at the solution, ``segments``: one (log index, start, stop) per signal block
    of the residual vector, in the order of the vector (the rows ``start:stop`` are that
    signal's samples of that log, in time order). ``white_cov``: the textbook covariance, for
    the reported inflation. Returns ``(cov, CovarianceInfo)``; ``cov`` is ``white_cov`` when
    the blocks are too few to estimate anything.
    """
    jac = np.asarray(jac, float)
    r = np.where(np.isfinite(resid), resid, 0.0)
    logs: dict[int, list[tuple[int, int]]] = {}
    for k, a, b in segments:
        logs.setdefault(k, []).append((a, b))
    taus, lengths = [], []
    for parts in logs.values():
        lengths.append(min(b - a for a, b in parts))
        taus.extend(integrated_time(r[a:b]) for a, b in parts)
    tau = max(taus) if taus else 1.0
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
    Hinv = np.linalg.pinv(jac.T @ jac)
    cov = Hinv @ S @ Hinv
    cov = 0.5 * (cov + cov.T)
    with np.errstate(invalid="ignore", divide="ignore"):
        ratio = np.sqrt(np.clip(np.diag(cov), 0, None) / np.diag(white_cov))
    ratio = ratio[np.isfinite(ratio)]
    inflation = float(ratio.max()) if len(ratio) else 1.0
    return cov, CovarianceInfo(block, nb, tau, short, inflation)
