"""Error metrics of a simulated model against a measured log (plain numbers, JSON-ready).

Definitions (every one is reported in ``metrics.json``):

- ``nrmse`` = RMS(sim - meas) / std(meas) (docs/report.md; the same as MATLAB ``compare``'s
  NRMSE cost) and ``fit_percent`` = 100 (1 - nrmse), MATLAB ``compare``'s fit; both null,
  and ``nrmse_undefined`` says why in words, for a measurement that never changes (std 0).
- ``rms``, ``max_abs`` [unit of the signal]: RMS and largest absolute error.
- Regimes: ``low_speed`` holds the samples where |omega_meas| < ``omega_threshold``
  = :data:`LOW_SPEED_FRACTION` x max |omega_meas| (near zero speed, where stick-slip and the dead
  zone act); ``high_speed`` the rest. Per regime: ``n``, ``fraction`` of samples, ``rms``,
  ``max_abs`` and ``nrmse`` (regime RMS error over the std of the WHOLE measurement, so the two
  regimes compare with each other and with the overall figure).
- Residual analysis as MATLAB ``resid``: the normalised autocorrelation of the residual
  r_ee(k)/r_ee(0), k = 0..M, and the cross-correlation of the input with the residual
  r_ue(k)/sqrt(r_uu(0) r_ee(0)), k = -M..M, with 99 % confidence bands. The autocorrelation band
  is +-z/sqrt(N) (white residual); the cross-correlation band is +-z sqrt(sum_j rho_uu(j)
  rho_ee(j) / N) (Bartlett: residual independent of the input, both possibly coloured; j up to
  N/4, at most 2^17). Lags are taken in steps of ``lag_step`` samples so that the M lags span
  about two mechanical time constants J/bv of the model (electrical L/R for a blocked rotor);
  ``lags`` are in samples: multiply by the log's dt.
"""

from __future__ import annotations

import math

import numpy as np

#: near-zero-speed regime: |omega| below this fraction of the log's largest |omega|
LOW_SPEED_FRACTION = 0.05
#: number of lags shown by the residual analysis (MATLAB resid's default)
MAX_LAG = 25
#: two-sided 99 % normal quantile
Z99 = 2.5758293035489004


def _f(x) -> float | None:
    """A JSON-safe float (None for NaN/inf)."""
    x = float(x)
    return x if math.isfinite(x) else None


def error_stats(err: np.ndarray, meas_std: float) -> dict:
    """RMS [unit], max |error| [unit] and RMS/std(meas) of an error array."""
    if len(err) == 0:
        return {"n": 0, "rms": None, "max_abs": None, "nrmse": None}
    rms = float(np.sqrt(np.mean(err**2)))
    return {"n": int(len(err)), "rms": _f(rms), "max_abs": _f(np.max(np.abs(err))),
            "nrmse": _f(rms / meas_std) if meas_std > 0 else None}


def speed_threshold(omega_meas: np.ndarray, fraction: float = LOW_SPEED_FRACTION) -> float:
    """Near-zero-speed threshold [rad/s]: ``fraction`` x max |omega_meas|."""
    return fraction * float(np.max(np.abs(omega_meas))) if len(omega_meas) else 0.0


#: lags of the Bartlett sum of the cross-correlation band: n/4, at most this many samples
BARTLETT_MAX_LAG = 1 << 17
#: block length of the blockwise (overlap-save) correlation: bounds memory on long logs
BLOCK = 1 << 17


def _cov_lags(a: np.ndarray, b: np.ndarray, nlag: int) -> np.ndarray:
    """sum_t a(t) b(t+k) / N for k = 0..nlag-1 (a, b mean-removed, same length N).

    Blockwise FFT (overlap-save), so memory stays O(BLOCK + nlag) on a long log.
    """
    n = len(a)
    out = np.zeros(nlag)
    blk = max(BLOCK, nlag)
    for s0 in range(0, n, blk):
        ab = a[s0:s0 + blk]
        bb = b[s0:s0 + blk + nlag]
        nfft = 1 << int(math.ceil(math.log2(len(ab) + len(bb))))
        c = np.fft.irfft(np.conj(np.fft.rfft(ab, nfft)) * np.fft.rfft(bb, nfft), nfft)
        m = min(nlag, len(bb))  # beyond len(bb) the true sum is 0 and c[k] holds wrap-around
        out[:m] += c[:m]
    return out / n


