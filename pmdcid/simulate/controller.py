"""A digital P / PI / PID controller as logged rigs run it: the ``--controller`` spec.

The spec is a small JSON object (a file, or the text itself) or ``key=value`` pairs separated by
commas (``type=PI,kp=0.05,ki=2,umax=7.4``). Keys (docs/cli.md, "Closed-loop logs"):

- ``type``: ``P``, ``PI`` or ``PID`` (default ``PI``); ``kp``, ``ki``, ``kd``: gains, in the
  controller's output unit per unit of the measured signal (ki per second, kd times seconds);
- ``umin``, ``umax``: output limits (default unbounded; ``ulimit`` sets both to ±value);
- ``period`` [s]: the controller's period (default: one step per log sample, as a loop-timed
  log records one row per step); a period that is not a whole number of log samples (a 1 kHz
  loop logged every 2-13 ms) runs on its own clock between the samples
  (:mod:`pmdcid.simulate.closedloop`);
- ``reference``: the log column holding the set-point (default ``omega_ref``); ``measured``:
  ``omega`` or ``theta``, the signal the controller acts on (default ``omega``);
- ``derivative``: ``measurement`` (default: the D term differentiates −measured, no kick on a
  set-point step) or ``error``; ``dfilter``: FIR taps applied to the differentiated signal
  (EMPS: ``[0.5, 0.5]``);
- ``antiwindup``: ``clamp`` (default: the integrator holds while the output is saturated and the
  error would push it further) or ``none``;
- ``form``: ``position`` (default: u = P + I + D) or ``velocity`` (incremental: u_k = u_{k-1} +
  kp Δe + ki e Ts + kd Δ²(...): the output itself is the integrator, clipped to the limits);
- ``integrate``: ``time`` (default: the integral adds ki·e·Ts) or ``steps`` (adds ki·e per
  step: a loop that ignores its own period; ki is then per step);
- ``quantum``: the output's resolution (an integer PWM count; default 0: none), rounded as
  ``rounding`` says: ``down`` (default, floor), ``zero`` (toward zero: C's integer cast of a
  float, ``(int)u``) or ``nearest``;
- ``scale``: the plant input per unit of controller output (EMPS: the drive gain 35.15 N/V;
  default 1); limits and quantum apply to the controller's own output;
- ``feedforward``: a log column added to the controller's output after its limits (EMPS's
  validation pulses, ``pulse_in_vir_units``; default none).
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field, fields

from pmdcid.errors import PmdcidError


class ControllerError(PmdcidError):
    """A ``--controller`` spec that cannot be read or is inconsistent."""


_CHOICES = {
    "type": ("P", "PI", "PID"), "measured": ("omega", "theta"),
    "derivative": ("measurement", "error"), "antiwindup": ("clamp", "none"),
    "form": ("position", "velocity"), "integrate": ("time", "steps"),
    "rounding": ("down", "zero", "nearest"),
}


@dataclass(frozen=True)
class ControllerSpec:
    """A P/PI/PID controller (see the module docstring for every key and unit)."""

    type: str = "PI"
    kp: float = 0.0
    ki: float = 0.0
    kd: float = 0.0
    umin: float = -math.inf
    umax: float = math.inf
    period: float | None = None
    reference: str = "omega_ref"
    measured: str = "omega"
    derivative: str = "measurement"
    dfilter: tuple[float, ...] = field(default=(1.0,))
    antiwindup: str = "clamp"
    form: str = "position"
    integrate: str = "time"
    quantum: float = 0.0
    rounding: str = "down"
    scale: float = 1.0
    feedforward: str | None = None

    @property
    def gains(self) -> tuple[float, float, float]:
        """(kp, ki, kd) with the terms the type leaves out at 0."""
        return (self.kp, self.ki if "I" in self.type else 0.0,
                self.kd if "D" in self.type else 0.0)

    def describe(self) -> str:
        kp, ki, kd = self.gains
        lim = (f", output in [{self.umin:g}, {self.umax:g}]"
               if math.isfinite(self.umin) or math.isfinite(self.umax) else "")
        per = f"every {self.period:g} s" if self.period else "every log sample"
        return (f"{self.type} on {self.measured} (reference {self.reference}): kp {kp:g}, "
                f"ki {ki:g}, kd {kd:g}{lim}, {self.form} form, {per}")


def parse_controller(text: str) -> ControllerSpec:
    """A :class:`ControllerSpec` from a JSON file's path, JSON text, or ``key=value,...``."""
    src = None
    if os.path.isfile(text):
        src = text
        try:
            with open(text, encoding="utf-8") as fh:
                text = fh.read()
        except (OSError, UnicodeDecodeError) as exc:
            raise ControllerError(f"cannot read the controller spec: {exc}", src) from None
    try:
        raw = _raw(text)
    except ControllerError as exc:
        raise ControllerError(str(exc), src) from None
    try:
        return controller_from_dict(raw)
    except ControllerError as exc:
        raise ControllerError(str(exc), src) from None


