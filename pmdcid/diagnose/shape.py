"""What an unexplained residual looks like, in physical terms: where to look next.

When structure remains that no catalogue effect explains, the speed residual (measured −
simulated) of the moving logs is tested for five shapes, each with the share of the residual's
variance it accounts for:

- it depends on the speed (``r·sign(ω)`` against ``|ω|``): the friction curve differs from the
  model's (friction flattening or rising with speed);
- it depends on the input (``r·sign(u)`` against ``|u|``): the drive's output is not its command
  (an H-bridge drop that depends on the current, a limit);
- it is periodic in the angle at N per revolution: cogging or an eccentric load;
- it holds a fixed frequency in time: the drive's PWM carrier, mains pick-up or a resonance;
- the repeats of one protocol differ from one another about as much as the model misses: the
  rig does not repeat (warm-up, a load that moves), no time-invariant model can do better.
"""

from __future__ import annotations

import math

import numpy as np

#: a shape is named when it accounts for at least this share of the residual's variance
MIN_SHARE = 0.15
#: quantile bins of the speed or input
BINS = 8
#: the repeats explain the residual when the floor is at least this share of the model's error
REPEAT_SHARE = 0.5
#: a fixed frequency needs this many periods in the log, and a peak this many times the median
#: power of the spectrum (a transient's smooth spectrum has no such peak)
MIN_PERIODS = 10
PEAK_OVER_MEDIAN = 50.0


def _binned_share(r: np.ndarray, x: np.ndarray) -> tuple[float, float, float, float]:
    """(share of var(r) explained by the means of r in quantile bins of x, correlation of the
    bin means with the bin centres, lowest and highest bin mean)."""
    ok = np.isfinite(r) & np.isfinite(x)
    r, x = r[ok], x[ok]
    if len(r) < 10 * BINS or np.ptp(x) <= 0:
        return 0.0, 0.0, 0.0, 0.0
    edges = np.unique(np.quantile(x, np.linspace(0, 1, BINS + 1)))
    if len(edges) < 3:
        return 0.0, 0.0, 0.0, 0.0
    b = np.clip(np.searchsorted(edges, x, side="right") - 1, 0, len(edges) - 2)
    cnt = np.bincount(b, minlength=len(edges) - 1)
    use = cnt > 0
    means = np.bincount(b, weights=r, minlength=len(edges) - 1)[use] / cnt[use]
    centres = np.bincount(b, weights=x, minlength=len(edges) - 1)[use] / cnt[use]
    tot = float(np.sum((r - r.mean()) ** 2))
    expl = float(np.sum(cnt[use] * (means - r.mean()) ** 2))
    rho = float(np.corrcoef(centres, means)[0, 1]) if len(means) > 2 and np.std(means) > 0 else 0.0
    return (expl / tot if tot > 0 else 0.0), rho, float(means.min()), float(means.max())


def _speed_shape(r, w, unit: str = "rad/s") -> dict | None:
    share, rho, lo, hi = _binned_share(r * np.sign(w), np.abs(w))
    if share < MIN_SHARE:
        return None
    trend = "grows with |ω|" if rho > 0.5 else "falls with |ω|" if rho < -0.5 else \
        "varies with |ω|"
    return {"shape": "speed", "share": share,
            "description": f"the speed error {trend} ({100 * share:.0f} % of the residual; "
                           f"r·sign(ω) from {lo:.3g} to {hi:.3g} {unit} across the speeds): "
                           "the friction curve differs from the model's (e.g. friction "
                           "flattening or rising with speed)"}


def _input_shape(r, u, unit: str) -> dict | None:
    share, rho, lo, hi = _binned_share(r * np.sign(u), np.abs(u))
    if share < MIN_SHARE or abs(rho) < 0.5:
        return None
    trend = "grows" if rho > 0 else "falls"
    return {"shape": "input", "share": share,
            "description": f"the speed error {trend} with |{unit}| ({100 * share:.0f} % of the "
                           f"residual; r·sign({unit}) from {lo:.3g} to {hi:.3g}): the drive's "
                           "output is not its command (a current-dependent H-bridge drop, a "
                           "limit, dead time)"}