def residual_correlations(e: np.ndarray, u: np.ndarray, lag_step: int = 1,
                          max_lag: int = MAX_LAG, z: float = Z99) -> dict:
    """MATLAB ``resid``-style correlations of residual ``e`` and input ``u`` (see module doc)."""
    n = len(e)
    lag_step = max(1, min(int(lag_step), (n - 1) // 2))
    max_lag = max(1, min(max_lag, (n - 1) // (2 * lag_step)))
    k = np.arange(max_lag + 1) * lag_step
    full = min(n, max(min(n // 4, BARTLETT_MAX_LAG), int(k[-1]) + 1))
    e = np.asarray(e, float) - np.mean(e)
    u = np.asarray(u, float) - np.mean(u)
    ree = _cov_lags(e, e, full)
    ruu = _cov_lags(u, u, full)
    auto = ree[k] / ree[0] if ree[0] > 0 else np.full(len(k), np.nan)
    kx = np.arange(-max_lag, max_lag + 1) * lag_step
    if ree[0] > 0 and ruu[0] > 0:
        pos = _cov_lags(u, e, int(k[-1]) + 1)  # sum u(t) e(t+k)
        neg = _cov_lags(e, u, int(k[-1]) + 1)  # sum u(t) e(t-k)
        cxy = np.where(kx >= 0, pos[np.abs(kx)], neg[np.abs(kx)])
        cross = cxy / math.sqrt(ree[0] * ruu[0])
        rho = (ree / ree[0]) * (ruu / ruu[0])
        var = max((rho[0] + 2.0 * rho[1:].sum()) / n, 1.0 / n)
        xband = z * math.sqrt(var)
    else:
        cross = np.full(len(kx), np.nan)
        xband = math.nan
    aband = z / math.sqrt(n)
    return {
        "lag_step": lag_step,
        "auto": {"lags": k.tolist(), "r": [_f(v) for v in auto], "band": _f(aband),
                 "outside": int(np.sum(np.abs(auto[1:]) > aband))},
        "cross": {"lags": kx.tolist(), "r": [_f(v) for v in cross], "band": _f(xband),
                  "outside": int(np.sum(np.abs(cross) > xband)) if math.isfinite(xband) else 0},
    }


def lag_step_for(model_vals: dict, dt: float, max_lag: int = MAX_LAG,
                 electrical: bool = False) -> int:
    """Lag step [samples] so that ``max_lag`` lags span about two time constants of the model:
    mechanical J/bv, or electrical L/R when ``electrical`` (a blocked rotor); at least 1."""
    a, b = ("L", "R") if electrical else ("J", "bv")
    num, den = model_vals.get(a, math.nan), model_vals.get(b, math.nan)
    if not (math.isfinite(num) and math.isfinite(den) and num > 0 and den > 0):
        return 1
    return max(1, int(round(2.0 * num / den / max_lag / dt)))


def signal_metrics(sim: np.ndarray, meas: np.ndarray, u: np.ndarray, low: np.ndarray | None,
                   lag_step: int = 1) -> dict:
    """Every number for one signal of one log (see module doc); ``low`` marks near-zero speed."""
    err = sim - meas
    sd = float(np.std(meas))
    err_rms = float(np.sqrt(np.mean(err**2)))
    nr = err_rms / sd if sd > 0 else math.nan
    out = {
        "nrmse": _f(nr),
        "fit_percent": _f(100.0 * (1.0 - nr)),
        "rms": _f(err_rms),
        "max_abs": _f(np.max(np.abs(err))),
        "meas_std": _f(sd),
    }
    if not sd > 0:  # JSON has no inf: null, and why in words
        out["nrmse_undefined"] = ("the measurement never changes (std 0): NRMSE and fit are "
                                  "undefined; rms and max_abs give the error")
    if low is not None:
        for name, mask in (("low_speed", low), ("high_speed", ~low)):
            st = error_stats(err[mask], sd)
            st["fraction"] = _f(mask.mean())
            out[name] = st
    out["resid"] = residual_correlations(err, u, lag_step)
    return out
