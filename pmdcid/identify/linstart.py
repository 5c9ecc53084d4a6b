"""A first J, bv, bc from any moving log: first-order least squares on input -> speed.

When no step settles (ramps, sines, chirps, a PRBS too fast for fit-mechanical), ``identify``
still needs a mechanical start for its simulation-error fits. Over one sample period dt with the
drive held (zero-order hold) and the friction's sign constant, the mechanical equation
``J omega' = T - bv omega - bc sign(omega)`` gives exactly

    omega[k+1] = a omega[k] + g (T[k] - bc sign(omega[k])),   a = exp(-dt bv/J),  g = (1 - a)/bv,

linear in (a, g, g bc): ordinary least squares over the samples where the rotor turns. Then
bv = (1 - a)/g, J = -dt bv/ln(a), bc = -(g bc)/g. The driving torque T [N m] is, by what the log
and the model hold:

- the logged torque ``tau`` (a torque-driven log);
- ``km i``, the logged current through the torque constant (km known);
- the voltage ``v`` for a lumped (per-volt) model, whose parameters are per volt;
- ``km (v - ke omega)/R`` (R, km known, no current: the electrical lag L/R neglected, the
  back-EMF damping km ke/R taken out of bv afterwards).

The electrical lag and the speed sensor's noise bias this estimate (noise on omega[k] pulls a
towards 0: J low by about the noise-to-signal variance ratio over dt/tau), so it is a start for
the fits that follow, written with stage ``start`` (never a prior) and no standard error.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from pmdcid.errors import FitError
from pmdcid.fit.results import Estimate, ResultProtocol, format_estimates
from pmdcid.io.derive import mad_std
from pmdcid.model import Model
from pmdcid.model.lumped import is_lumped

STAGE = "start"
#: a sample is used when the speed exceeds this many noise std at both ends (the rotor turns)
TURN_SIGMAS = 3.0
#: fewest samples the regression needs
MIN_ROWS = 20


def _noise(w: np.ndarray) -> float:
    d = np.diff(w)
    return mad_std(d) / math.sqrt(2.0) if len(d) else 0.0


def drive_torque(log, model: Model) -> tuple[np.ndarray, float]:
    """(T [N m, or V per volt], damping km ke/R to take out of bv) of one log: module docstring."""
    if log.drive == "tau":
        return np.asarray(log["tau"], float), 0.0
    if is_lumped(model):
        return np.asarray(log["v"], float), 0.0
    if not model.has("km"):
        raise FitError("a linear start needs km (give --km) or a lumped model", log.path)
    km = model.value("km")
    if log.has("i") and "i" not in log.derived:
        return km * np.asarray(log["i"], float), 0.0
    if not model.has("R"):
        raise FitError("a linear start from the voltage needs R (fit-electrical)", log.path)
    R = model.value("R")
    ke = model.value("ke") if "back_emf" in model.effects and model.has("ke") else 0.0
    return km * np.asarray(log["v"], float) / R, km * ke / R


def _rows(log, model: Model):
    T, emf = drive_torque(log, model)
    w = np.asarray(log["omega"], float)
    sig = _noise(w)
    turning = np.abs(w) > TURN_SIGMAS * max(sig, 1e-12)
    ok = turning[:-1] & turning[1:] & np.isfinite(w[:-1]) & np.isfinite(w[1:]) & np.isfinite(T[:-1])
    X = np.column_stack([w[:-1], T[:-1], -np.sign(w[:-1])])[ok]
    return X, w[1:][ok], emf, float(log.dt)


@dataclass
class LinearStart(ResultProtocol):
    """J, bv, bc of the first-order least squares (stage ``start``, no standard errors)."""

    estimates: dict[str, Estimate]
    paths: list[str]
    warnings: list[str] = field(default_factory=list)

    def apply(self, model: Model) -> None:
        """Write J, bv, bc as starting values (stage ``start``: never a prior)."""
        for name in ("J", "bv", "bc"):
            e = self.estimates[name]
            model.set(name, e.value, math.nan, e.unit, stage=STAGE)

    def table(self) -> str:
        lines = ["linear start: first-order least squares of the speed on the drive "
                 "(omega[k+1] = a omega[k] + g (T[k] - bc sign omega[k]))", ""]
        lines += format_estimates(list(self.estimates.values()))
        return "\n".join(lines)


def linear_start(logs, model: Model) -> LinearStart:
    """J, bv, bc from ``logs`` (speed measured or derived) by the regression of the module's
    docstring. Raises :class:`FitError` when the rotor hardly turns or the fit is not a stable
    first-order system (a >= 1 or a <= 0: the drive does not explain the speed)."""
    logs = [lg for lg in logs if lg.has("omega")]
    names = ", ".join(lg.path for lg in logs) or None
    if not logs:
        raise FitError("a linear start needs a speed (or angle) column", names)
    parts = [_rows(lg, model) for lg in logs]
    X = np.concatenate([p[0] for p in parts])
    y = np.concatenate([p[1] for p in parts])
    if len(y) < MIN_ROWS:
        raise FitError("the rotor hardly turns: too few moving samples for a linear start", names)
    dt = float(np.median([p[3] for p in parts]))
    scale = np.maximum(np.sqrt(np.mean(X**2, axis=0)), 1e-300)
    th = np.linalg.lstsq(X / scale, y, rcond=None)[0] / scale
    a, g, gbc = th
    if not (0 < a < 1 and g > 0):
        raise FitError(f"the speed does not follow the drive as a first-order system (a = {a:.3g},"
                       f" g = {g:.3g}): check the sign of the speed against the input", names)
    b_total = (1 - a) / g
    emf = float(np.median([p[2] for p in parts]))
    bv = b_total - emf
    warns = []
    if not bv > 0:
        warns.append(f"the first-order damping {b_total:.3g} is no more than the back-EMF's "
                     f"{emf:.3g}: bv starts at a tenth of it")
        bv = 0.1 * b_total
    J = -dt * b_total / math.log(a)
    bc = max(gbc / g, 0.0)
    est = {"J": Estimate("J", J, math.nan, "kg m^2"),
           "bv": Estimate("bv", bv, math.nan, "N m s/rad"),
           "bc": Estimate("bc", bc, math.nan, "N m")}
    return LinearStart(est, [lg.path for lg in logs], warns)


__all__ = ["LinearStart", "drive_torque", "linear_start"]
