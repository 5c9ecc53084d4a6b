"""The closed loop: a motor model under a known digital controller, from the logged reference.

Each controller period the controller (:mod:`pmdcid.simulate.controller`) reads the simulated
measurement (sensor effects applied: ``speed_offset``, ``sensor_delay`` read from the states
already simulated) against the reference, and its output is held over the period while the one
kernel (:func:`pmdcid.simulate.kernel.run_kernel`'s compiled loop, unchanged) steps the motor
through it. No second integrator: the kernel is called once per period with the input held.

Times may be non-uniform (a loop-timed log: one row per controller step, 2–13 ms apart): each
period is stepped with its own length (its discretisation cached by length). A ``period`` that
is not a whole number of log samples (a 1 kHz loop logged by a slower task) runs the controller
on its own clock, ticking between the samples (:func:`_run_own_clock`).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass

import numpy as np

from pmdcid.errors import LogError, ModelError
from pmdcid.simulate import SimResult, param_vector
from pmdcid.simulate.controller import ControllerSpec, ControllerState
from pmdcid.simulate.initial import settled_start
from pmdcid.simulate.kernel import _compiled, discretize_cached
from pmdcid.simulate.layout import I_STATE, NSTATE, OMEGA_STATE, THETA_STATE, state_vector
from pmdcid.simulate.sensors import apply_sensors
from pmdcid.simulate.substeps import check_work, choose_substeps


@dataclass
class ClosedLoopResult(SimResult):
    """:class:`SimResult` plus ``u``: the plant input the controller applied at each sample
    (the log's input unit: V, or N m; ``scale`` × the controller's output) and ``ctrl``, the
    controller's own output."""

    u: np.ndarray | None = None
    ctrl: np.ndarray | None = None

    def get(self, name: str) -> np.ndarray:
        if name in ("v", "tau", "u"):
            return self.u
        return getattr(self, name)


def reference_of(log, spec: ControllerSpec, key: str = "reference") -> np.ndarray:
    """The log's column named by the spec's ``reference`` (or ``feedforward``), canonical or
    extra."""
    name = getattr(spec, key)
    for src in (log.data, log.extra):
        if name in src:
            return np.asarray(src[name], float)
    have = ", ".join(list(log.data) + list(log.extra)) or "none"
    raise LogError(f"the controller's {key} column '{name}' is not in the log (it has "
                   f"{have}); name it with the spec's {key}=COLUMN", log.path)


def feedforward_of(log, spec: ControllerSpec) -> np.ndarray | None:
    """The spec's feedforward column of ``log`` (None when the spec has none)."""
    return None if spec.feedforward is None else reference_of(log, spec, "feedforward")


def on_samples(t: np.ndarray, spec: ControllerSpec) -> bool:
    """True when the controller updates at log samples: every sample (no ``period``), or every
    ``period`` that is a whole number of samples of a uniform log. False: it runs on its own
    clock, between the samples (a 1 kHz loop logged every 2-13 ms)."""
    if spec.period is None:
        return True
    dt = float((t[-1] - t[0]) / (len(t) - 1))
    m = spec.period / dt
    return round(m) >= 1 and abs(m - round(m)) <= 0.01 * m


def controller_ticks(t: np.ndarray, spec: ControllerSpec) -> np.ndarray:
    """Sample indices where the controller updates: every sample, or every ``period``
    (a whole number of samples of a uniform log: :func:`on_samples`)."""
    n = len(t)
    if spec.period is None:
        return np.arange(n)
    if not on_samples(t, spec):
        raise LogError(f"the controller period {spec.period:g} s is not a whole number of "
                       f"samples ({float((t[-1] - t[0]) / (n - 1)):g} s apart)")
    dt = float((t[-1] - t[0]) / (n - 1))
    return np.arange(0, n, int(round(spec.period / dt)))


