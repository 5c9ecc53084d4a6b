"""A lag between the command and the measured speed that changes along a log.

Host-paced logging (a PC or Simulink polling a microcontroller over USB or serial) stamps the
command and the speed on different clocks. When the board's sample clock runs slower than the
host's, or samples queue in a buffer flushed now and then, each speed sample arrives later after
the command that caused it than the one before: the lag grows by eps * t (eps, the clock-rate
mismatch, is dimensionless) and falls back when the buffer drops samples. A time-invariant model
holds one delay (``input_delay``, ``sensor_delay``): on such a log its error grows along the log,
no parameter removes it, and held-out logs of another length or phase of the sawtooth are
predicted with the lag their own time stamps happen to have. diagnose says so (a warning line)
rather than credit the lag to an effect.

Detection (:func:`lag_profile`), on each log with a measured speed: cut it into :data:`WINDOWS`
windows; in each window where the simulated speed moves (its variation about its own straight
line is above :data:`MIN_MOTION` times the measured speed's noise: a hold or a ramp says nothing
about a lag, only about a level), find the shift s (the simulation delayed by s, up to a quarter
window either way) that minimises the squared speed error. Then one shift for every window (what
a constant latency can do) against one per window: the lag varies along the log when the shifts
per window remove at least :data:`MIN_GAIN` of the squared error a constant shift leaves and
both their span and their straight-line trend from the first to the last window are at least
:data:`MIN_SPREAD` samples, leaving out the one window a constant shift fits worst (a single
transient the model misses, such as a breakaway from rest, is not a clock; nor are two windows
off in opposite directions, which move no trend). With a constant lag and white noise the
per-window shifts fit only the noise (a gain of about windows / samples, far below MIN_GAIN).
"""

from __future__ import annotations

import os
from dataclasses import dataclass

import numpy as np

from pmdcid.identify.latency import shift_curve

#: windows per log (scale-free: the same test on a 10 s and a 160 s log)
WINDOWS = 10
#: a window shorter than this has too few samples to place a lag [samples]
MIN_WINDOW = 200
#: a window informs on the lag when the simulated speed varies about its straight line by this
#: many times the measured speed's noise std
MIN_MOTION = 5.0
#: per-window shifts must remove this share of the squared error a constant shift leaves
MIN_GAIN = 0.2
#: ... and both span and drift (the trend across the windows) by this many samples (a constant
#: lag scatters by a sample or so)
MIN_SPREAD = 4
#: at least this many informative windows
MIN_INFORMATIVE = 3


@dataclass
class LagProfile:
    """Per-window lags of a measured speed behind its simulation."""

    times: np.ndarray  # window centres [s]
    lags: np.ndarray  # best shift per informative window [s]
    common: float  # one best shift for all of them [s]
    gain: float  # share of the constant shift's squared error the per-window shifts remove
    spread: float  # max - min of the window lags [s]
    slope: float  # least-squares trend of the lag against time [s/s]
    dt: float  # sample period [s]

    @property
    def varies(self) -> bool:
        drift = abs(self.slope) * (self.times[-1] - self.times[0]) if len(self.times) else 0.0
        return (len(self.lags) >= MIN_INFORMATIVE and self.gain >= MIN_GAIN
                and min(self.spread, drift) >= MIN_SPREAD * self.dt)


def _moves(sim: np.ndarray, noise: float) -> bool:
    x = np.arange(len(sim), dtype=float)
    resid = sim - np.polyval(np.polyfit(x, sim, 1), x)
    return float(np.std(resid)) > MIN_MOTION * noise


def lag_profile(t, sim, meas, noise: float) -> LagProfile | None:
    """The lag of ``meas`` behind ``sim`` (speeds [rad/s] on the time grid ``t`` [s]) window by
    window (module docstring); ``noise`` [rad/s] is the measured speed's white-noise std. None
    when the log is too short for :data:`WINDOWS` windows."""
    sim, meas = np.asarray(sim, float), np.asarray(meas, float)
    n = len(meas)
    width = n // WINDOWS
    if width < MIN_WINDOW or not (np.isfinite(sim).all() and np.isfinite(meas).all()):
        return None
    dt = float((t[-1] - t[0]) / (n - 1))
    kmax = width // 4
    padded = np.pad(sim, kmax, mode="edge")
    curves, centres = [], []
    for w in range(WINDOWS):
        a, b = w * width, (w + 1) * width
        if _moves(sim[a:b], max(noise, 1e-12)):
            curves.append(shift_curve(padded, meas, a, b, kmax))
            centres.append(float(t[(a + b) // 2]))
    if not curves:
        return LagProfile(np.array([]), np.array([]), 0.0, 0.0, 0.0, 0.0, dt)
    C, times = np.array(curves), np.array(centres)
    if len(C) > MIN_INFORMATIVE:  # one window off alone is one transient missed, not a clock
        common = int(np.argmin(np.sum(C, axis=0)))
        worst = int(np.argmax(C[:, common] - np.min(C, axis=1)))
        C, times = np.delete(C, worst, axis=0), np.delete(times, worst)
    shifts = np.arange(-kmax, kmax + 1) * dt
    own = np.argmin(C, axis=1)
    common = int(np.argmin(np.sum(C, axis=0)))
    const_sse = float(np.sum(C[:, common]))
    own_sse = float(np.sum(C[np.arange(len(C)), own]))
    lags = shifts[own]
    slope = float(np.polyfit(times, lags, 1)[0]) if len(lags) >= 2 else 0.0
    return LagProfile(times, lags, float(shifts[common]),
                      1.0 - own_sse / const_sse if const_sse > 0 else 0.0,
                      float(np.ptp(lags)), slope, dt)


def describe_lag(name: str, p: LagProfile) -> str:
    """One log's lag in words: its straight-line trend from the first to the last window."""
    line = np.polyfit(p.times, p.lags, 1) if len(p.lags) >= 2 else (0.0, p.common)
    first, last = (1e3 * float(np.polyval(line, x)) for x in (p.times[0], p.times[-1]))
    return (f"{name} {first:.0f} -> {last:.0f} ms (trend {1e3 * p.slope:+.2g} ms/s, windows "
            f"spanning {1e3 * p.spread:.0f} ms; a lag per window removes {100 * p.gain:.0f} % "
            "of the error one constant lag leaves)")


def timing_warning(problem, sims) -> str | None:
    """One line naming the logs whose speed lags the model by an amount that changes along
    the log (module docstring), or None."""
    from pmdcid.io.derive import noise_std

    seen = []
    for k, (log, sim) in enumerate(zip(problem.logs, sims, strict=True)):
        if problem.blocked[k] or not log.has("omega") or "omega" in log.derived:
            continue
        om = np.asarray(log["omega"], float)
        prof = lag_profile(log.t, sim.omega, om, noise_std(om))
        if prof is not None and prof.varies:
            seen.append(describe_lag(os.path.basename(str(log.path)), prof))
    if not seen:
        return None
    return ("the speed lags the model by an amount that changes along the log: "
            + "; ".join(seen) + ". The command's and the speed's time stamps drift apart "
            "(host-paced logging over USB or serial, a sample clock slower than the host's, "
            "samples queued and dropped): no time-invariant model (input_delay, sensor_delay) "
            "follows it, so held-out logs keep an error the model cannot remove; time-stamp "
            "command and speed on the same clock (on the board) and record again")


__all__ = ["LagProfile", "describe_lag", "lag_profile", "timing_warning"]