def _peak_share(r: np.ndarray, df: float, lo: float) -> tuple[float, float]:
    """(frequency of the highest periodogram peak above ``lo``, share of the variance within
    +-2 bins of it); frequencies in units of 1/``df``'s reciprocal grid."""
    r = r - np.mean(r)
    p = np.abs(np.fft.rfft(r)) ** 2
    f = np.arange(len(p)) * df
    tot = float(np.sum(p[1:]))
    use = f > lo
    if tot <= 0 or not use.any():
        return math.nan, 0.0
    j = int(np.argmax(np.where(use, p, -1.0)))
    if p[j] < PEAK_OVER_MEDIAN * float(np.median(p[use])):
        return float(f[j]), 0.0
    band = float(np.sum(p[max(j - 2, 1): j + 3]))
    return float(f[j]), band / tot


def _time_shape(r: np.ndarray, dt: float, duration: float) -> dict | None:
    f, share = _peak_share(r, 1.0 / (len(r) * dt), MIN_PERIODS / duration)
    if share < MIN_SHARE:
        return None
    return {"shape": "frequency", "share": share, "frequency_hz": f,
            "description": f"a fixed frequency of {f:.3g} Hz in time ({100 * share:.0f} % of "
                           "the residual): the drive's PWM carrier, mains pick-up or a "
                           "mechanical resonance"}


def _angle_shape(r: np.ndarray, w: np.ndarray, dt: float) -> dict | None:
    fast = np.abs(w) > 0.2 * np.percentile(np.abs(w), 95)
    if fast.sum() < 200:
        return None
    s = np.cumsum(np.abs(w[fast])) * dt / (2 * math.pi)  # revolutions travelled
    if s[-1] - s[0] < 5:
        return None
    n = min(len(s), 1 << 16)
    grid = np.linspace(s[0], s[-1], n)
    rg = np.interp(grid, s, r[fast])
    per_rev, share = _peak_share(rg, 1.0 / (grid[-1] - grid[0]), 0.5)
    if share < MIN_SHARE or not math.isfinite(per_rev) or abs(per_rev - round(per_rev)) > 0.1:
        return None
    return {"shape": "angle", "share": share, "per_revolution": int(round(per_rev)),
            "description": f"periodic in the angle at {round(per_rev)} per revolution "
                           f"({100 * share:.0f} % of the residual): cogging or an eccentric "
                           "load"}


def residual_shapes(problem, sims, floor: float | None = None,
                    model_error: float | None = None) -> list[dict]:
    """The shapes the speed residual of ``problem``'s moving logs shows (each at most once,
    the log where it is strongest), largest share first."""
    found: dict[str, dict] = {}
    for ch in problem.channels:
        if ch.signal != "omega" or problem.blocked[ch.log]:
            continue
        log = problem.logs[ch.log]
        r = ch.meas - problem.simulated(sims, ch)
        w = ch.meas
        dt = log.dt * (ch.rows.step if len(ch.meas) > 1 else 1)
        unit = "τ" if log.drive == "tau" else "v"
        for item in (_speed_shape(r, w), _input_shape(r, np.asarray(log.u)[ch.rows], unit),
                     _time_shape(r, dt, log.duration), _angle_shape(r, w, dt)):
            if item is None:
                continue
            item = {**item, "log": log.path}
            if item["shape"] not in found or item["share"] > found[item["shape"]]["share"]:
                found[item["shape"]] = item
    out = sorted(found.values(), key=lambda x: -x["share"])
    if floor is not None and model_error and floor >= REPEAT_SHARE * model_error:
        out.insert(0, {"shape": "repeats", "share": floor / model_error,
                       "description": f"the repeats of a protocol differ by {floor:.3g} (speed "
                                      f"NRMSE, each run against the mean of the others) where "
                                      f"the model misses by {model_error:.3g}: the rig does not "
                                      "repeat itself, no time-invariant model does better"})
    return out


__all__ = ["residual_shapes"]
