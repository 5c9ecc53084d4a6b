"""Warnings about a drive whose output is not its command, from diagnose's final model and fit.

Some drive effects are not catalogue effects because the logs cannot pin them down or the
catalogue already holds their signature (docs/effects.md, "Real drives"); diagnose then says what
it saw and what to do, one line each (summary ``warnings``):

- a **slow PWM carrier** (or mains pick-up, a resonance): the measured speed ripples at a fixed
  frequency that neither the command nor the rotor's angle explains. The model sees the
  command's average; following the carrier would need its frequency, phase against the host's
  clock, the bus voltage and the bridge's decay mode, none of which a log holds;
- a **large drive drop**: the command loses a sizeable part before the motor turns (a lumped
  model's dead zone and friction in volts), or diagnose added ``brush_drop``: an H-bridge's
  bipolar drop v0 + r_d |i| and its dead time give the same constant drop in the direction of the
  current; r_d |i| sign(i) = r_d i is indistinguishable from R (with a current sensor) or from
  friction and viscous per volt (without one);
- a **sensor delay on logs without current**: an input applied late (a host-paced loop's
  latency) and outputs read late are the same thing on voltage and speed alone;
- a **lag that changes along a log** (:mod:`pmdcid.diagnose.timing`): the command's and the
  speed's time stamps drift apart, which no time-invariant delay follows.
"""

from __future__ import annotations

import math
import os

import numpy as np

from pmdcid.diagnose.shape import MIN_PERIODS, MIN_SHARE, _peak_share
from pmdcid.identify.identifiability import MAX_REL_STDERR

#: a carrier line is not the command's: the command has under this share of its variance there
INPUT_SHARE = 0.01
#: a line within this fraction of a whole number of revolutions per second is the angle's
ANGLE_TOL = 0.1
#: a command lost before the motor turns is worth a warning above this share of the largest one
DROP_SHARE = 0.1


def _line(x: np.ndarray, dt: float, lo: float) -> tuple[float, float]:
    """(frequency [Hz], share of var(x)) of the sharpest periodogram line of x above ``lo``."""
    return _peak_share(np.asarray(x, float), 1.0 / (len(x) * dt), lo)


def _band_share(x: np.ndarray, dt: float, f: float) -> float:
    """Share of var(x) within +-2 periodogram bins of frequency ``f`` [Hz]."""
    x = np.asarray(x, float) - np.mean(x)
    p = np.abs(np.fft.rfft(x)) ** 2
    tot = float(np.sum(p[1:]))
    if tot <= 0:
        return 0.0
    j = int(round(f * len(x) * dt))
    return float(np.sum(p[max(j - 2, 1): j + 3])) / tot


def _angle_locked(resid: np.ndarray, omega: np.ndarray, dt: float, f: float,
                  share: float) -> bool:
    """True when a line at ``f`` [Hz] is a whole number N of periods per revolution at the
    typical speed and at least as sharp in the rotor's angle as in time (N per revolution:
    cogging, an eccentric load; at a varying speed only such a line stays sharp in angle)."""
    fast = np.abs(omega) > 0.2 * np.percentile(np.abs(omega), 95)
    if fast.sum() < 64:
        return False
    per_rev = f / (float(np.median(np.abs(omega[fast]))) / (2 * math.pi))
    n = round(per_rev)
    if n < 1 or abs(per_rev - n) > ANGLE_TOL:
        return False
    revs = np.cumsum(np.abs(omega[fast])) * dt / (2 * math.pi)
    if revs[-1] - revs[0] < MIN_PERIODS / n:
        return False
    grid = np.linspace(revs[0], revs[-1], min(len(revs), 1 << 16))
    ra = np.interp(grid, revs, resid[fast])
    width = (grid[-1] - grid[0]) / (len(grid) - 1)
    return _band_share(ra, width, n) >= 0.8 * share


def carrier_line(t: np.ndarray, u: np.ndarray, omega: np.ndarray,
                 resid: np.ndarray) -> tuple[float, float] | None:
    """(frequency [Hz], amplitude [rad/s]) of a fixed-frequency speed ripple the model misses,
    or None. The line must hold at least :data:`MIN_SHARE` of the speed residual's variance and
    stand :data:`~pmdcid.diagnose.shape.PEAK_OVER_MEDIAN` times above the spectrum's median, be
    absent from the command, and not be a whole number of lines per revolution."""
    ok = np.isfinite(resid) & np.isfinite(omega)
    if ok.sum() < 64 or not ok.all():
        return None
    dt = float((t[-1] - t[0]) / (len(t) - 1))
    duration = len(t) * dt
    f, share = _line(resid, dt, MIN_PERIODS / duration)
    if share < MIN_SHARE or not math.isfinite(f) or f <= 0:
        return None
    if _band_share(u, dt, f) > INPUT_SHARE:
        return None
    if _angle_locked(resid, omega, dt, f, share):
        return None
    amp = math.sqrt(2.0 * share * float(np.var(resid)))
    return f, amp


def carrier_warning(problem, sims) -> str | None:
    """One line naming the logs whose speed ripples at a carrier-like frequency."""
    seen = []
    for k, (log, sim) in enumerate(zip(problem.logs, sims, strict=True)):
        if problem.blocked[k] or not log.has("omega") or "omega" in log.derived:
            continue
        om = log["omega"]
        hit = carrier_line(log.t, log.u, om, om - sim.omega)
        if hit is not None:
            seen.append(f"{os.path.basename(log.path)} {hit[0]:.3g} Hz (±{hit[1]:.2g} rad/s)")
    if not seen:
        return None
    return ("the speed ripples at a fixed frequency the command does not have: "
            + ", ".join(seen) + ": a PWM carrier this slow (or mains pick-up, a resonance) "
            "shows in the speed, and the model, which sees the command's average, cannot follow "
            "it; raise the PWM frequency well above the motor's bandwidth (kHz) and record "
            "again, or leave these logs out of the fit")