def _raw(text: str) -> dict:
    s = text.strip()
    if s.startswith("{"):
        try:
            raw = json.loads(s)
        except json.JSONDecodeError as exc:
            raise ControllerError(f"controller spec is not valid JSON: {exc}") from None
        if not isinstance(raw, dict):
            raise ControllerError("controller spec must be a JSON object")
        return raw
    raw = {}
    for part in s.split(","):
        key, sep, val = part.partition("=")
        if not sep or not key.strip():
            raise ControllerError(f"controller spec {part.strip()!r}: give key=value pairs "
                                  "(type=PI,kp=...,ki=...) or a JSON file")
        raw[key.strip()] = val.strip()
    return raw


def controller_from_dict(raw: dict) -> ControllerSpec:
    """A checked :class:`ControllerSpec` from a dict of spec keys (values may be strings)."""
    known = {f.name for f in fields(ControllerSpec)} | {"ulimit"}
    bad = sorted(set(raw) - known)
    if bad:
        raise ControllerError(f"unknown controller key(s) {', '.join(bad)}; known: "
                              f"{', '.join(sorted(known))}")
    vals: dict = {}
    for key, val in raw.items():
        vals[key] = _value(key, val)
    if "ulimit" in vals:
        lim = abs(vals.pop("ulimit"))
        vals.setdefault("umin", -lim)
        vals.setdefault("umax", lim)
    spec = ControllerSpec(**vals)
    _check(spec)
    return spec


def _value(key: str, val):
    if key in _CHOICES:
        v = str(val).strip()
        v = v.upper() if key == "type" else v.lower()
        if v not in _CHOICES[key]:
            raise ControllerError(f"controller {key} {val!r}: choose among "
                                  f"{', '.join(_CHOICES[key])}")
        return v
    if key in ("reference", "feedforward"):
        return str(val).strip()
    if key == "dfilter":
        taps = val if isinstance(val, list) else str(val).strip("[] ").split(";")
        return tuple(_number(key, x) for x in taps)
    return _number(key, val)


def _number(key: str, val) -> float:
    try:
        x = float(val)
    except (TypeError, ValueError):
        raise ControllerError(f"controller {key} {val!r} is not a number") from None
    if math.isnan(x) or (math.isinf(x) and key not in ("umin", "umax")):
        raise ControllerError(f"controller {key} {val!r} is not a finite number")
    return x


def _check(spec: ControllerSpec) -> None:
    if spec.umin >= spec.umax:
        raise ControllerError(f"controller umin {spec.umin:g} is not below umax {spec.umax:g}")
    if spec.period is not None and not spec.period > 0:
        raise ControllerError(f"controller period {spec.period:g} s must be positive")
    if spec.quantum < 0 or spec.scale == 0:
        raise ControllerError("controller quantum must be >= 0 and scale non-zero")
    if not spec.dfilter or abs(sum(spec.dfilter)) < 1e-12:
        raise ControllerError("controller dfilter taps must sum to a non-zero value")
    if not any(spec.gains):
        raise ControllerError(f"controller {spec.type} has all its gains at 0")


