"""Fisher information of a profile from the exact kernel's sensitivities at the model.

The information of a profile about parameters theta is ``sum_s S_s' S_s / sigma_s^2`` over the
signals s it measures (speed omega [rad/s]; current i [A] when the rig is voltage-driven), with
S_s the sensitivity of the simulated signal to each parameter: a central difference. The kernel
is only piecewise smooth at stick-slip events, which it places to within one internal step; run
here at 50 us steps (:data:`H_EVENTS`), the sensitivities are steady for relative steps from
1e-3 down to 3e-4, while 1e-2 (the fits' envelope step, right for the default 1 ms kernel)
overstates the dead zone's standard error 1.5x on slow triangles: the dead zone's effect is not
linear over +-1 % there. The predicted standard errors of a set of profiles are
``sqrt(diag(inv(sum F)))`` (absolute, SI).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pmdcid.fit.covariance import standard_errors
from pmdcid.model import EFFECTS, Model
from pmdcid.model.lumped import is_lumped, lag_substeps
from pmdcid.model.spec import BASE_PARAMS
from pmdcid.simulate import blocked_rotor, param_values, simulate_values

#: relative central-difference step of the sensitivities (see the module's docstring)
REL_STEP = 1e-3
#: the same for a lumped model with its electrical lag (tau_e): the fits' own step (1 %). Its
#: dead zone acts on the lagged per-volt torque, whose events move with tau_e, ke_share and dz
#: by internal steps, and smaller steps read that roughness, not the cost's bowl: on
#: bench/lumped_coverage.py's seed 1 (all five logs) the predicted errors of J, bc, dz, tau_e
#: fell 0.18, 0.38, 0.58, 0.68 % -> 0.088, 0.11, 0.15, 0.12 % -> 0.043, 0.044, 0.041, 0.16 %
#: at steps of 1e-2, 1e-3, 3e-4, against their spreads over 20 seeds of 0.14, 0.40, 0.59 and
#: 3.2 %
LAG_REL_STEP = 1e-2
#: longest internal kernel step [s]: stick-slip and dead-zone events are placed to within one
#: internal step, and with the kernel's default (1 ms at 1 kHz) the simulated response moves by
#: whole steps, which biases the sensitivities of bc and dz (2x on bc for the paper's motor);
#: from 0.2 ms down the predictions agree within 10 %, so 50 us is used
H_EVENTS = 5e-5


def internal_steps(t) -> int:
    """Internal kernel steps per sample of instants ``t`` [s]: steps of at most H_EVENTS."""
    dt = float(t[1] - t[0]) if len(t) > 1 else H_EVENTS
    return max(1, int(math.ceil(dt / H_EVENTS - 1e-9)))


@dataclass(frozen=True)
class Drive:
    """How a rig is driven: ``column`` of the profile files (``v`` or ``tau``) and whether the
    kernel runs its torque-driven path (a torque rig, or a lumped per-volt model with u = v)."""

    column: str
    torque_path: bool

    @property
    def electrical(self) -> bool:
        """True when the current is simulated (voltage-driven through R, L, km)."""
        return not self.torque_path


def drive_of(model: Model | None, taumax_given: bool = False) -> Drive:
    """The drive a model (or, without one, the options) implies.

    A lumped model (top-level ``"lumped": true``: parameters per volt, identified without
    current) is driven by voltage but simulated on the torque path with u = v; a model without
    R, L, km is torque-driven; otherwise voltage-driven.
    """
    if model is None:
        return Drive("tau", True) if taumax_given else Drive("v", False)
    if model.extra.get("lumped") is True:
        return Drive("v", True)
    if taumax_given or not all(model.has(n) for n in ("R", "L", "km")):
        return Drive("tau", True)
    return Drive("v", False)


def model_values(model: Model, drive: Drive) -> dict[str, float]:
    """Simulation values (SI) of ``model``: bv from the paper's b when missing."""
    return param_values(model, drive.torque_path)


def identified(model: Model, drive: Drive) -> list[str]:
    """Parameters a plan identifies: R, L (voltage-driven), J, bv, bc, dz when the model has
    them (bv also from b), a lumped model's electrical lag tau_e when it has one and its
    back-EMF share ke_share when that lies inside (0, 1) (the fits free them with the rest,
    and they trade with J: :mod:`pmdcid.model.lumped`), and the parameters of the model's
    effects (integers held)."""
    names = ["R", "L"] if drive.electrical and model.has("R") and model.has("L") else []
    for n in ("J", "bv", "bc", "dz"):
        if model.has(n) or (n == "bv" and model.has("b")):
            if n == "J" or model.value(n if model.has(n) else "b") > 0:
                names.append(n)
    if drive.torque_path and is_lumped(model) and model.has("tau_e") and model.value("tau_e") > 0:
        names.append("tau_e")
        if model.has("ke_share") and 0 < model.value("ke_share") < 1:  # (held at a bound)
            names.append("ke_share")
    for e in model.effects:
        eff = EFFECTS[e]
        if drive.torque_path and eff.acts_on in ("electrical", "input"):
            continue
        names += [p.name for p in eff.params if p.name not in eff.held and p.name not in names]
    return names


