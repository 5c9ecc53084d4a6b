"""A constant latency between command and speed, from voltage-and-speed step logs.

On a lumped (per-volt) model there is no electrical lag: the torque follows the command at once,
and a rotor at rest starts as soon as the command exceeds its dead zone and static friction. Any
time between a step of the command and the speed's first move is then latency: the command
applied late by a host-paced loop (USB or serial), or the speed read late (a counting window, a
filter). On voltage and speed alone the two are one thing (docs/effects.md, "Real drives"), which
``sensor_delay`` holds. fit-mechanical's curve fits time a dead time per step, but their dead
time also absorbs the curve's misfit (on exact friction logs without latency it is 0-3 ms), so
the latency is measured with the kernel instead (:func:`step_latency`): the fitted model is
simulated on each step log and delayed by the shift that minimises the squared speed error over
every log together (one FFT correlation per log, refined between samples by a parabola). A shift
of under :data:`MIN_SAMPLES` samples is not kept: the zero-order hold and a speed counted over
the last sample period already offset the speed by half a sample each.
"""

from __future__ import annotations

import math

import numpy as np

#: a latency shorter than this many sample periods is not kept (see the module docstring)
MIN_SAMPLES = 2


def shift_curve(padded: np.ndarray, meas: np.ndarray, a: int, b: int, kmax: int) -> np.ndarray:
    """Mean squared error of a simulation delayed by k samples against ``meas[a:b]``, for k =
    -kmax..kmax; ``padded`` is the simulation with kmax edge samples added at each end (the
    rotor held its first and last state outside the log). One FFT correlation."""
    from pmdcid.identify.filters import correlate_valid

    seg = padded[a:b + 2 * kmax]
    w = meas[a:b]
    cross = correlate_valid(seg, w)[::-1]  # index k + kmax
    c2 = np.concatenate(([0.0], np.cumsum(seg * seg)))
    width = b - a
    starts = np.arange(2 * kmax, -1, -1)  # delay k reads seg[kmax - k : kmax - k + width]
    ss = c2[starts + width] - c2[starts]
    return (ss - 2.0 * cross + float(np.dot(w, w))) / width


def parabola_min(curve: np.ndarray, j: int) -> float:
    """The minimum's position between samples: a parabola through curve[j-1..j+1] [index]."""
    if j <= 0 or j >= len(curve) - 1:
        return float(j)
    a, b, c = curve[j - 1], curve[j], curve[j + 1]
    den = a - 2.0 * b + c
    return float(j) + (0.5 * (a - c) / den if den > 0 else 0.0)


def step_latency(logs, model) -> tuple[float, float] | None:
    """(latency [s], its white-noise standard error [s]) of the measured speed behind
    ``model`` simulated on ``logs`` (module docstring), including a ``sensor_delay`` the model
    already has; None when it is under :data:`MIN_SAMPLES` samples or no log measures a speed."""
    from pmdcid.simulate import input_is_torque, param_values, simulate_values
    from pmdcid.simulate.initial import initial_state

    use = [lg for lg in logs if lg.has("omega") and "omega" not in lg.derived and lg.n > 20]
    if not use:
        return None
    dt = use[0].dt
    use = [lg for lg in use if abs(lg.dt - dt) <= 1e-6 * dt]
    base = 0.0
    if "sensor_delay" in model.effects and "delay" in model.parameters:
        base = float(model.parameters["delay"].value)
    kmax = max(2, min(lg.n for lg in use) // 50)
    total, nsamp = np.zeros(2 * kmax + 1), 0
    for lg in use:
        torque = input_is_torque(lg, model)
        vals = param_values(model, torque)
        sim = simulate_values(lg.t, lg.u, vals, torque, x0=initial_state(lg)).omega
        meas = np.asarray(lg["omega"], float)
        if not (np.isfinite(sim).all() and np.isfinite(meas).all()):
            continue
        total += lg.n * shift_curve(np.pad(sim, kmax, mode="edge"), meas, 0, lg.n, kmax)
        nsamp += lg.n
    if nsamp == 0:
        return None
    j = int(np.argmin(total))
    k = parabola_min(total, j) - kmax
    latency = base + k * dt
    if latency < MIN_SAMPLES * dt:
        return None
    curv = (total[j - 1] - 2 * total[j] + total[j + 1]) if 0 < j < len(total) - 1 else 0.0
    sigma2 = float(total[j]) / max(nsamp - 1, 1)
    se = math.sqrt(2.0 * sigma2 / curv) * dt if curv > 0 else math.nan
    return latency, se


__all__ = ["MIN_SAMPLES", "parabola_min", "shift_curve", "step_latency"]
