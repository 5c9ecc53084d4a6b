"""fit-electrical on free-running logs: R [ohm], L [H] and ke [V s/rad] without a blocked rotor.

With the rotor turning the armature obeys ``v = R i + L di/dt + ke omega``. Differentiating a
sampled current amplifies its noise and, at the sample rates of real rigs (L/R of a small motor is
0.5-5 ms, logs at 0.1-2 kHz), blurs the very transient that carries L. Instead the equation is
discretised exactly: over one sample period dt with the voltage held (zero-order hold, as the
contract says a log's ``v`` is) and the speed varying linearly between samples,

    i[k+1] = a i[k] + g v[k] + c0 omega[k] + c1 omega[k+1] + b_log,
    a = exp(-dt R/L),  g = (1 - a)/R,  c0 + c1 = -(1 - a) ke/R,

linear in (a, g, c0, c1, b) and solved by ordinary least squares over every sample of every log
(one offset ``b`` per log: a current-sensor offset or a brush drop, v0 = b/g volts). Then
R = (1 - a)/g, ke = -(c0 + c1)/g, L = -R dt/ln(a). The split c0/c1 is left free, so a speed that is
a window average (encoder counts per sample) rather than an instantaneous value costs nothing.
When L/R is below about two sample periods, a is near 0 and L is not resolved: R and ke still are
(they set the quasi-static current), and the result says so.

Standard errors: the sandwich covariance of :mod:`.covariance` (the residual is correlated when the
speed sensor or the model is imperfect), propagated to R, L, ke by finite differences.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from pmdcid.errors import FitError
from pmdcid.fit.covariance import block_covariance, standard_error, standard_errors
from pmdcid.fit.results import (
    Estimate,
    FitStats,
    bounded,
    fitted,
    format_estimates,
    plus_minus,
    write_estimate,
)
from pmdcid.identify.plausibility import MAX_TAU_ELECTRICAL
from pmdcid.identify.steps import held_levels
from pmdcid.io.derive import mad_std
from pmdcid.model import Model
from pmdcid.model.effects import within_range

STAGE = "fit-electrical"
#: the stage name of a km written as ke (no datasheet km)
KM_FROM_KE = "ke (km = ke, no datasheet)"
#: what that means, in words (the result's warning and identify's note)
KM_FROM_KE_NOTE = ("no datasheet km: km = ke = {ke:.4g} is written (an ideal motor's torque and "
                   "back-EMF constants are one number in SI, N m/A = V s/rad; iron and brush "
                   "losses make the true km slightly smaller); give --km to use the datasheet's")
#: L/R below this many sample periods: L is not resolved by the sampling
MIN_TAU_SAMPLES = 2.0
#: ... or when its relative standard error exceeds this
MAX_L_REL_SE = 0.25
#: the speed moves by more than this many noise std: the rotor turns
TURN_SIGMAS = 10.0
#: a current that overshoots its settled value by this fraction behaves like a loaded motor
OVERSHOOT = 0.10
#: refinements of the instrumental-variable estimate (the noise on the regressor i[k] biases
#: plain least squares: the current is nearly a static function of voltage and speed, so the
#: little that is left to tell a = exp(-dt R/L) is of the order of the sensor noise)
IV_ITERATIONS = 3
#: a voltage offset beyond this many standard errors is reported
OFFSET_SIGMAS = 3.0


#: units of the parameters a motor's torque equation is written in (N m, N m s/rad, kg m^2,
#: ...; N and kg for a linear axis): with the current logged they are known only through
#: km (the torque is km i), so they scale with it
TORQUE_UNITS = ("N m", "N", "kg")


def follow_ke(model: Model, km_before: float) -> None:
    """A km written as ke (no datasheet, :data:`KM_FROM_KE`) follows a refitted ke: km = ke
    again, and every parameter of the torque equation (its unit in :data:`TORQUE_UNITS`;
    values, standard errors and intervals) scaled by the same ratio ke / ``km_before``, so that
    the model simulates exactly as it was fitted (only ratios to km are seen in the current and
    speed). Why: a refit that moves ke (diagnose adding a brush drop: ke 0.0539 -> 0.0500) left
    km at the old ke, and J, bv, bc 8 % off at a thousand standard errors."""
    km = model.parameters.get("km")
    if km is None or km.stage != KM_FROM_KE or not model.has("ke") or km_before <= 0:
        return
    ke = model.parameters["ke"]
    scale = ke.value / km_before
    if scale == 1.0:
        return
    for name, par in model.parameters.items():
        if name != "km" and par.unit.split(" ")[0] in TORQUE_UNITS:
            par.value *= scale
            par.stderr *= scale
            if par.interval is not None:
                par.interval = within_range(name, par.interval[0] * scale,
                                            par.interval[1] * scale)
    model.set("km", ke.value, ke.stderr, km.unit, stage=KM_FROM_KE)


def first_diff_noise_std(x: np.ndarray) -> float:
    """Robust white-noise std of a signal from its first differences (MAD), same unit as x."""
    d = np.diff(np.asarray(x, float))
    if len(d) < 3:
        return 0.0
    return mad_std(d) / math.sqrt(2.0)


def rotor_turns(omega: np.ndarray) -> bool:
    """Whether a speed record [rad/s] shows the rotor turning: its spread (5th to 95th
    percentile) exceeds :data:`TURN_SIGMAS` noise std (an offset alone is not motion)."""
    om = np.asarray(omega, float)
    spread = float(np.percentile(om, 95) - np.percentile(om, 5))
    return spread > TURN_SIGMAS * first_diff_noise_std(om) and spread > 0.0


def loaded_current(i: np.ndarray, onset: int) -> tuple[bool, float, float]:
    """Whether the current [A] after a step at sample ``onset`` overshoots its settled value as a
    motor speeding up does (back-EMF), not as an RL circuit (monotone). Returns (turns?, peak
    change, settled change) [A]."""
    i = np.asarray(i, float)
    base = float(np.median(i[:onset]))
    after = i[onset:] - base
    w = max(1, min(len(after) // 50, 25))
    sm = np.convolve(after, np.ones(w) / w, mode="valid")
    final = float(np.median(after[-max(3, len(after) // 10):]))
    sg = math.copysign(1.0, final) if final else 1.0
    peak = float(np.max(sg * sm)) * sg
    noise = first_diff_noise_std(i) / math.sqrt(w)
    over = abs(peak) - abs(final)
    return over > max(OVERSHOOT * abs(final), 8 * noise), peak, final


@dataclass
class FreeRunResult:
    """R, L, ke (and tau_e, per-log voltage offsets) from free-running logs; warnings."""

    estimates: dict[str, Estimate]
    offsets: dict[str, Estimate]
    paths: list[str]
    stats: FitStats
    dt: float
    l_resolved: bool
    l_bound: bool = False  # L is an upper bound (a not above 0)
    ke_resolved: bool = True
    warnings: list[str] = field(default_factory=list)
    covariance_note: str = ""

    def apply(self, model: Model) -> None:
        """Write R, ke (effect ``back_emf``) and L when resolved (or when the model has no L
        yet, as the honest value or bound with its warning); other parameters are kept."""
        e = self.estimates["R"]
        model.set("R", e.value, e.stderr, e.unit, stage=STAGE)
        if self.ke_resolved:
            e = self.estimates["ke"]
            model.set("ke", e.value, e.stderr, e.unit, stage=STAGE)
            model.add_effect("back_emf")
            if not model.has("km"):  # SI: one number (V s/rad = N m/A); the datasheet's wins
                model.set("km", e.value, e.stderr, "N m/A", stage=KM_FROM_KE)
        keep_l = not self.l_resolved and model.has("L")
        if not keep_l:
            write_estimate(model, self.estimates["L"], STAGE)
        fits = model.extra.setdefault("fits", {})
        fits[STAGE] = {
            "logs": list(self.paths), "method": "free-running (exact discrete-time regression)",
            "tau_e": self.estimates["tau_e"].value, "L_resolved": self.l_resolved,
            "L_kept_from_model": keep_l,
            "voltage_offsets_V": {k: v.value for k, v in self.offsets.items()},
            "ndata": self.stats.ndata, "redchi": self.stats.redchi,
        }

    def table(self) -> str:
        lines = ["fit-electrical: free-running logs (v = R i + L di/dt + ke omega, exact "
                 "discrete-time regression)", ""]
        lines += format_estimates([self.estimates[k] for k in ("R", "L", "ke", "tau_e")])
        if not self.l_resolved:
            lines.append(f"L not resolved: L/R is under {MIN_TAU_SAMPLES:g} sample periods "
                         f"({self.dt * 1e3:.3g} ms) or loosely determined; "
                         + ("the interval up to its bound shown" if self.l_bound
                            else "value shown as fitted"))
        lines.append("")
        lines.append("voltage offset per log (brush drop or current-sensor offset, V):")
        for p, e in self.offsets.items():
            name = p if len(p) <= 40 else "..." + p[-37:]
            se = f" ± {e.stderr:.2g}" if math.isfinite(e.stderr) else ""
            lines.append(f"  {name:<40} {e.value:9.4g}{se}")
        lines.append(f"residual std {math.sqrt(self.stats.redchi):.3g} A "
                     f"({self.stats.ndata} samples)")
        if self.covariance_note:
            lines.append(self.covariance_note)
        return "\n".join(lines)


def _rows(log) -> tuple[np.ndarray, np.ndarray, list[tuple[int, int, float]]]:
    """Regressors [i[k], v[k], w[k], w[k+1]], target i[k+1] of one log, and the rows of the
    voltage's plateaus with their means' standard errors [V]. A measured voltage held at levels
    enters as its plateaus' means (:func:`~pmdcid.identify.steps.held_levels`): its noise is
    the sensor's, not the armature's, and as a regressor it would bias the fit and, as noise,
    swamp the current's; each mean's own error is carried into the estimates
    (:func:`_level_covariance`)."""
    i = np.asarray(log["i"], float)
    v = np.asarray(log["v"], float)
    held = held_levels(log.t, v)
    plateaus = []
    if held is not None:
        v = held.u
        plateaus = [(a, min(e, len(v) - 1), se) for a, e, se in held.plateaus if a < len(v) - 1]
    w = np.asarray(log["omega"], float) if log.has("omega") else np.zeros(len(i))
    X = np.column_stack([i[:-1], v[:-1], w[:-1], w[1:]])
    return X, i[1:], plateaus


def _simulated_current(A, th, starts, ends) -> np.ndarray:
    """i[k] simulated by the fitted difference equation from each log's voltage and speed
    (free of the current sensor's noise): the instrument for the regressor i[k]."""
    from scipy.signal import lfilter

    a = th[0]
    drive = A[:, 1:] @ th[1:]
    out = np.empty(len(A))
    for s0, e0 in zip(starts, ends, strict=True):
        i0 = A[s0, 0]
        # x[k] = i[k]: x[0] = i0, x[k+1] = a x[k] + drive[k]
        xs, _ = lfilter([1.0], [1.0, -a], drive[s0:e0 - 1], zi=[a * i0])
        out[s0] = i0
        out[s0 + 1:e0] = xs
    return out


def _measured(v: np.ndarray) -> bool:
    """True for a measured (noisy) voltage: it changes from sample to sample by more than a
    millionth of its range at most samples (a commanded, held input does not)."""
    d = np.abs(np.diff(v))
    span = float(np.ptp(v)) if len(v) else 0.0
    return bool(span > 0 and np.median(d) > 1e-6 * span)


def _neighbour_mean(v: np.ndarray, starts, ends) -> np.ndarray:
    """The instrument for a measured voltage v[k]: the mean of its neighbours v[k-1], v[k+1]
    (the log's own ends: the one neighbour). A measured voltage's noise at k biases the
    conductance g low and R high (errors in variables); its neighbours carry the same held
    level and none of that noise."""
    out = v.copy()
    for a, b in zip(starts, ends, strict=True):
        seg = v[a:b]
        if len(seg) < 3:
            continue
        z = np.empty_like(seg)
        z[1:-1] = 0.5 * (seg[:-2] + seg[2:])
        z[0], z[-1] = seg[1], seg[-2]
        out[a:b] = z
    return out


def _iv_regression(parts):
    """Least squares, then refined instrumental variables, on the stacked rows of every log
    (one offset column per log). Returns (theta, HAC covariance, residual, CovarianceInfo)."""
    X = np.concatenate([x for x, _, _ in parts])
    y = np.concatenate([t for _, t, _ in parts])
    ends = np.cumsum([len(t) for _, t, _ in parts])
    starts = ends - np.array([len(t) for _, t, _ in parts])
    ind = np.zeros((len(y), len(parts)))
    for k, (a, b) in enumerate(zip(starts, ends, strict=True)):
        ind[a:b, k] = 1.0
    A = np.column_stack([X, ind])
    scale = np.maximum(np.sqrt(np.mean(A**2, axis=0)), 1e-300)
    th = np.linalg.lstsq(A / scale, y, rcond=None)[0] / scale
    Z = A
    noisy_v = _measured(A[:, 1])
    for _ in range(IV_ITERATIONS):  # refined instrumental variables: the model's own current
        if not 0 < th[0] < 1:
            break
        Z = A.copy()
        Z[:, 0] = _simulated_current(A, th, starts, ends)
        if noisy_v:
            Z[:, 1] = _neighbour_mean(A[:, 1], starts, ends)
        th = np.linalg.lstsq((Z / scale).T @ (A / scale), (Z / scale).T @ y, rcond=None)[0] / scale
    r = A @ th - y
    s2 = float(r @ r) / max(len(y) - A.shape[1], 1)
    segs = [(k, int(a), int(b)) for k, (a, b) in enumerate(zip(starts, ends, strict=True))]
    ZZ = Z.T @ Z
    cov_z, info = block_covariance(Z, r, segs, np.linalg.pinv(ZZ) * s2)
    M = np.linalg.pinv(Z.T @ A) @ ZZ  # IV sandwich: (Z'A)^-1 S (A'Z)^-1
    cov = M @ cov_z @ M.T + _level_covariance(th, Z, A, parts, starts)
    return th, cov, r, info


def _level_covariance(th, Z, A, parts, starts) -> np.ndarray:
    """The covariance the plateau means of a noisy held voltage add to the estimates: a mean
    off by dv on its rows moves theta by -(Z'A)^-1 Z'[rows] 1 g dv (g = theta's conductance),
    and each mean is off by its standard error, independently."""
    G = [Z[s0 + a:s0 + e].sum(axis=0) * (th[1] * se)
         for (_, _, plateaus), s0 in zip(parts, starts, strict=True) for a, e, se in plateaus]
    if not G:
        return np.zeros((len(th), len(th)))
    G = np.linalg.pinv(Z.T @ A) @ np.array(G).T
    return G @ G.T


def _offsets(logs, th, cov, warns) -> dict[str, Estimate]:
    """Each log's voltage offset v0 = b/g [V] (brush drop or current-sensor offset) with its
    standard error; a significant one (3 std errors, over 1 % of the log's largest |v|) warned."""
    g = th[1]
    out = {}
    for k, lg in enumerate(logs):
        b = th[4 + k]
        grad = np.zeros(len(th))
        grad[1], grad[4 + k] = -b / g**2, 1.0 / g
        v0, v0_se = b / g, standard_error(float(grad @ cov @ grad))
        out[lg.path] = fitted(f"v0[{lg.path}]", v0, v0_se, "V")
        if abs(v0) > OFFSET_SIGMAS * v0_se and abs(v0) > 0.01 * float(np.max(np.abs(lg["v"]))):
            warns.append(f"{lg.path}: the current implies a voltage offset of {v0:.3g} ± "
                         f"{v0_se:.2g} V (a brush drop or a current-sensor offset; fitted "
                         "separately, not folded into R)")
    return out


def _physical(th: np.ndarray, dt: float) -> np.ndarray:
    """(a, g, c0, c1) -> (R [ohm], tau_e [s], ke [V s/rad]); tau_e NaN when a is not in (0, 1)."""
    a, g, c0, c1 = th[:4]
    r = (1 - a) / g
    tau = -dt / math.log(a) if 0 < a < 1 else math.nan
    return np.array([r, tau, -(c0 + c1) / g])


def _propagate(th, cov, dt):
    """Values and covariance of (R, tau_e, ke) by central differences (delta method)."""
    f0 = _physical(th, dt)
    p = len(th)
    Jf = np.zeros((3, p))
    for k in range(4):
        h = max(1e-6 * abs(th[k]), 1e-3 * math.sqrt(max(cov[k, k], 0.0)), 1e-15)
        hp, hm = th.copy(), th.copy()
        hp[k] += h
        hm[k] -= h
        Jf[:, k] = (_physical(hp, dt) - _physical(hm, dt)) / (2 * h)
    return f0, Jf @ cov @ Jf.T


def fit_free_running(logs, model: Model | None = None) -> FreeRunResult:
    """Fit R, L, ke to logs with ``t``, ``v``, ``i`` and (where the rotor turns) ``omega``.

    All logs must share one sample period. Raises :class:`FitError` when the logs do not
    separate R from ke (the voltage and the speed do not vary independently enough).
    """
    dts = np.array([lg.dt for lg in logs])
    dt = float(np.median(dts))
    if np.any(np.abs(dts - dt) > 1e-6 * dt):
        raise FitError("free-running logs at different sample periods ("
                       + ", ".join(f"{d * 1e3:.4g} ms" for d in sorted(set(dts))) + "): fit "
                       "each rate separately", ", ".join(lg.path for lg in logs))
    names = ", ".join(lg.path for lg in logs)
    parts = [_rows(lg) for lg in logs]
    if not any(np.ptp(x[:, 1]) > 1e-9 * np.max(np.abs(x[:, 1]), initial=0.0) for x, _, _ in parts):
        raise FitError("the voltage never changes in these logs: R, L and ke need a voltage "
                       "that changes (steps, a ramp) while the current is logged", names)
    th, cov, r, info = _iv_regression(parts)
    a, g = th[0], th[1]
    if not (g > 0 and math.isfinite(g)) or not a < 1:
        raise FitError("the free-running regression gives a non-positive conductance: check the "
                       "sign of the current column against the voltage (map it with -c "
                       "i=SRC*-1), or the logs do not excite the armature (constant voltage)",
                       names)
    vals, pcov = _propagate(th, cov, dt)
    se = standard_errors(pcov)  # NaN, never 0, where a variance is not positive
    R, tau, ke = vals
    warns: list[str] = []
    if not (math.isfinite(se[0]) and se[0] < 0.5 * R):
        raise FitError(f"R is not determined by these logs (R = {plus_minus(R, se[0])} ohm): the "
                       "voltage must vary (steps, a ramp) while the current is logged", names)
    a_se = standard_error(cov[0, 0])
    bound = not math.isfinite(tau)
    tau_at = None  # the lag simulations use where only a bound is known (below)
    if bound:  # a <= 0: only an upper bound on tau_e from a's upper confidence limit
        a_hi = min(max(a, 0.0) + 2 * a_se, 1 - 1e-12) if math.isfinite(a_se) else 1 - 1e-12
        tau = -dt / math.log(a_hi) if a_hi > 0 else dt / math.log(1e12)
        tau_se = tau
        # simulated as the regression's own estimate gives it (a <= 0: under a sample period),
        # never at the bound: a measured voltage's noise widens a's interval, and a lag at its
        # upper end is one the logs do not show (bench/newrigs.py freerun-vmeas seed 1, 1 kHz,
        # L/R 0.6 ms: simulated at the bound's 27 ms, the speed's fit took bc 31 % low at 6.7
        # standard errors and bv 2.3 x; at the estimate, bc -2.4 % and bv +3 %)
        tau_at = dt / math.log(1e12)
        if tau > MAX_TAU_ELECTRICAL:  # a's interval reaches 1: the logs bound no lag at all
            tau = MAX_TAU_ELECTRICAL
    else:
        tau_se = float(se[1])
    resolved = bool(not bound and tau >= MIN_TAU_SAMPLES * dt and tau_se < MAX_L_REL_SE * tau)
    L = tau * R
    L_se = L if bound else L * math.hypot(tau_se / tau, se[0] / R)
    turning = [lg.path for lg in logs if lg.has("omega") and rotor_turns(lg["omega"])]
    warns.append(f"{', '.join(turning)}: the rotor turns: fitted as free-running (v = R i + "
                 "L di/dt + ke omega), not as a blocked rotor")
    ke_ok = abs(ke) >= 2 * se[2]
    if not ke_ok:
        warns.append(f"the back-EMF constant is not resolved (ke = {plus_minus(ke, se[2])} V "
                     "s/rad): the speed varies too little against the voltage, or the current "
                     "does not see it; ke and the back_emf effect are not written")
    elif ke < 0:
        raise FitError(f"the back-EMF constant comes out negative (ke = {ke:.3g} ± {se[2]:.2g} "
                       "V s/rad): the speed and current columns have opposite sign conventions "
                       "(map one with -c omega=SRC*-1)", names)
    if not resolved:
        what = (f"L/R is under {tau * 1e3:.3g} ms (upper bound)" if bound else
                f"L/R = {tau * 1e3:.3g} ± {tau_se * 1e3:.2g} ms")
        had = model is not None and model.has("L")
        warns.append(f"L is not resolved by these logs: {what}, against a sample period of "
                     f"{dt * 1e3:.3g} ms (needs L/R >= {MIN_TAU_SAMPLES:g} periods, known to "
                     f"{MAX_L_REL_SE:.0%}: below that the value rests on the sub-sample timing "
                     "of the drive and the current sensor); "
                     + ("the model's L is kept" if had else
                        ("the interval from 0 to that bound is written" if bound else
                         "the fitted value is written with its standard error"))
                     + ": sample faster, or use a blocked-rotor log, to identify L")
    if ke_ok and ke > 0 and not (model is not None and model.has("km")):
        warns.append(KM_FROM_KE_NOTE.format(ke=ke))
    offsets = _offsets(logs, th, cov, warns)
    est = {"R": fitted("R", R, se[0], "ohm"), "L": fitted("L", L, L_se, "H"),
           "ke": fitted("ke", ke, se[2], "V s/rad"), "tau_e": fitted("tau_e", tau, tau_se, "s")}
    if bound:  # only an upper bound: the interval up to it, simulated at the estimate
        why = ("not resolved by these logs, L/R under the sample period (simulated as under "
               "one, as the regression's own estimate gives it): sample faster, or record a "
               "blocked-rotor log")
        if tau >= MAX_TAU_ELECTRICAL:  # no bound: simulating at its end would be a lag of 1 s
            why = ("not resolved by these logs: the current does not bound L/R below any "
                   f"motor's ({MAX_TAU_ELECTRICAL:g} s; a measured voltage's noise hides the "
                   "armature's lag), simulated as under one sample period, as the regression's "
                   "own estimate gives it: sample faster, or record a blocked-rotor log")
        est["L"] = bounded("L", 0.0, float(L), "H", why, float(tau_at * R))
        est["tau_e"] = bounded("tau_e", 0.0, float(tau), "s", why, float(tau_at))
    stats = FitStats(len(r), len(th), float(r @ r), 0, True)
    return FreeRunResult(est, offsets, [lg.path for lg in logs], stats, dt, resolved, bound,
                         bool(ke_ok), warns, info.describe())
