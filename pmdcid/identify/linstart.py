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

The speed sensor's noise on omega[k] would pull a towards 0 (J low by about the noise-to-signal
variance ratio over dt/tau: on a 256-count encoder read at 1 kHz, bv 2000 times the truth, beyond
the joint fit's reach of 10 times its start). Where that noise dominates the speed's first
difference, omega[k] is instrumented by omega[k - m], m samples back where the noise no longer
reaches (:func:`noise_lag`): the same regression, instrumental variables. A drive that leaves
no damping the logs' span resolves (a ~ 1: a current-driven rotor whose viscous friction is
tiny) gives J = dt/g and a damping of J/span to start from. The electrical lag still biases it,
so it is a start for the fits that follow, written with stage ``start`` (never a prior) and no
standard error.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from pmdcid.errors import FitError
from pmdcid.fit.covariance import integrated_time
from pmdcid.fit.results import Estimate, ResultProtocol, format_estimates
from pmdcid.io.derive import mad_std
from pmdcid.model import Model
from pmdcid.model.lumped import is_lumped

STAGE = "start"
#: a sample is used when the speed exceeds this many noise std at both ends (the rotor turns)
TURN_SIGMAS = 3.0
#: fewest samples the regression needs
MIN_ROWS = 20
#: the longest reach of the speed's noise looked for [samples] (a firmware's moving average)
MAX_NOISE_LAG = 16
#: a pole this many of its standard errors above 1 is still read as 1 (no damping resolved):
#: a rotor driven by its current has a time constant J/bv of tens of seconds, and a quantised
#: speed puts the fitted pole 1e-3 either side of it
UNDAMPED_SE = 2.0


def _noise(w: np.ndarray) -> float:
    d = np.diff(w)
    return mad_std(d) / math.sqrt(2.0) if len(d) else 0.0


def drive_sources(log, model: Model) -> list[str]:
    """The drives a linear start can read ``log``'s torque from, in the order tried: the logged
    torque, the voltage of a lumped model, the logged current (km i), the voltage through R
    and km (module docstring)."""
    if log.drive == "tau":
        return ["tau"]
    if is_lumped(model):
        return ["v"]
    out = ["i"] if log.has("i") and "i" not in log.derived else []
    return out + ["v"] if model.has("R") or not out else out


def drive_torque(log, model: Model, source: str | None = None) -> tuple[np.ndarray, float]:
    """(T [N m, or V per volt], damping km ke/R to take out of bv) of one log from ``source``
    (one of :func:`drive_sources`; None: the first): module docstring."""
    source = source or drive_sources(log, model)[0]
    if log.drive == "tau":
        return np.asarray(log["tau"], float), 0.0
    if is_lumped(model):
        return np.asarray(log["v"], float), 0.0
    if not model.has("km"):
        raise FitError("a linear start needs km (give --km) or a lumped model", log.path)
    km = model.value("km")
    if source == "i":
        return km * np.asarray(log["i"], float), 0.0
    if not model.has("R"):
        raise FitError("a linear start from the voltage needs R (fit-electrical)", log.path)
    R = model.value("R")
    ke = model.value("ke") if "back_emf" in model.effects and model.has("ke") else 0.0
    return km * np.asarray(log["v"], float) / R, km * ke / R


def noise_lag(w: np.ndarray) -> int:
    """How many samples back the speed's noise no longer reaches [samples]: 0 when its first
    difference is not dominated by noise, else the last lag (up to :data:`MAX_NOISE_LAG`) at
    which the first difference's autocorrelation differs from its far lags' (the smooth
    signal's share, lags up to twice as far) by more than 3 times their scatter (at least
    1/sqrt(n)). The difference of a noise
    that reaches q samples (white: 0; an encoder's count difference: 1; a firmware's moving
    average of 4: 3) is correlated up to lag q + 1, with a negative autocorrelation somewhere
    (its autocorrelations sum to -1/2): without one, the differences are the signal's."""
    d = np.diff(w[np.isfinite(w)])
    d = d - np.mean(d) if len(d) else d
    den = float(d @ d)
    if len(d) < 10 * MAX_NOISE_LAG or not den > 0:
        return 0
    r = np.array([float(d[:-j] @ d[j:]) / den for j in range(1, 2 * MAX_NOISE_LAG + 1)])
    far = r[MAX_NOISE_LAG:]
    dev = r[:MAX_NOISE_LAG] - float(np.median(far))
    lim = 3.0 * max(1.0 / math.sqrt(len(d)), mad_std(far))
    if not np.any(dev < -lim):
        return 0
    return int(np.flatnonzero(np.abs(dev) > lim)[-1]) + 1