def signals_of(blocked: bool, drive: Drive) -> tuple[str, ...]:
    """Measured signals of a profile: the speed (free rotor) and the current (voltage drive)."""
    out = () if blocked else ("omega",)
    return out + (("i",) if drive.electrical else ())


#: what a plan says beside a lumped model's predicted tau_e error
TAU_E_BOUND = ("tau_e's predicted standard error is a lower bound: the fits' own is larger "
               "(the dead zone's events make their cost rough on the lag's scale), and on "
               "bench/lumped_coverage.py's seeds 1-12 the fitted tau_e lay beyond twice the "
               "predicted error in 4 of 12")


def bound_notes(names: list[str]) -> list[str]:
    """The words beside predicted errors that are lower bounds (:data:`TAU_E_BOUND`)."""
    return [TAU_E_BOUND] if "tau_e" in names else []


def simulate_profile(t, u, vals: dict[str, float], drive: Drive, blocked: bool):
    """Simulated i [A] and omega [rad/s] of one profile (blocked: the rotor held); a lumped
    model's lag (tau_e) resolved as its fits resolve it (:func:`~pmdcid.model.lumped.
    lag_substeps`) where that is finer than :data:`H_EVENTS`."""
    if blocked:
        vals = blocked_rotor(vals)
    nsub = internal_steps(t)
    tau_e = float(vals.get("tau_e", 0.0) or 0.0)
    if drive.torque_path and tau_e > 0 and len(t) > 1:
        nsub = max(nsub, lag_substeps(float(t[1] - t[0]), tau_e))
    return simulate_values(t, u, vals, drive.torque_path, nsub)


def step_of(name: str, value: float, scale: float, rel: float = REL_STEP) -> float:
    """Central-difference step [SI] of one parameter: ``rel`` of its value (of ``scale`` at 0)."""
    return rel * (abs(value) if value != 0 else scale)


def relative_step(vals: dict[str, float], drive: Drive) -> float:
    """The sensitivities' relative step: :data:`REL_STEP`, or :data:`LAG_REL_STEP` for a lumped
    model with its electrical lag (see there)."""
    lag = drive.torque_path and float(vals.get("tau_e", 0.0) or 0.0) > 0
    return LAG_REL_STEP if lag else REL_STEP


def sensitivities(t, u, vals, names, drive: Drive, blocked: bool,
                  scales: dict[str, float] | None = None,
                  signals: tuple[str, ...] | None = None) -> dict[str, np.ndarray]:
    """d(signal)/d(parameter) for each measured signal (default :func:`signals_of`): arrays
    (samples, parameters) in SI units."""
    sigs = signals_of(blocked, drive) if signals is None else signals
    cols: dict[str, list[np.ndarray]] = {s: [] for s in sigs}
    rel = relative_step(vals, drive)
    for name in names:
        h = step_of(name, vals[name], (scales or {}).get(name, 1.0), rel)
        lo = vals[name] - h
        hi = vals[name] + h
        spec = BASE_PARAMS.get(name)
        if spec is not None and lo < spec.lower:  # one-sided at a bound
            lo = vals[name]
        if spec is not None and hi > spec.upper:  # (a back-EMF share of 1)
            hi = vals[name]
        up = simulate_profile(t, u, {**vals, name: hi}, drive, blocked)
        dn = simulate_profile(t, u, {**vals, name: lo}, drive, blocked)
        for s in sigs:
            cols[s].append((up.get(s) - dn.get(s)) / (hi - lo))
    return {s: np.column_stack(c) if c else np.zeros((len(t), 0)) for s, c in cols.items()}


def information(sens: dict[str, np.ndarray], noise: dict[str, float]) -> np.ndarray:
    """Fisher information (parameters x parameters, SI) from a profile's sensitivities.

    ``noise``: white-noise std of each signal (``omega`` [rad/s], ``i`` [A]).
    """
    p = next(iter(sens.values())).shape[1] if sens else 0
    F = np.zeros((p, p))
    for s, S in sens.items():
        F += S.T @ S / noise[s] ** 2
    return F


#: parameters whose range is physical (a share of a whole), not a cap set far beyond any motor
RANGED = ("ke_share",)


def range_information(names: list[str]) -> np.ndarray:
    """The information a :data:`RANGED` parameter's range [lower, upper] alone holds
    (``BASE_PARAMS``): that of a uniform distribution over it, 12 / (upper - lower)^2 on the
    diagonal (0 for every other parameter: their bounds are caps, and one the profiles leave
    free stays ``free``). Negligible wherever the profiles determine the parameter; where they
    leave it free (a lumped model's back-EMF share, in [0, 1], on steps alone), it keeps the
    linearised covariance from sending the parameters that trade with it (J, tau_e) across
    values the range forbids."""
    d = []
    for n in names:
        spec = BASE_PARAMS.get(n) if n in RANGED else None
        d.append(12.0 / (spec.upper - spec.lower) ** 2 if spec is not None else 0.0)
    return np.diag(d)