def simulate_closed_loop(t, vals: dict[str, float], spec: ControllerSpec, ref: np.ndarray,
                         torque_driven: bool = False, x0=None, *, nsub: int | None = None,
                         logged_u: np.ndarray | None = None,
                         noise: np.ndarray | None = None,
                         feedforward: np.ndarray | None = None,
                         mean_quantum: bool = False,
                         logged_y: np.ndarray | None = None) -> ClosedLoopResult:
    """Simulate the motor ``vals`` (:func:`pmdcid.simulate.param_values`) under ``spec`` at
    instants ``t`` [s] from ``x0``, the set-point ``ref`` (the measured signal's unit).

    ``logged_u``: the log's own controller output (plant input units), whose first value
    starts the integrator (a loop running before the log began); ``logged_y``: the log's own
    measurement of the controlled signal, whose first value is what the controller read at
    that first tick (the integrator then takes up only what the loop carried in, not the
    proportional part of that sample's noise: read from the simulated start instead, a PI loop
    logged from rest every 5 ms put kp x the first sample's noise into the integrator for the
    whole log, J 4 % off). ``noise``: added to the
    measurement the controller reads at each sample (a synthetic log's sensor noise, fed back
    as a real loop feeds it back); the result's measured signal then includes it.
    ``feedforward``: added to the controller's output after its limits (controller units).
    ``mean_quantum``: the output's quantum as its mean effect (half a count less, smooth)
    instead of the rounding (:class:`~pmdcid.simulate.controller.ControllerState`; position
    form only): a fit's view, whose cost would otherwise be a staircase in the parameters.
    """
    t = np.asarray(t, float)
    ref = np.asarray(ref, float)
    if float(vals.get("latency", 0.0)) > 0.0 or vals.get("ramp") is not None:
        raise ModelError("input_delay (latency) and a ramp reading are not simulated in closed "
                         "loop; simulate without --controller")
    p = param_vector(vals)
    x = np.empty((len(t), NSTATE))
    u0 = float(logged_u[0]) if logged_u is not None and len(logged_u) else 0.0  # plant input
    x[0] = state_vector(settled_start(x0, u0, p, torque_driven))
    ff = np.zeros(len(t)) if feedforward is None else np.asarray(feedforward, float)
    ctrl = ControllerState(spec, mean_quantum)
    y0 = float(logged_y[0]) if logged_y is not None and len(logged_y) else math.nan
    logged = (logged_u, y0 if logged_u is not None else math.nan)
    if on_samples(t, spec):
        u = _run_loop(t, p, ctrl, (ref, ff), torque_driven, x, controller_ticks(t, spec),
                      logged, noise, vals, nsub)
    else:
        u = _run_own_clock(t, p, ctrl, (ref, ff), torque_driven, x, logged, noise, vals,
                           nsub)
    sensor = {"delay": float(vals.get("delay", 0.0)), "omega0": float(vals.get("omega0", 0.0))}
    om, th = apply_sensors(t, x[:, OMEGA_STATE], x[:, THETA_STATE], sensor)
    if noise is not None:
        if spec.measured == "omega":
            om = om + noise
        else:
            th = th + noise
    i = np.full(len(t), np.nan) if torque_driven else x[:, I_STATE].copy()
    return ClosedLoopResult(t, i, om, th, x[:, OMEGA_STATE].copy(), x[:, THETA_STATE].copy(),
                            u=u * spec.scale, ctrl=u)


def _measured(t, x, k, spec, vals, noise) -> float:
    """What the controller reads at sample k: the sensor's view of the states so far."""
    col = OMEGA_STATE if spec.measured == "omega" else THETA_STATE
    d = float(vals.get("delay", 0.0))
    if d > 0.0:
        y = float(np.interp(t[k] - d, t[:k + 1], x[:k + 1, col], left=x[0, col]))
    else:
        y = float(x[k, col])
    if spec.measured == "omega":
        y += float(vals.get("omega0", 0.0))
    if noise is not None:
        y += float(noise[k])
    return y


def _run_loop(t, p, ctrl, inputs, torque_driven, x, ticks, logged, noise, vals, nsub):
    """Fill ``x`` (n, NSTATE) sample by sample under the controller ``ctrl``; returns its
    output held at each sample (``inputs``: the reference and the feedforward; ``logged``:
    the log's controller output and its first measurement, :func:`_first_output`)."""
    ref, ff = inputs
    n = len(t)
    spec = ctrl.spec
    u = np.empty(n)
    run = _compiled("run_into")
    buf = np.empty((2, NSTATE))
    hold = np.empty(2)
    steps: dict[float, tuple] = {}
    is_tick = np.zeros(n, bool)
    is_tick[ticks] = True
    first = True
    out = 0.0
    for k in range(n):
        if is_tick[k]:
            ts = _period(t, k, ticks, spec)
            y = _measured(t, x, k, spec, vals, noise)
            if first:
                out = _first_output(ctrl, float(ref[k]), y, ts, logged, ff[0])
                first = False
            else:
                out = ctrl.step(float(ref[k]), y, ts)
            out += ff[k]
        u[k] = out
        if k + 1 < n:
            h = float(t[k + 1] - t[k])
            Phi, Gam, m = _stepper(steps, p, h, torque_driven, nsub)
            hold[:] = out * spec.scale
            run(hold, p, Phi, Gam, m, bool(torque_driven), x[k], buf)
            x[k + 1] = buf[1]
    return u