def _rows(log, model: Model, source: str | None = None):
    """Regressors [omega[k], T[k], -sign omega[k]], their instruments (omega[k] replaced by
    omega[k - m], m = :func:`noise_lag`: the speed's noise in omega[k] is in the regressor and
    pulls a towards 0; m samples back it is independent of the noise at k and k + 1), target
    omega[k + 1], the back-EMF damping, dt; the torque from ``source`` (:func:`drive_torque`)."""
    T, emf = drive_torque(log, model, source)
    w = np.asarray(log["omega"], float)
    sig = _noise(w)
    m = noise_lag(w)
    turning = np.abs(w) > TURN_SIGMAS * max(sig, 1e-12)
    k = np.arange(m, len(w) - 1)
    ok = (turning[k] & turning[k + 1] & np.isfinite(w[k]) & np.isfinite(w[k + 1])
          & np.isfinite(T[k]) & np.isfinite(w[k - m]))
    k = k[ok]
    X = np.column_stack([w[k], T[k], -np.sign(w[k])])
    Z = X.copy()
    Z[:, 0] = w[k - m]
    return X, Z, w[k + 1], emf, float(log.dt)


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
    docstring, from each drive the logs give in turn (:func:`drive_sources`: a logged current
    whose noise or the armature's lag leaves no stable first-order fit, then the voltage through
    R and km), the first that fits kept (its source said in a warning when not the first).
    Raises :class:`FitError` when the rotor hardly turns or no drive gives a stable first-order
    system (a >= 1 or a <= 0: the drive does not explain the speed), naming each one tried."""
    logs = [lg for lg in logs if lg.has("omega")]
    names = ", ".join(lg.path for lg in logs) or None
    if not logs:
        raise FitError("a linear start needs a speed (or angle) column", names)
    sources = [s for s in drive_sources(logs[0], model)
               if all(s in drive_sources(lg, model) for lg in logs)] or [None]
    failed = []
    for source in sources:
        res = _linear_start(logs, model, source, names)
        if isinstance(res, LinearStart):
            if failed:
                res.warnings.insert(0, f"the drive read from {source}: " + "; ".join(failed))
            return res
        failed.append(f"from {source}: {res}" if source else res)
    raise FitError("; ".join(failed), names)


def _instrumental(X: np.ndarray, Z: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, float]:
    """(the instrumental-variable solution of y ~ X with instruments Z, the standard error of
    its first coefficient): the sandwich (Z'X)^-1 Z'Z (X'Z)^-1 times the residual's variance
    and its integrated autocorrelation time (a quantised speed's residual is correlated)."""
    A = Z.T @ X
    th = np.linalg.lstsq(A, Z.T @ y, rcond=None)[0]
    r = y - X @ th
    try:
        Ai = np.linalg.inv(A)
    except np.linalg.LinAlgError:
        return th, 0.0
    var = float(r @ r) / max(len(y) - X.shape[1], 1) * integrated_time(r)
    cov = var * (Ai @ (Z.T @ Z) @ Ai.T)
    return th, math.sqrt(max(float(cov[0, 0]), 0.0))


def _linear_start(logs, model: Model, source, names) -> LinearStart | str:
    """The regression with the torque from ``source``: the result, or why the fit is no stable
    first-order system (the rotor hardly turning raises: no other drive changes that)."""
    parts = [_rows(lg, model, source) for lg in logs]
    X = np.concatenate([p[0] for p in parts])
    Z = np.concatenate([p[1] for p in parts])
    y = np.concatenate([p[2] for p in parts])
    if len(y) < MIN_ROWS:
        raise FitError("the rotor hardly turns: too few moving samples for a linear start", names)
    if not float(X[:, 1] @ -X[:, 2]) > 0:  # the drive's torque opposes the speed on the whole
        return ("the speed runs against the drive (the torque opposes it on the moving samples): "
                "check the sign of the speed against the input")
    dt = float(np.median([p[4] for p in parts]))
    scale = np.maximum(np.sqrt(np.mean(X**2, axis=0)), 1e-300)
    th, a_se = _instrumental(X / scale, Z / scale, y)
    a, g, gbc = th / scale
    span = max(float(lg.t[-1] - lg.t[0]) for lg in logs)
    if not (0 < a < 1 + max(dt / span, UNDAMPED_SE * a_se / scale[0]) and g > 0):
        return (f"the speed does not follow the drive as a first-order system (a = {a:.6g}, "
                f"g = {g:.3g}): check the sign of the speed against the input")
    emf = float(np.median([p[3] for p in parts]))
    warns = []
    if a >= 1 - dt / span:  # no damping the logs resolve: J from the drive's gain alone
        b_total = dt / (g * span)
        J = dt / g
        warns.append(f"no damping within the logs' span ({span:.3g} s): J from the drive's gain "
                     "alone, the damping started at J / span")
    else:
        b_total = (1 - a) / g
        J = -dt * b_total / math.log(a)
    bv = b_total - emf
    if not bv > 0:
        warns.append(f"the first-order damping {b_total:.3g} is no more than the back-EMF's "
                     f"{emf:.3g}: bv starts at a tenth of it")
        bv = 0.1 * b_total
    bc = max(gbc / g, 0.0)
    est = {"J": Estimate("J", J, math.nan, "kg m^2"),
           "bv": Estimate("bv", bv, math.nan, "N m s/rad"),
           "bc": Estimate("bc", bc, math.nan, "N m")}
    return LinearStart(est, [lg.path for lg in logs], warns)


__all__ = ["LinearStart", "drive_sources", "drive_torque", "linear_start"]
