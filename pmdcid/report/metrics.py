"""Error metrics of a simulated model against a measured log (plain numbers, JSON-ready).

Definitions (every one is reported in ``metrics.json``):

- ``nrmse`` = RMS(sim - meas) / std(meas) (CONTRACT.md; the same as MATLAB ``compare``'s
  NRMSE cost) and ``fit_percent`` = 100 (1 - nrmse), MATLAB ``compare``'s fit.
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
  rho_ee(j) / N) (Bartlett: residual independent of the input, both possibly coloured). Lags are
  taken in steps of ``lag_step`` samples so that the M lags span about two mechanical time
  constants J/bv of the model (``lag_s`` gives them in seconds).
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


def nrmse(sim: np.ndarray, meas: np.ndarray) -> float:
    """RMS error / std of the measurement (NaN when the measurement is constant)."""
    sd = float(np.std(meas))
    return float(np.sqrt(np.mean((sim - meas) ** 2))) / sd if sd > 0 else math.nan


def speed_threshold(omega_meas: np.ndarray, fraction: float = LOW_SPEED_FRACTION) -> float:
    """Near-zero-speed threshold [rad/s]: ``fraction`` x max |omega_meas|."""
    return fraction * float(np.max(np.abs(omega_meas))) if len(omega_meas) else 0.0


def _acov(x: np.ndarray, nlag: int) -> np.ndarray:
    """Biased autocovariance of ``x`` (mean removed) at lags 0..nlag-1, by FFT."""
    n = len(x)
    nfft = 1 << int(math.ceil(math.log2(2 * n)))
    fx = np.fft.rfft(x - x.mean(), nfft)
    return np.fft.irfft(fx * np.conj(fx), nfft)[:nlag] / n


def _xcov(u: np.ndarray, e: np.ndarray, lags: np.ndarray) -> np.ndarray:
    """Biased cross-covariance sum_t u(t) e(t+k) / N at the given (signed) lags, by FFT."""
    n = len(u)
    nfft = 1 << int(math.ceil(math.log2(2 * n)))
    fu = np.fft.rfft(u - u.mean(), nfft)
    fe = np.fft.rfft(e - e.mean(), nfft)
    c = np.fft.irfft(np.conj(fu) * fe, nfft) / n  # c[k] = sum u(t) e(t+k), negative k wrap
    return c[lags % nfft]


def residual_correlations(e: np.ndarray, u: np.ndarray, lag_step: int = 1,
                          max_lag: int = MAX_LAG, z: float = Z99) -> dict:
    """MATLAB ``resid``-style correlations of residual ``e`` and input ``u`` (see module doc)."""
    n = len(e)
    lag_step = max(1, int(lag_step))
    max_lag = max(1, min(max_lag, (n - 1) // (2 * lag_step)))
    k = np.arange(max_lag + 1) * lag_step
    full = min(n, max(n // 4, int(k[-1]) + 1))
    ree = _acov(e, full)
    ruu = _acov(u, full)
    auto = ree[k] / ree[0] if ree[0] > 0 else np.full(len(k), np.nan)
    kx = np.arange(-max_lag, max_lag + 1) * lag_step
    if ree[0] > 0 and ruu[0] > 0:
        cross = _xcov(u, e, kx) / math.sqrt(ree[0] * ruu[0])
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


def lag_step_for(model_vals: dict, dt: float, max_lag: int = MAX_LAG) -> int:
    """Lag step [samples] so that ``max_lag`` lags span about 2 J/bv (at least 1 sample)."""
    j = model_vals.get("J", math.nan)
    bv = model_vals.get("bv", math.nan)
    if not (math.isfinite(j) and math.isfinite(bv) and bv > 0 and j > 0):
        return 1
    return max(1, int(round(2.0 * j / bv / max_lag / dt)))


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
    if low is not None:
        for name, mask in (("low_speed", low), ("high_speed", ~low)):
            st = error_stats(err[mask], sd)
            st["fraction"] = _f(mask.mean())
            out[name] = st
    out["resid"] = residual_correlations(err, u, lag_step)
    return out