class ControllerState:
    """One running controller: :meth:`step` gives the output for one period."""

    def __init__(self, spec: ControllerSpec, mean_quantum: bool = False):
        self.spec = spec
        #: the quantum's mean effect (u - quantum/2, a smooth output) instead of the rounding:
        #: a fit's view, whose cost must move continuously with the motor's parameters. Position
        #: form only: in the velocity form the rounded output is the integrator's state, and
        #: half a count less every step would accumulate
        self.mean_quantum = mean_quantum and spec.form == "position"
        self.integral = 0.0
        self.u_prev = 0.0
        self.e_prev = math.nan
        self.d_prev = 0.0
        self.hist: list[float] = []  # the differentiated signal's last len(dfilter)+1 values

    def _derivative(self, x: float, ts: float) -> float:
        """Filtered backward difference of ``x`` [unit/s] (0 on the first step)."""
        taps = self.spec.dfilter
        self.hist.append(x)
        if len(self.hist) > len(taps) + 1:
            self.hist.pop(0)
        h = self.hist
        if len(h) < 2:
            return 0.0
        now = sum(c * v for c, v in zip(taps, reversed(h), strict=False))
        before = sum(c * v for c, v in zip(taps, reversed(h[:-1]), strict=False))
        norm = sum(taps[:len(h) - 1])
        return (now - before) / (ts * norm) if norm else 0.0

    def terms(self, ref: float, meas: float, ts: float) -> tuple[float, float, float]:
        """(error, its integral increment, derivative term) of this step."""
        kp, ki, kd = self.spec.gains
        e = ref - meas
        dx = e if self.spec.derivative == "error" else -meas
        d = kd * self._derivative(dx, ts) if kd else 0.0
        inc = ki * e * (1.0 if self.spec.integrate == "steps" else ts)
        return e, inc, d

    def start(self, ref: float, meas: float, ts: float, logged: float | None) -> float:
        """The first step's output; with ``logged`` (the log's first controller output) the
        integrator starts where the output equals it (a loop that ran before the log began)."""
        u = self.step(ref, meas, ts)
        if logged is not None and math.isfinite(logged) and ("I" in self.spec.type
                                                              or self.spec.form == "velocity"):
            shift = logged - u
            if self.spec.form == "velocity":
                self.u_prev += shift
            else:
                self.integral += shift
            u = self._limit(u + shift)
            if self.spec.form == "velocity":
                self.u_prev = u
        return u

    def step(self, ref: float, meas: float, ts: float) -> float:
        """The controller's output for one period of ``ts`` seconds (its own unit)."""
        e, inc, d = self.terms(ref, meas, ts)
        kp = self.spec.gains[0]
        if self.spec.form == "velocity":
            de = 0.0 if math.isnan(self.e_prev) else e - self.e_prev
            u = self._limit(self.u_prev + kp * de + inc + (d - self.d_prev))
            self.u_prev, self.e_prev, self.d_prev = u, e, d
            return u
        raw = kp * e + self.integral + inc + d
        sat = (raw > self.spec.umax and e > 0) or (raw < self.spec.umin and e < 0)
        if not (sat and self.spec.antiwindup == "clamp"):
            self.integral += inc
        self.e_prev = e
        return self._limit(kp * e + self.integral + d)

    def _limit(self, u: float) -> float:
        q = self.spec.quantum
        if q > 0 and self.mean_quantum:
            u -= _mean_rounding(self.spec.rounding, u) * q
        elif q > 0:
            u = q * _ROUND[self.spec.rounding](u / q)
        return min(max(u, self.spec.umin), self.spec.umax)


#: the output's rounding to whole quanta (a millionth of a count: rounding, not a level)
_ROUND = {"down": lambda x: math.floor(x + 1e-6),
          "zero": lambda x: float(math.trunc(x + math.copysign(1e-6, x))),
          "nearest": lambda x: math.floor(x + 0.5)}


def _mean_rounding(rounding: str, u: float) -> float:
    """What the rounding takes off on average [quanta]: half of one rounding down, half toward
    zero, none to the nearest."""
    if rounding == "down":
        return 0.5
    if rounding == "zero":
        return 0.5 * (1.0 if u > 0 else -1.0 if u < 0 else 0.0)
    return 0.0
