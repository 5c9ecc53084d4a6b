"""Inverse-dynamics least squares (IDIM-LS, the robotics standard; Janot et al., EMPS 2019).

The rigid mechanical model, torque-driven (SI: tau [N m or N], speed [rad/s or m/s])::

    tau = J*alpha + bv*omega + bc*sign(omega) + tau0

is linear in (J, bv, bc, tau0). Speed ``omega`` and acceleration ``alpha`` come from the measured
angle (or speed) by the zero-phase Butterworth filter of :mod:`pmdcid.io.derive` and central
differences. Both sides of the regression are then filtered by the same zero-phase low-pass and
decimated ("parallel filtering and decimation", Gautier 1997): the equation error stays linear in
the parameters while the rows become close to independent, so that the standard errors from
(X'X)^-1 mean something. The fit is linear and instant; it is the start of the simulation-error
fit on any log that has an angle or a speed.

Voltage-driven logs use tau = km*i (needs the current ``i`` and ``km`` in the model); the paper's
dead zone is then ignored, which biases bc: the simulation-error fit corrects that.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from pmdcid.errors import FitError
from pmdcid.fit.covariance import block_covariance, standard_errors
from pmdcid.fit.results import Estimate, ResultProtocol
from pmdcid.identify.offset import offset_evident, offset_note
from pmdcid.io.derive import check_cutoff, choose_cutoff, log_cutoff, log_kinematics, lowpass
from pmdcid.model import Model
from pmdcid.model.spec import BASE_PARAMS
from pmdcid.notes import Note

PARAMS = ("J", "bv", "bc", "tau0")
STAGE = "inverse-dynamics"
#: samples skipped at each end of a log, in periods of the cut-off (filter transients)
EDGE_PERIODS = 5.0
#: rows at speeds below this fraction of the log's (99th percentile) speed are left out
REST_FRACTION = 0.02


def _units() -> dict[str, str]:
    from pmdcid.model.effects import effect_param_specs

    u = {n: BASE_PARAMS[n].unit for n in ("J", "bv", "bc")}
    u["tau0"] = effect_param_specs()["tau0"].unit
    return u


@dataclass
class InverseDynamicsResult(ResultProtocol):
    """Estimates J [kg m^2], bv [N m s/rad], bc [N m], tau0 [N m] (kg, N s/m, N, N for a linear
    axis), with standard errors; the relative torque error [%] of the regression; warnings."""

    estimates: dict[str, Estimate]
    rel_torque_error: float  # 100*||tau - X theta|| / ||tau|| on the regression rows [%]
    ndata: int
    cutoff_hz: float  # the (lowest) cut-off used [Hz]
    decimation: int
    condition: float  # condition number of the (column-scaled) regressor matrix
    warnings: list[str] = field(default_factory=list)

    def values(self) -> dict[str, float]:
        return {k: e.value for k, e in self.estimates.items()}

    def apply(self, model: Model, stage: str = STAGE) -> None:
        """Write J, bv, bc (and tau0 with the ``torque_offset`` effect) into ``model``."""
        for name, e in self.estimates.items():
            if name == "tau0":
                if not e.vary:
                    continue
                model.add_effect("torque_offset")
            model.set(name, e.value, e.stderr, e.unit, stage=stage)

    def table(self) -> str:
        lines = [f"{'parameter':<10} {'value':>14} {'stderr':>11}  unit"]
        for e in self.estimates.values():
            se = f"{e.stderr:11.3g}" if math.isfinite(e.stderr) else f"{'fixed':>11}"
            lines.append(f"{e.name:<10} {e.value:14.6g} {se}  {e.unit}")
        lines.append(f"relative torque error {self.rel_torque_error:.2f} % "
                     f"({self.ndata} rows, cut-off {self.cutoff_hz:g} Hz, "
                     f"decimation {self.decimation}, condition {self.condition:.1f})")
        return "\n".join(lines)


def applied_torque(log, model: Model | None) -> np.ndarray:
    """The torque [N m] driving the log: ``tau``, or km*i for a voltage-driven log."""
    if log.drive == "tau":
        return np.asarray(log["tau"], float)
    if not log.has("i"):
        raise FitError(
            f"{log.path}: voltage-driven log without current 'i': inverse dynamics needs the "
            "applied torque (map a 'tau' column or a current column 'i' and give km)"
        )
    if model is None or not model.has("km"):
        raise FitError(
            f"{log.path}: voltage-driven log: inverse dynamics needs km to turn the current into "
            "torque (give --km or put km in the model)"
        )
    return model.value("km") * np.asarray(log["i"], float)


def zoh_centred(u: np.ndarray) -> np.ndarray:
    """Torque seen by central differences at each sample instant: the mean of the held values
    either side of it, (u[k-1] + u[k]) / 2 (the input is zero-order held from each sample to
    the next; without this the torque would lead the kinematics by half a sample)."""
    u = np.asarray(u, float)
    return np.concatenate(([u[0]], 0.5 * (u[1:] + u[:-1])))


def decimation_factor(dt: float, cutoff_hz: float) -> int:
    """Keep one row in k after the parallel low-pass: k = floor(0.4*rate/cut-off), at least 1."""
    return max(1, int(0.4 / (dt * cutoff_hz)))


def auto_cutoff(log) -> float:
    """The log's ``--cutoff`` if given, else the highest cut-off at which sensor noise stays a
    small part of the acceleration (:func:`pmdcid.io.derive.choose_cutoff`)."""
    if getattr(log, "cutoff_hz", None) is not None:
        return float(log.cutoff_hz)
    derived = getattr(log, "derived", set())
    if log.has("theta") and "theta" not in derived:
        return choose_cutoff(log["theta"], log.dt, nder=2)
    if log.has("omega") and "omega" not in derived:
        return choose_cutoff(log["omega"], log.dt, nder=1)
    return log_cutoff(log)


def regression_rows(log, model: Model | None = None, cutoff_hz: float | None = None,
                    rest_fraction: float = REST_FRACTION, centre_zoh: bool = True):
    """Observation matrix rows [alpha, omega, sign(omega), 1] and torque of one log, filtered in
    parallel, edge-trimmed and decimated. Returns (X, y, cutoff_hz, k)."""
    fc = cutoff_hz if cutoff_hz is not None else auto_cutoff(log)
    check_cutoff(fc, log.dt, log.path)
    tau = applied_torque(log, model)
    if centre_zoh:
        tau = zoh_centred(tau)
    kin = log_kinematics(log, fc)
    X = np.column_stack([kin.alpha, kin.omega, np.sign(kin.omega), np.ones(log.n)])
    Xf = np.column_stack([lowpass(c, log.dt, fc) for c in X.T])
    yf = lowpass(tau, log.dt, fc)
    k = decimation_factor(log.dt, fc)
    edge = min(int(math.ceil(EDGE_PERIODS / (fc * log.dt))), log.n // 10)
    keep = np.zeros(log.n, bool)
    keep[edge:log.n - edge:k] = True
    # near rest the rotor may stick (friction then balances any torque below breakaway, not
    # bc*sign(omega)) and the sign of a filtered speed is noise: leave those rows out
    # (widened by one period of the cut-off: the parallel filter spreads their error)
    from scipy.ndimage import maximum_filter1d  # here: fit-nonlinear imports this module

    slow = np.abs(kin.omega) < rest_fraction * np.percentile(np.abs(kin.omega), 99)
    width = int(math.ceil(1.0 / (fc * log.dt)))
    slow = maximum_filter1d(slow.astype(np.uint8), 2 * width + 1, mode="constant") > 0
    keep &= ~slow
    return Xf[keep], yf[keep], fc, k


def fit_inverse_dynamics(logs, model: Model | None = None,
                         cutoff_hz: float | None = None,
                         rest_fraction: float = REST_FRACTION,
                         centre_zoh: bool = True) -> InverseDynamicsResult:
    """Least squares of the applied torque on filtered acceleration, speed, sign(speed), 1.

    ``logs``: one or more :class:`~pmdcid.io.Log` with an angle or a speed, and ``tau`` (or
    ``v`` with ``i`` and ``km`` in ``model``). ``cutoff_hz``: filter cut-off [Hz] (default: the
    logs' ``--cutoff``, else per log the highest cut-off up to min(rate/10, 100 Hz) at which the
    sensor noise is at most 10 % of the acceleration, see :func:`auto_cutoff`). Raises
    :class:`FitError` when the data cannot determine the parameters (no motion, J <= 0).
    ``rest_fraction``: rows slower than this fraction of the log's speed are left out (0 keeps
    every row); ``centre_zoh``: compare the kinematics with the held torque's mean either side
    of each instant (:func:`zoh_centred`). ``rest_fraction=0, centre_zoh=False`` is the EMPS
    authors' IDIM-LS as published.
    """
    if not logs:
        raise FitError("no logs given to the inverse-dynamics fit")
    rows, ys, warns = [], [], []
    fcs, k_used, segments = [], 1, []
    for log in logs:
        X, y, fc, k_used = regression_rows(log, model, cutoff_hz, rest_fraction, centre_zoh)
        fcs.append(fc)
        if len(y) == 0 or np.abs(X[:, 1]).max() <= 0:
            warns.append(f"{log.path}: never moves: left out of the inverse-dynamics fit")
            continue
        first = segments[-1][2] if segments else 0
        segments.append((len(segments), first, first + len(y)))
        rows.append(X)
        ys.append(y)
    if not rows:
        raise FitError("no log moves: inverse dynamics needs motion (speed and acceleration)")
    X = np.vstack(rows)
    y = np.concatenate(ys)
    names = list(PARAMS)
    # sign(omega) and the constant are indistinguishable if the speed never reverses
    sgn = X[:, 2]
    if min((sgn > 0).mean(), (sgn < 0).mean()) < 0.01:
        warns.append("the speed (almost) never reverses: torque offset tau0 cannot be told from "
                     "Coulomb friction; tau0 fixed at 0")
        X = X[:, :3]
        names = names[:3]
    theta, se, resid, sv = _solve(X, y, segments)
    if len(names) == 4 and not offset_evident(theta[3], se[3], len(y)):
        warns.append(Note(offset_note(theta[3], se[3], _units()["tau0"], len(y)), about="tau0",
                          severity="note"))
        X = X[:, :3]
        names = names[:3]
        theta, se, resid, sv = _solve(X, y, segments)
    n, p = X.shape
    units = _units()
    est = {nm: Estimate(nm, float(v), float(e), units[nm]) for nm, v, e in
           zip(names, theta, se, strict=True)}
    if "tau0" not in est:
        est["tau0"] = Estimate("tau0", 0.0, math.nan, units["tau0"], vary=False)
    if est["J"].value <= 0:
        raise FitError(f"inverse dynamics gives a non-positive inertia J = {est['J'].value:.3g}: "
                       "the logs do not excite the acceleration (or the cut-off is too low)")
    for nm in ("bv", "bc"):
        if est[nm].value < 0:
            warns.append(f"inverse dynamics gives a negative {nm} = {est[nm].value:.3g} "
                         f"{units[nm]}: friction poorly excited")
    rel = 100.0 * float(np.linalg.norm(resid) / np.linalg.norm(y)) if np.any(y) else math.nan
    return InverseDynamicsResult(est, rel, n, float(min(fcs)), k_used,
                                 float(sv[0] / sv[-1]) if sv[-1] > 0 else math.inf, warns)


def _solve(X, y, segments):
    """Column-scaled least squares of ``y`` on ``X``: (theta, standard errors from the block
    sandwich, residual, singular values); raises :class:`FitError` when ``X`` is rank-deficient."""
    scale = np.linalg.norm(X, axis=0)
    scale[scale == 0] = 1.0
    Xs = X / scale
    theta_s, _, rank, sv = np.linalg.lstsq(Xs, y, rcond=None)
    if rank < Xs.shape[1]:
        raise FitError("the logs do not excite the model (regressor matrix rank-deficient): "
                       "use a log with acceleration, varying speed and both directions")
    theta = theta_s / scale
    resid = y - X @ theta
    n, p = X.shape
    s2 = float(resid @ resid) / max(n - p, 1)
    cov = np.linalg.inv(Xs.T @ Xs) * s2 / np.outer(scale, scale)
    # the torque residual is model error, correlated in time: block sandwich (covariance.py)
    cov, _ = block_covariance(X, resid, segments, cov)
    return theta, standard_errors(cov), resid, sv


def fit_quasi_static(logs, model: Model | None = None,
                     rest_fraction: float = REST_FRACTION) -> dict[str, float]:
    """Torque on speed, sign(speed) and 1 at the samples themselves (no filter, no acceleration):
    bv [N m s/rad], bc [N m] and tau0 [N m] when the sampling is too slow to resolve the
    acceleration, so that :func:`fit_inverse_dynamics` has nothing to regress on. A start for
    the simulation-error fit, not an estimate: J is left out. Raises :class:`FitError` when the
    speed never leaves rest or the rows cannot separate the terms."""
    rows, ys = [], []
    for log in logs:
        # the speed at t_k follows the torque held over the period before it, u[k-1]
        tau = applied_torque(log, model)[:-1]
        om = (np.asarray(log["omega"], float) if log.has("omega") else np.gradient(
            np.asarray(log["theta"], float), log.dt))[1:]
        ok = np.isfinite(om) & np.isfinite(tau)
        if not ok.any():
            continue
        moving = ok & (np.abs(om) > rest_fraction * np.percentile(np.abs(om[ok]), 99))
        rows.append(np.column_stack([om[moving], np.sign(om[moving]), np.ones(moving.sum())]))
        ys.append(tau[moving])
    X = np.vstack(rows) if rows else np.zeros((0, 3))
    y = np.concatenate(ys) if ys else np.zeros(0)
    if len(y) < 10:
        raise FitError("the speed never leaves rest: no quasi-static start either")
    sgn = X[:, 1]
    both = min((sgn > 0).mean(), (sgn < 0).mean()) >= 0.01
    if not both:
        X = X[:, :2]
    theta, _, rank, _ = np.linalg.lstsq(X, y, rcond=None)
    if rank < X.shape[1]:
        raise FitError("torque and speed do not separate viscous from Coulomb friction")
    out = {"bv": float(theta[0]), "bc": float(theta[1]), "tau0": float(theta[2]) if both else 0.0}
    if out["bv"] <= 0:
        raise FitError(f"a quasi-static fit gives a non-positive bv = {out['bv']:.3g}")
    return out