def stderr(F: np.ndarray) -> np.ndarray:
    """Predicted standard errors sqrt(diag(inv F)); inf for a parameter F leaves free."""
    p = F.shape[0]
    out = np.full(p, math.inf)
    d = np.sqrt(np.clip(np.diag(F), 0.0, None))
    seen = d > 0
    if not seen.any():
        return out
    Fn = F[np.ix_(seen, seen)] / np.outer(d[seen], d[seen])  # unit diagonal: well conditioned
    w, V = np.linalg.eigh(Fn)
    keep = w > 1e-12 * w.max()
    inv = (V[:, keep] / w[keep]) @ V[:, keep].T
    se = predicted_se(inv) / d[seen]
    free = (np.abs(V[:, ~keep]) > 1e-3).any(axis=1)  # along a direction the data cannot see
    se[free] = math.inf
    out[seen] = se
    return out


def predicted_se(cov: np.ndarray) -> np.ndarray:
    """Predicted standard errors from a predicted covariance by the fits' one rule
    (:func:`pmdcid.fit.covariance.standard_errors`: a variance that is not finite and positive
    gives none), none written as inf here, plan's word for a parameter the profiles leave free
    (was 0 for a zero variance: a parameter known exactly)."""
    return np.nan_to_num(standard_errors(cov), nan=math.inf)


#: the parameters identify fits from the blocked-rotor logs' current (fit-electrical)
ELECTRICAL = ("R", "L")


def _pinv(F: np.ndarray) -> np.ndarray:
    """Inverse of an information matrix, scaled to unit diagonal first (well conditioned);
    a parameter it leaves free gets an infinite variance."""
    d = np.sqrt(np.clip(np.diag(F), 0.0, None))
    out = np.full(F.shape, 0.0)
    np.fill_diagonal(out, math.inf)
    seen = d > 0
    if seen.any():
        Fn = F[np.ix_(seen, seen)] / np.outer(d[seen], d[seen])
        out[np.ix_(seen, seen)] = np.linalg.pinv(Fn) / np.outer(d[seen], d[seen])
    return out


def stage_information(sens: list[dict[str, np.ndarray]], blocked: list[bool],
                      noise: dict[str, float], p: int) -> tuple[np.ndarray, np.ndarray]:
    """(blocked-rotor profiles' information, free profiles' speed-only information)."""
    F_el = sum((information(s, noise) for s, b in zip(sens, blocked, strict=True) if b),
               np.zeros((p, p)))
    F_sp = sum((information({"omega": s["omega"]}, noise) for s, b in
                zip(sens, blocked, strict=True) if not b and "omega" in s), np.zeros((p, p)))
    return F_el, F_sp


def staged_from(F_el: np.ndarray, F_sp: np.ndarray, names: list[str]) -> np.ndarray:
    """:func:`staged_stderr` from the two stages' information matrices (the free profiles'
    with the parameters' ranges, :func:`range_information`)."""
    F_sp = F_sp + range_information(names)
    e = [k for k, n in enumerate(names) if n in ELECTRICAL]
    m = [k for k, n in enumerate(names) if n not in ELECTRICAL]
    out = np.full(len(names), math.inf)
    if not e:
        return stderr(F_sp)
    cov_e = _pinv(F_el[np.ix_(e, e)])
    out[e] = predicted_se(cov_e)
    if m:
        inv_mm = _pinv(F_sp[np.ix_(m, m)])
        A = np.where(np.isfinite(inv_mm), inv_mm, 0.0) @ F_sp[np.ix_(m, e)]
        carried = A @ np.where(np.isfinite(cov_e), cov_e, 0.0) @ A.T
        out[m] = predicted_se(inv_mm + np.diag(np.diag(carried)))
    return out


def staged_stderr(sens: list[dict[str, np.ndarray]], blocked: list[bool], names: list[str],
                  noise: dict[str, float]) -> np.ndarray:
    """Predicted standard errors (SI) of the stages identify runs, not of one fit of everything:
    R, L from the blocked-rotor profiles' current alone (fit-electrical), the rest from the free
    profiles' speed alone (the joint fit) with R, L held at their fitted values, whose error
    moves the rest by ``-inv(F_mm) F_me dR`` (the covariance adds
    ``inv(F_mm) F_me Cov_e F_em inv(F_mm)``)."""
    F_el, F_sp = stage_information(sens, blocked, noise, len(names))
    return staged_from(F_el, F_sp, names)


def relative(se: np.ndarray, values: np.ndarray) -> np.ndarray:
    """Relative standard errors (inf for a zero value)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(values != 0, se / np.abs(values), math.inf)


__all__ = ["Drive", "ELECTRICAL", "LAG_REL_STEP", "RANGED", "REL_STEP", "TAU_E_BOUND",
           "bound_notes",
           "drive_of", "identified", "information", "model_values", "range_information",
           "relative", "sensitivities", "signals_of", "simulate_profile", "stage_information",
           "staged_from", "staged_stderr", "stderr"]