class _Stepper:
    """The motor stepped over a held input for any length of time (discretisations cached)."""

    def __init__(self, p, torque_driven, nsub):
        self.p, self.td, self.nsub = p, bool(torque_driven), nsub
        self.run = _compiled("run_into")
        self.cache: dict[float, tuple] = {}
        self.buf = np.empty((2, NSTATE))
        self.hold = np.empty(2)

    def advance(self, state: np.ndarray, u: float, h: float) -> np.ndarray:
        """The state ``h`` seconds after ``state`` under the input ``u`` held."""
        Phi, Gam, m = _stepper(self.cache, self.p, h, self.td, self.nsub)
        self.hold[:] = u
        self.run(self.hold, self.p, Phi, Gam, m, self.td, state, self.buf)
        return self.buf[1].copy()


def _read_at(now, state, seen, k, spec, vals, noise) -> float:
    """What the controller reads at time ``now`` inside sample k's interval (state ``state``):
    the sensor's view (a delay read from ``seen``, the (time, signal) pairs of the ticks and
    samples so far), the noise of sample k added."""
    col = OMEGA_STATE if spec.measured == "omega" else THETA_STATE
    y = float(state[col])
    seen.append((now, y))
    d = float(vals.get("delay", 0.0))
    if d > 0.0:
        while len(seen) > 2 and seen[1][0] <= now - d:  # keep one pair at or before now - d
            seen.popleft()
        ts, ys = zip(*seen, strict=True)
        y = float(np.interp(now - d, ts, ys))
    if spec.measured == "omega":
        y += float(vals.get("omega0", 0.0))
    if noise is not None:
        y += float(noise[k])
    return y


def _run_own_clock(t, p, ctrl, inputs, torque_driven, x, logged, noise, vals, nsub):
    """Fill ``x`` with the controller on its own clock: it ticks at t0 + j period [s], reads
    the simulated measurement there (the reference, feedforward and noise of the log sample
    the tick falls in held), and its output is held until the next tick; the kernel steps the
    motor between ticks and samples. Returns the output in effect at each sample (after a tick
    at the sample itself): what a log task records of a faster loop."""
    ref, ff = inputs
    spec = ctrl.spec
    n, period = len(t), float(spec.period)
    eps = 1e-9 * period
    motor = _Stepper(p, torque_driven, nsub)
    u = np.empty(n)
    out, j, state = 0.0, 0, x[0].copy()
    seen = deque([(float(t[0]), float(state[OMEGA_STATE if spec.measured == "omega"
                                            else THETA_STATE]))])
    for k in range(n):
        now, end = float(t[k]), float(t[k + 1]) if k + 1 < n else float(t[k])
        u[k] = out
        while t[0] + j * period <= max(now + eps, end - eps):
            tick = float(t[0] + j * period)
            if tick > now:
                state = motor.advance(state, out * spec.scale, tick - now)
                now = tick
            y = _read_at(now, state, seen, k, spec, vals, noise)
            if j == 0:
                out = _first_output(ctrl, float(ref[k]), y, period, logged, ff[0]) + ff[k]
            else:
                out = ctrl.step(float(ref[k]), y, period) + ff[k]
            j += 1
            if tick <= t[k] + eps:
                u[k] = out
        if k + 1 < n:
            x[k + 1] = motor.advance(state, out * spec.scale, end - now) if end > now else state
            state = x[k + 1].copy()
    return u


def _first_output(ctrl, ref: float, y: float, ts: float, logged, ff0: float) -> float:
    """The controller's first output (:meth:`ControllerState.start`): with the log's own
    output (``logged[0]``), the integrator started where it gives that output, from what the
    controller read then, the log's first measurement (``logged[1]``, where finite) rather
    than the simulated ``y``."""
    logged_u, y0 = logged
    if logged_u is None:
        return ctrl.start(ref, y, ts, None)
    read = y0 if math.isfinite(y0) else y
    return ctrl.start(ref, read, ts, float(logged_u[0]) / ctrl.spec.scale - ff0)


def _period(t, k, ticks, spec) -> float:
    """Length of the controller's period starting at sample k [s]."""
    if spec.period is not None:
        return float(spec.period)
    if k + 1 < len(t):
        return float(t[k + 1] - t[k])
    return float(t[k] - t[k - 1]) if k > 0 else 1.0


def _stepper(cache, p, h, torque_driven, nsub):
    """(Phi, Gamma, substeps) for a period of ``h`` seconds, cached by its length."""
    key = round(h, 12)
    hit = cache.get(key)
    if hit is None:
        if not h > 0 or not math.isfinite(h):
            raise LogError(f"time does not increase ({h:g} s between two samples)")
        m = nsub or choose_substeps(h, p)
        check_work(2, h, m, p)
        Phi, Gam = discretize_cached(p, h / m, torque_driven)
        hit = cache[key] = (Phi, Gam, int(m))
    return hit