def command_lost(vals: dict[str, float], umax: float) -> float:
    """Smallest command [V on a per-volt model] that turns the rotor in steady state: the dead
    zone's output must exceed the static friction bc + fs (slope and offset of the dead zone)."""
    from pmdcid.simulate import param_vector
    from pmdcid.simulate.terms import dead_zone, static_friction

    p = param_vector(vals)
    grid = np.linspace(0.0, umax, 2001)
    fstat = static_friction(p)
    moving = [u for u in grid if dead_zone(p, float(u)) > fstat]
    return float(moving[0]) if moving else umax


def dead_zone_low(model) -> float | None:
    """The low end [model units] of a dead zone ``model`` does not determine: its interval's,
    or, where it is poorly determined (the fit stages' rule,
    :data:`pmdcid.identify.identifiability.MAX_REL_STDERR` of the Coulomb friction), its value
    less two standard errors (at least 0); None where it is determined (or absent, or no
    model)."""
    par = model.parameters.get("dz") if model is not None else None
    if par is None:
        return None
    if par.interval is not None:
        return float(par.interval[0])
    bc = model.parameters.get("bc")
    level = abs(bc.value) if bc is not None else abs(par.value)
    se = par.stderr
    if se is not None and math.isfinite(se) and se > MAX_REL_STDERR * level:
        return max(par.value - 2.0 * se, 0.0)
    return None


def drop_warning(problem, vals: dict[str, float], added: list[str],
                 model=None) -> str | None:
    """One line when the drive visibly loses part of its command (see the module's text).
    Where ``model``'s dead zone is not determined (:func:`dead_zone_low`) the loss is said
    from its low end, with the fitted value's as the upper: guanlunlu-l298n's steps (6, 12,
    24 V) move at every level and leave the breakaway anywhere from the running friction's
    2.4 V to 5 V; a model of them with a lag (session 33's trial, docs/identification.md)
    held dz = 5.1 ± 4.4 V, and the warning read 3.65 V as if known."""
    lumped = any(log.meta.get("lumped") == "true" for log in problem.logs)
    if "brush_drop" in added and not lumped:
        return (f"brush_drop vb = {vals['vb']:.3g} V: an H-bridge's bipolar drop (an L298N "
                "loses 1.5-2.5 V) or its dead time gives the same constant drop, and its "
                f"current-dependent part is inside R = {vals['R']:.3g} Ω (the motor's and the "
                "drive's): compare R with the motor's resistance measured at its terminals, or "
                "log the terminal voltage, to tell the motor from the drive")
    if not lumped:
        return None
    umax = max(float(np.max(np.abs(log.u))) for log in problem.logs)
    lost = command_lost(vals, umax)
    low = dead_zone_low(model)
    least = lost if low is None else min(command_lost({**vals, "dz": low}, umax), lost)
    if umax <= 0 or least < DROP_SHARE * umax:
        return None
    upto = (f" or more (up to {lost:.3g} V: these logs do not determine the dead zone)"
            if least < 0.99 * lost else "")
    return (f"the command loses {least:.3g} V{upto} ({100 * least / umax:.0f} % of the "
            "largest) before the motor turns: a drive drop (an L298N loses 1.5-2.5 V, more "
            "with current), dead time, brush drop and friction all sit in this per-volt dead "
            "zone and Coulomb friction, and without current they cannot be told apart, so the "
            "model holds at the loads logged; log the current to separate them (the drive's "
            "drop becomes brush_drop, its current-dependent part R)")


#: a sensor delay within this share of a sample period of half that period is said to be a
#: speed counted over each period (its mean, late by half the period)
HALF_SAMPLE_SHARE = 0.15


def latency_warning(problem, vals: dict[str, float], added: list[str]) -> str | None:
    """A sensor delay found without a current: it may be the input applied late."""
    if "sensor_delay" not in added or problem.measures("i"):
        return None
    delay = vals["delay"]
    line = (f"sensor_delay = {1e3 * delay:.3g} ms with no current logged: a command "
            "applied late (a host-paced loop's latency over USB or serial) looks the same on "
            "voltage and speed; log the current to tell them apart (input_delay)")
    dt = float(np.median(np.concatenate([np.diff(log.t) for log in problem.logs])))
    if abs(delay - 0.5 * dt) <= HALF_SAMPLE_SHARE * dt:
        line += (f". It is about half a sample period ({1e3 * dt:.3g} ms): a speed counted over "
                 "each period (encoder counts per period, divided by it) is the period's mean, "
                 "late by half of it; that is what a sensor delay is for")
    return line


def drive_warnings(problem, sims, vals: dict[str, float], added: list[str],
                   model=None) -> list[str]:
    """Every drive warning that applies (summary ``warnings``); ``model``: the final model
    (its standard errors)."""
    from pmdcid.diagnose.timing import timing_warning

    out = [carrier_warning(problem, sims), drop_warning(problem, vals, added, model),
           latency_warning(problem, vals, added), timing_warning(problem, sims)]
    return [w for w in out if w]


__all__ = ["carrier_line", "command_lost", "drive_warnings"]
