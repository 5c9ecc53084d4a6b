"""fit-mechanical: free-speed voltage steps -> Kmot, tau_mot -> b, J (paper section III-B), and
better: bv, bc from the affine steady-state line across amplitudes.

Per step (the speed omega [rad/s] after a voltage step dV [V]; several steps per log, up or down,
from rest or from a moving start, each up to the next change of input: :mod:`.mechsteps`):

- the paper's first-order model ``omega = Kmot dV (1 - exp(-(t - t0 - d)/tau_mot))`` (Strejc start,
  least-squares refinement), and its formulas b = km/(Kmot R), J = tau_mot b (eqs. 13-14);
- a second-order model with the electrical lag tau_e = L/R held: after breakaway (dead time d)
  ``J omega' + bv omega = km i(t) - bc`` with i rising as 1 - exp(-t/tau_e), whose solution is
  ``omega_ss (1 + a e^(-s/tau_e) - (1 + a) e^(-s/tau_m))``, a = beta tau_e/(tau_m - tau_e); beta < 1
  when the rotor breaks free after the current has partly risen (dead zone above Coulomb).

Across plateaus (every plateau where the rotor turns) the steady speed is affine in voltage
(Coulomb friction):
``omega_ss = (km/(R bv)) V - bc/bv``. The line's slope gives bv, its intercept bc, and
J = tau_m bv. The joint exact refinement (:func:`speed_from_rest`) uses the steps from rest only.
The paper's b lumps Coulomb friction into the viscous term (b > bv, and b depends on
the amplitude): it is reported and written as ``b``, but fit-nonlinear starts from bv, bc, J.

Torque steps (logs whose input is ``tau`` [N m], CONTRACT.md): ``tau = J omega' + bv omega +
bc sign(omega)`` gives J, bv and bc from the same fits with no motor constant: the torque is
the drive itself (km = R = 1, no electrical lag: :func:`torque_steps`). b, bv are then in
N m s/rad, bc in N m, J in kg m^2 and Kmot in rad/s per N m; no breakaway time (no current
rises) and no back-EMF. Voltage and torque logs are not mixed in one fit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import numpy as np

from pmdcid.errors import FitError, NoStepError
from pmdcid.fit.covariance import standard_error
from pmdcid.fit.results import (
    Estimate,
    FitStats,
    ResultProtocol,
    fitted,
    format_estimates,
    write_estimate,
)
from pmdcid.identify.inductance import carry_inductance_error
from pmdcid.identify.mechsteps import (  # noqa: F401 - paper_mechanical re-exported
    MOVE_SIGMAS,
    SETTLE_TAUS,
    MechStep,
    fit_step,
    head_level,
    paper_mechanical,
    speed_noise,
)
from pmdcid.identify.nonlinear_setup import MIN_SAMPLES, require_km
from pmdcid.identify.steps import MIN_PLATEAU_SAMPLES, despike, find_steps, held_head, lsq
from pmdcid.model import Model

STAGE = "fit-mechanical"
#: Coulomb friction's words where the steady speeds' line would make it negative
BC_AT_BOUND = ("at its bound 0, no standard error: the steady speeds' line passes above the "
               "origin, where Coulomb friction would be negative")
#: what a user can run on step logs fit-mechanical cannot use
BY_SIMULATION = "fit-nonlinear fits such logs by simulation error"


def speed_from_rest(s, torque, J, bv, bc, t_break, tau_e):
    """Speed [rad/s] after a voltage step from rest at s = 0 [s].

    The magnetic torque rises as ``torque (1 - exp(-s/tau_e))`` [N m]; the rotor is held until it
    reaches ``max(t_break, bc)`` (the dead zone's break point or static friction), then
    ``J omega' = torque(s) - bc - bv omega``. Exact solution; zero if the torque never breaks free.
    """
    s = np.asarray(s, float)
    T, sg = abs(torque), math.copysign(1.0, torque)
    brk = max(t_break, bc)
    if T <= brk or bv <= 0 or J <= 0:
        return np.zeros_like(s)
    sb = -tau_e * math.log1p(-brk / T)
    tm = J / bv
    if abs(tm - tau_e) < 1e-9 * tm:
        tm *= 1 + 1e-6
    wss = (T - bc) / bv
    a = (T / bv) * tau_e / (tm - tau_e)
    c = -(wss + a * math.exp(-sb / tau_e)) * math.exp(sb / tm)
    x = np.maximum(s, sb)
    w = wss + a * np.exp(-x / tau_e) + c * np.exp(-x / tm)
    return sg * np.where(s > sb, w, 0.0)


def steady_line(v: np.ndarray, w: np.ndarray, w_se: np.ndarray, *, origin: bool = False):
    """Weighted line |omega_ss| = a |V| + c [rad/s]: returns (a, c, cov 2x2). ``origin``: the
    line through the origin (c = 0, its row and column of ``cov`` zero): the least-squares line
    under Coulomb friction's bound bc >= 0 when the free line's intercept c is above zero."""
    X = np.column_stack([np.abs(v), np.ones(len(v))])[:, :1 if origin else 2]
    y = np.abs(w)
    wt = 1.0 / np.where(np.isfinite(w_se) & (w_se > 0), w_se, np.nanmedian(w_se) or 1.0)
    A = X * wt[:, None]
    coef, *_ = np.linalg.lstsq(A, y * wt, rcond=None)
    resid = (y - X @ coef) * wt
    dof = max(len(y) - X.shape[1], 1)
    s2 = max(float(resid @ resid) / dof, 1.0) if len(y) > X.shape[1] else 1.0
    cov = np.zeros((2, 2))
    cov[:X.shape[1], :X.shape[1]] = np.linalg.inv(A.T @ A) * s2
    c = 0.0 if origin else float(coef[1])
    return float(coef[0]), c, cov


@dataclass
class MechanicalResult(ResultProtocol):
    """b (paper), bv, bc, J with standard errors; the paper's Kmot, tau_mot; per-step fits."""

    estimates: dict[str, Estimate]
    steps: list[MechStep]
    stats: FitStats
    km_from_option: bool = False
    warnings: list[str] = field(default_factory=list)
    joint: bool = False  # bv, bc, J from the joint exact fit of all steps (else from the line)
    #: a lumped model's electrical lag the steps left open: below this [s] at two standard
    #: errors (:func:`pmdcid.identify.latency.step_lag`); NaN where they resolved it or never
    #: tried. fit-nonlinear then fits the current as instant (``steps_lag_bound`` in runners.py)
    lag_bound: float = math.nan

    #: the steps' input column: ``'v'`` (voltage steps) or ``'tau'`` (torque steps)
    drive: str = "v"

    @property
    def input_unit(self) -> str:
        return INPUT_UNIT[self.drive]

    def apply(self, model: Model) -> None:
        """Write b, bv, bc, J (stage 'fit-mechanical'); km with stage 'datasheet' if given."""
        if self.km_from_option:
            e = self.estimates["km"]
            model.set("km", e.value, math.nan, e.unit, stage="datasheet")
        for name in ("b", "bv", "bc", "J", "tau_e"):  # tau_e: a lumped model's lag
            e = self.estimates.get(name)
            if e is not None and e.vary and math.isfinite(e.value):
                write_estimate(model, e, STAGE)
        d = self.estimates.get("delay")  # the steps' latency (lumped: identify/latency.py)
        if d is not None and math.isfinite(d.value):
            model.add_effect("sensor_delay")
            model.set("delay", d.value, d.stderr, "s", stage=STAGE)
        fits = model.extra.setdefault("fits", {})
        fits[STAGE] = {
            "logs": list(dict.fromkeys(s.path for s in self.steps)),
            "Kmot": self.estimates["Kmot"].value, "tau_mot": self.estimates["tau_mot"].value,
            "breakaway_torque": _finite(self.estimates["T_break"].value),
            "skipped": [f"{s.path} at {s.t0:.4g} s" for s in self.steps
                        if not s.moved and not s.head],
        }
        if math.isfinite(self.lag_bound):
            fits[STAGE]["tau_e_bound"] = self.lag_bound
        self._keep_lumped(model)

    def table(self) -> str:
        lines = ["fit-mechanical: free-speed steps", ""]
        lines.append(f"{'log':<22} {'t0 s':>6} {self.input_unit:>5} {'from':>5} {'Kmot':>8} "
                     f"{'tau_mot':>8} "
                     f"{'b paper':>9} {'w_ss':>8} {'tau_m':>8} {'dead ms':>7}")
        for s in self.steps:
            name = s.path if len(s.path) <= 22 else "..." + s.path[-19:]
            name = f"{name:<22} {s.t0:6.4g}"
            if s.head:
                lines.append(f"{name} {s.level:5.3g} start (turning: the level held before "
                             f"the first step) w_ss {s.omega_ss:.4g} +- {s.omega_ss_se:.2g}")
                continue
            if not s.moved:
                why = {"did not move": "did not move (below the dead zone / breakaway)",
                       "coasts to rest": "decays to rest",
                       }.get(s.note, s.note or "did not move")
                lines.append(f"{name} {s.level:5.3g}  {why}: not used")
                continue
            lines.append(f"{name} {s.level:5.3g} {'rest' if s.from_rest else 'moving':>5} "
                         f"{s.kmot:8.4g} {s.tau_mot:8.4g} "
                         f"{s.b:9.4g} {s.omega_ss:8.4g} {s.tau_m:8.4g} "
                         f"{1e3 * s.dead_time:7.3g}")
        lines.append("")
        lines.append("paper (first order, Coulomb lumped into b): b = km/(Kmot R), "
                     "J = tau_mot b" if self.drive == "v" else
                     "first order, Coulomb lumped into b: b = 1/Kmot, J = tau_mot b")
        lines += format_estimates([self.estimates[k] for k in ("Kmot", "tau_mot", "b",
                                                                "J_paper")])[1:]
        lines.append("")
        lines.append("affine steady-state line w_ss = (km/(R bv)) V - bc/bv, "
                     "second-order steps (tau_e held), J = tau_m bv:" if self.drive == "v" else
                     "affine steady-state line w_ss = tau/bv - bc/bv, first-order steps, "
                     "J = tau_m bv:")
        sfx = "_line" if self.joint else ""
        lines += format_estimates([self.estimates[k + sfx] for k in ("bv", "bc", "J")])[1:]
        if self.joint:
            lines.append("")
            lines.append("joint exact fit of all steps (shared J, bv, bc, breakaway torque), "
                         "written to the model:")
            lines += format_estimates([self.estimates[k] for k in ("bv", "bc", "J")])[1:]
        if math.isfinite(self.estimates["T_break"].value):  # none per volt or per N m
            lines += format_estimates([self.estimates["T_break"]])[1:]
        if "delay" in self.estimates:  # latency: a dead time with no electrical lag
            lines += format_estimates([self.estimates["delay"]])[1:]
        return "\n".join(lines)


def _finite(x):
    return x if math.isfinite(x) else None


#: the unit of each drive's input, as the tables and messages say it
INPUT_UNIT = {"v": "V", "tau": "N m"}


def _why_no_step(steps) -> str:
    """Why none of ``steps`` gave a speed response fit-mechanical can use, in the user's terms."""
    notes = {s.note for s in steps}
    if "plateau too short" in notes:
        return ("the input is not held long enough for the speed to settle (record longer "
                f"plateaus); {BY_SIMULATION}")
    if not steps:
        return ("the input holds no step (fit-mechanical needs voltage or torque steps held "
                "until the speed settles)")
    if notes == {"coasts to rest"}:
        return ("every step lets the rotor coast to rest (a step to 0 or into the dead zone): "
                "fit-mechanical needs steps that drive it to a steady speed; fit-nonlinear and "
                "identify can use a coast-down log")
    return ("no step moves the rotor: fit-mechanical needs steps above the dead zone (larger "
            "inputs)")


def fit_mechanical(logs, model: Model, km: float | None = None, *,
                   joint: bool = True) -> MechanicalResult:
    """Fit the free-speed step logs (``t``, ``v``, ``omega``; one or more steps each, from rest
    or from a moving start: :func:`~pmdcid.identify.steps.find_steps`).

    Needs R and L in ``model`` (fit-electrical) and km from ``km`` [N m/A] or the model.
    Raises :class:`~pmdcid.errors.ModelError` when they are missing, :class:`FitError` when no
    step moves the rotor. When the model's L is poorly determined, the steps are fitted again at
    L minus and plus its standard error and half the spread of J, bv, bc enters their errors.
    Torque step logs (``t``, ``tau``, ``omega``) need nothing from the model: :func:`torque_steps`.
    """
    if _drive_of(logs) == "tau":
        res = torque_steps(logs)
        if km is not None:
            res.warnings.append(f"km = {km:g} N m/A is not used: torque steps give J, bv, bc "
                                "without it (and it is not written)")
        return res
    res = _fit_mechanical(logs, model, km, joint)
    carry_inductance_error(res, model, lambda m: _fit_mechanical(logs, m, km, joint).estimates)
    return res


def _drive_of(logs) -> str:
    """The drive of every log (``'v'`` or ``'tau'``); a mix of both refused."""
    drives = {lg.drive for lg in logs}
    if len(drives) > 1:
        raise FitError("fit-mechanical fits voltage steps or torque steps, not both at once: "
                       "give the voltage logs and the torque logs to separate runs",
                       ", ".join(lg.path for lg in logs))
    return drives.pop() if drives else "v"


def torque_steps(logs) -> MechanicalResult:
    """fit-mechanical on torque step logs [N m]: the steps' fits with km = R = 1 and no
    electrical lag (the torque is the drive), so b, bv [N m s/rad], bc [N m] and J [kg m^2]
    come out in SI with no motor constant. No joint refinement and no breakaway torque: both
    time the rotor's breakaway by the current's rise, which a torque drive does not have."""
    work = Model()
    work.set("R", 1.0)
    work.set("L", TORQUE_LAG)
    res = _fit_mechanical(logs, work, 1.0, joint=False)
    res.km_from_option = False
    res.drive = "tau"
    del res.estimates["km"]
    res.estimates["Kmot"].unit = "rad/s/(N m)"
    tb = res.estimates["T_break"]
    res.estimates["T_break"] = Estimate("T_break", math.nan, math.nan, tb.unit)
    return res


#: the electrical lag [s] the step fits hold for torque steps: none (1 ns keeps the
#: second-order form's two time constants apart), as for a lumped model's per-volt steps
TORQUE_LAG = 1e-9


def _fit_mechanical(logs, model: Model, km, joint) -> MechanicalResult:
    model.require("R", "L", stage="fit-mechanical")
    km_given = km is not None
    if km is None:
        require_km(model, logs, "fit-mechanical")
        km = model.value("km")
    elif not (math.isfinite(km) and km > 0):
        raise FitError(f"--km must be a positive torque constant in N m/A, got {km:g}")
    if not logs:
        raise FitError("fit-mechanical needs at least one free-speed step log")
    R, L = model.value("R"), model.value("L")
    tau_e = L / R
    warns: list[str] = []
    steps: list[MechStep] = []
    data: list[tuple] = []  # steps from rest: (time from onset, speed, torque amplitude, noise)
    no_step: list[FitError] = []  # logs whose input holds no step
    heads: list[tuple] = []  # logs that start turning at a held level: (log, step, w, sig)
    for log in logs:
        what = "torque" if log.drive == "tau" else "voltage"
        log.require("omega", purpose=f"fit-mechanical ({what} step and rotor speed)")
        w, bad = despike(log["omega"])
        if len(bad):
            k = int(bad[np.argmax(np.abs(np.asarray(log["omega"])[bad] - w[bad]))])
            warns.append(f"{log.path}: {len(bad)} isolated speed spike(s) (e.g. "
                         f"{log['omega'][k]:.4g} rad/s at t = {log.t[k]:.4g} s) replaced by "
                         "the median of their neighbours")
            log = replace(log, data={**log.data, "omega": w})
        sig = speed_noise(w)
        # a log that starts at rest may hold its step from the first sample (the input applied
        # as logging starts, e.g. lego-ev3): a step from 0 there. At rest: the first speed
        # within the noise or a fifth of the log's largest (a speed derived from the angle by
        # a zero-phase filter already rises at the first sample)
        at_rest = abs(float(w[0])) <= max(MOVE_SIGMAS * sig, 0.2 * float(np.max(np.abs(w))))
        try:
            found = find_steps(log.t, log.u, log.path, at_start=at_rest)
        except FitError as exc:  # used when another log holds steps: a warning then
            no_step.append(exc)
            continue
        if not at_rest and held_head(log.u, found[0]):
            heads.append((log, found[0], w, sig))
        for step in found:
            ms, d = fit_step(log, step, tau_e, km, R, sig, warns)
            steps.append(ms)
            if d is not None:
                data.append(d)
    if no_step and not steps:
        _refuse_short(logs)
        raise NoStepError("no log holds a voltage step (an input held at a level; a measured "
                          f"voltage that sags with the load is not): {BY_SIMULATION}",
                          ", ".join(lg.path for lg in logs))
    warns += [f"{exc}: not used ({BY_SIMULATION})" for exc in no_step]
    _still_warnings(steps, warns)
    _short_warnings(steps, warns)
    moving = [s for s in steps if s.moved]
    if not moving:
        why = _why_no_step(steps)
        kind = NoStepError if BY_SIMULATION in why else FitError
        raise kind("no usable step: " + why, ", ".join(lg.path for lg in logs))
    steps = _head_levels(heads, moving) + steps
    ndata = sum(s.ndata for s in moving)
    chisqr = sum(s.chisqr for s in moving)
    ke = model.value("ke") if "back_emf" in model.effects and model.has("ke") else 0.0
    b_emf = km * ke / R
    res = _combine(moving, steps, km, R, tau_e, km_given, ndata, chisqr, warns, b_emf)
    if b_emf > 0:
        res.warnings.append(f"the model has back-EMF (ke = {ke:.4g} V s/rad): its damping km ke/R "
                            f"= {b_emf:.3g} N m s/rad is taken out of the steady-speed line's to "
                            "give bv, and J is read from the steps' slow time constant with the "
                            "current coupled to the speed; the joint refinement from rest (no "
                            "back-EMF) is skipped")
    elif joint and len({round(abs(s.amplitude), 9) for s in moving if s.from_rest}) >= 2:
        _joint(res, data, tau_e)
        b, bv = res.estimates["b"].value, res.estimates["bv"].value
        if b > 1.02 * bv:
            res.warnings.append(f"the paper's b = {b:.4g} exceeds the viscous bv = {bv:.4g} "
                                "N m s/rad: Coulomb friction is lumped into b (it varies with "
                                "the step amplitude)")
    return res


def _head_levels(heads, moving) -> list[MechStep]:
    """The levels the logs that start turning hold before their first step
    (:func:`~pmdcid.identify.mechsteps.head_level`), read with the steps' mechanical time
    constant: a second point on the steady-speed line from a log with one step."""
    if not heads or not moving:
        return []
    tm, tm_se = _mean_se(np.array([s.tau_m for s in moving]),
                         np.array([s.tau_m_se for s in moving]))
    out = []
    for log, step, w, sig in heads:
        h = head_level(log, step, w, sig, tm, tm_se)
        # a level that drives the rotor (a coast at 0 V or inside the dead zone ends at rest,
        # off the line): turning its way, its steady speed clear of the noise and of its error
        if (h is not None and math.isfinite(h.omega_ss) and h.level * h.omega_ss > 0
                and abs(h.omega_ss) > MOVE_SIGMAS * max(h.omega_ss_se, sig)):
            out.append(h)
    return out


def _refuse_short(logs) -> None:
    """Every log too short to hold a step, or too short for fit-nonlinear (the stage "no step"
    points to): said as such."""
    n = max(lg.n for lg in logs)
    paths = ", ".join(lg.path for lg in logs)
    if n < MIN_PLATEAU_SAMPLES:
        raise FitError(f"too short ({n} samples) to hold a step response (at least "
                       f"{MIN_PLATEAU_SAMPLES}: a step and the speed settling after it)", paths)
    if n < MIN_SAMPLES:
        raise FitError(f"no log holds a voltage step, and at {n} samples the logs are too short "
                       f"for fit-nonlinear too (at least {MIN_SAMPLES}): record longer logs",
                       paths)


def _still_warnings(steps, warns) -> None:
    """One warning per kind of step left out because the rotor is at rest on its plateau."""
    for note, what in (("did not move", "below the dead zone / breakaway torque: the input does "
                        "not move the rotor"),
                       ("coasts to rest", "the plateau is at rest after a decay (Coulomb "
                        "friction may end a decay early: not a first-order response)")):
        where = [f"{s.path} at {s.t0:.4g} s ({s.level:.3g} {s.unit})" for s in steps
                 if s.note == note]
        if where:
            warns.append(f"{what}: {'; '.join(where)}: reported, not fitted")


def _short_warnings(steps, warns) -> None:
    """One warning per log for the steps whose input holds under
    :data:`~pmdcid.identify.mechsteps.SETTLE_TAUS` time constants (a rich log, an APRBS, holds
    dozens: the table lists each)."""
    short: dict[str, list[MechStep]] = {}
    for s in steps:
        if s.short is not None:
            short.setdefault(s.path, []).append(s)
    end = f"the speed does not settle; refused (not used: {BY_SIMULATION})"
    for path, group in short.items():
        held, tau = (np.array(x) for x in zip(*(s.short for s in group), strict=True))
        if len(group) == 1:
            s = group[0]
            warns.append(f"{path} (step to {s.level:.3g} {s.unit} at t = {s.t0:.4g} s): the input "
                         f"holds {held[0]:.3g} s, under {SETTLE_TAUS:g} time constants "
                         f"({tau[0]:.3g} s): {end}")
            continue
        warns.append(f"{path}: {len(group)} steps (at t = {group[0].t0:.4g} ... "
                     f"{group[-1].t0:.4g} s) hold their input {_span(held)} s, under "
                     f"{SETTLE_TAUS:g} of their time constants ({_span(tau)} s): {end}")


def _span(x: np.ndarray) -> str:
    lo, hi = float(np.min(x)), float(np.max(x))
    return f"{lo:.3g}" if f"{lo:.3g}" == f"{hi:.3g}" else f"{lo:.3g}-{hi:.3g}"


def _joint(res: MechanicalResult, data, tau_e) -> None:
    """Refine J, bv, bc and the breakaway torque jointly over all moving steps with the exact
    step response (:func:`speed_from_rest`), starting from the line; replaces the estimates."""
    est = res.estimates
    x0 = [est["J"].value, est["bv"].value, max(est["bc"].value, 0.0),
          max(est["T_break"].value, est["bc"].value)]
    if not all(math.isfinite(v) and v >= 0 for v in x0) or x0[0] <= 0 or x0[1] <= 0:
        return

    def resid(x):
        return np.concatenate([(speed_from_rest(sk, T, *x, tau_e) - w) / sig
                               for sk, w, T, sig in data])

    lo = np.array([1e-3 * x0[0], 1e-3 * x0[1], 0.0, 0.0])
    hi = np.array([1e3 * x0[0], 1e3 * x0[1], np.inf, np.inf])
    if x0[2] == 0.0:
        x0[2] = 1e-3 * max(abs(T) for _, _, T, _ in data)
    x0[3] = max(x0[3], x0[2])
    # the breakaway torque delays each response by a time that, sampled slowly, is a fraction of
    # a sample: the cost has side minima in it (e.g. just below the smallest step's torque, which
    # then barely starts); start from the best of a grid from bc to the largest step's torque
    grid = np.linspace(x0[2], max(abs(T) for _, _, T, _ in data), 41)
    costs = [float(np.sum(resid([x0[0], x0[1], x0[2], g]) ** 2)) for g in grid]
    if min(costs) < float(np.sum(resid(x0) ** 2)):
        x0[3] = float(grid[int(np.argmin(costs))])
    ends = np.cumsum([len(w) for _, w, _, _ in data])
    cf = lsq(resid, x0, lo, hi, ("J", "bv", "bc", "T_break"),
             segments=[(k, int(e - len(d[1])), int(e)) for k, (d, e)
                       in enumerate(zip(data, ends, strict=True))])
    if not cf.success or not np.all(np.isfinite(cf.values)):
        res.warnings.append("the joint fit of the steps did not converge: bv, bc, J from the "
                            "steady-speed line are written")
        return
    for k, unit in (("bv", "N m s/rad"), ("bc", "N m"), ("J", "kg m^2")):
        est[f"{k}_line"] = Estimate(f"{k}_line", est[k].value, est[k].stderr, unit)
        est[k] = Estimate(k, cf[k], cf.se(k), unit)
    est["T_break"] = Estimate("T_break", max(cf["T_break"], cf["bc"]), cf.se("T_break"), "N m")
    res.joint = True
    res.stats = FitStats(cf.ndata, 4, cf.sigma**2 * max(cf.ndata - 4, 1), 0, cf.success)
    if cf.sigma > 3:
        res.warnings.append(f"the steps leave a residual {cf.sigma:.2g} times their noise: the "
                            "model misses something (Stribeck friction, back-EMF: try diagnose)")


def _mean_se(x: np.ndarray, se: np.ndarray | None = None) -> tuple[float, float]:
    """Mean and its standard error (scatter-based; inverse-variance weighted if ``se``);
    non-finite values are left out (NaN when none is left)."""
    x = np.asarray(x, float)
    ok = np.isfinite(x)
    if not ok.any():
        return math.nan, math.nan
    x = x[ok]
    se = None if se is None else np.asarray(se, float)[ok]
    if se is not None and np.all(np.isfinite(se)) and np.all(se > 0):
        w = 1.0 / np.asarray(se) ** 2
        m = float(np.sum(w * x) / np.sum(w))
        e = math.sqrt(1.0 / float(np.sum(w)))
        if len(x) > 1:  # inflate by the scatter if it is larger than the stated errors
            chi = float(np.sum(w * (x - m) ** 2)) / (len(x) - 1)
            e *= math.sqrt(max(chi, 1.0))
        return m, e
    return float(np.mean(x)), (float(np.std(x, ddof=1)) / math.sqrt(len(x))
                               if len(x) > 1 else math.nan)


def line_friction(a: float, c: float, cov: np.ndarray, km: float, R: float, b_emf: float):
    """(d_eff, bv, bv_se, bc, bc_se) from the steady-speed line |omega_ss| = a |V| + c
    (:func:`steady_line`: a [rad/s/V], c [rad/s], their 2x2 covariance ``cov``): the total
    damping d_eff = km/(R a) [N m s/rad] (viscous plus the back-EMF's ``b_emf`` = km ke/R),
    bv = d_eff - b_emf, bc = -c d_eff [N m], the errors propagated (delta method) by the one
    rule (:func:`pmdcid.fit.covariance.standard_error`: NaN, never 0, where a variance is not
    positive)."""
    d_eff = km / (R * a)
    # d(bc) = -d_eff dc - c d(d_eff); d(d_eff) = -d_eff/a da
    g = np.array([c * d_eff / a, -d_eff])
    return (d_eff, d_eff - b_emf, d_eff * standard_error(cov[0, 0]) / a, -c * d_eff,
            standard_error(float(g @ cov @ g)))


def _line_estimates(v, w, w_se, motor: tuple, est: dict, warns: list) -> tuple:
    """bv and bc from the steps' steady speeds (levels ``v``, speeds ``w`` and their errors),
    written into ``est``; ``motor`` = (km, R, b_emf). Returns (d_eff, bv, bv_se)."""
    km, R, b_emf = motor
    a, c, cov = steady_line(v, w, w_se)
    if a <= 0:
        raise FitError("steady speed does not grow with the input across the steps: check "
                       "the sign and scale of the speed column")
    d_eff, bv, bv_se, bc, bc_se = line_friction(a, c, cov, km, R, b_emf)
    est["bv"] = fitted("bv", bv, bv_se, "N m s/rad")
    est["bc"] = fitted("bc", bc, bc_se, "N m")
    if bc < 0:  # bc >= 0: the least-squares line under that bound passes through the origin
        warns.append(f"the steady-speed line gives a negative Coulomb friction bc = {bc:.3g} N m "
                     "(intercept above zero: the speed grows less than in proportion to the "
                     "input, a speed law the model lacks, or noise): bc is written at its bound "
                     "0 and bv is read on the line through the origin")
        d_eff, bv, bv_se, _, _ = line_friction(*steady_line(v, w, w_se, origin=True), km, R,
                                               b_emf)
        est["bv"] = fitted("bv", bv, bv_se, "N m s/rad")
        est["bc"] = Estimate("bc", 0.0, math.nan, "N m", caveat=BC_AT_BOUND)
    return d_eff, bv, bv_se


def slow_pole_inertia(tau_m: float, d_eff: float, b_emf: float, tau_e: float) -> float:
    """J [kg m^2] of a motor whose step responses' slow time constant is ``tau_m`` [s], with the
    total damping ``d_eff`` = bv + km ke/R [N m s/rad], the back-EMF's part ``b_emf`` = km ke/R
    and the armature's lag ``tau_e`` = L/R [s].

    The step fits hold the current's rise at tau_e, as if the current did not depend on the
    speed; with back-EMF it does, and the poles are those of
    ``L J s^2 + (R J + L bv) s + R d_eff``, whose slow one lies below J/d_eff by about tau_e
    times the back-EMF's share of the damping: on a small motor whose back-EMF makes most of its
    damping, at tau_e/tau_m = 3 %, J = tau_m d_eff was 3 % low, 15-22 standard errors
    (tests/identify/test_mechanical.py). That polynomial at s = -1/tau_m gives
    ``J = tau_m (d_eff tau_m - tau_e bv)/(tau_m - tau_e)``; without back-EMF (bv = d_eff) it
    is tau_m d_eff, the model's own relation."""
    if not (b_emf > 0 and tau_m > tau_e > 0):
        return tau_m * d_eff
    bv = max(d_eff - b_emf, 0.0)
    return tau_m * (d_eff * tau_m - tau_e * bv) / (tau_m - tau_e)


def _combine(moving, steps, km, R, tau_e, km_given, ndata, chisqr, warns, b_emf=0.0):
    """Means over steps, the steady-speed line, J. ``b_emf`` = km ke/R [N m s/rad]: the damping
    the back-EMF adds (model effect back_emf), taken out of the line's damping to give bv."""
    kmot, kmot_se = _mean_se(np.array([s.kmot for s in moving]))
    tmot, tmot_se = _mean_se(np.array([s.tau_mot for s in moving]))
    b, b_se = _mean_se(np.array([s.b for s in moving]))
    if b < 0:  # km/Kmot - km^2/R: the speed per volt exceeds what the back-EMF allows
        raise FitError(
            f"the steps give a non-positive damping b = {b:.3g} N m s/rad: the speed does not "
            "follow the input as a motor's does; check the speed's sign against the input "
            "(-c omega=COLUMN*-1), the input's offset, and km",
            ", ".join(dict.fromkeys(s.path for s in moving)))
    jp, jp_se = _mean_se(np.array([s.J_paper for s in moving]))
    tm, tm_se = _mean_se(np.array([s.tau_m for s in moving]), np.array([s.tau_m_se
                                                                         for s in moving]))
    levels = moving + [s for s in steps if s.head]  # the logs' starting levels too
    v = np.array([s.level for s in levels])
    w = np.array([s.omega_ss for s in levels])
    w_se = np.array([s.omega_ss_se for s in levels])
    est = {"km": Estimate("km", km, math.nan, "N m/A", vary=False),
           "Kmot": Estimate("Kmot", kmot, kmot_se, "rad/s/V"),
           "tau_mot": Estimate("tau_mot", tmot, tmot_se, "s"),
           "b": Estimate("b", b, b_se, "N m s/rad"),
           "J_paper": Estimate("J_paper", jp, jp_se, "kg m^2")}
    if len(np.unique(np.round(np.abs(v), 9))) >= 2:
        d_eff, bv, bv_se = _line_estimates(v, w, w_se, (km, R, b_emf), est, warns)
    else:
        warns.append("all steps have the same amplitude: Coulomb friction cannot be separated "
                     "from viscous; bv = b (paper) and bc = 0 are written")
        d_eff, bv, bv_se = b, b - b_emf, b_se
        est["bv"] = Estimate("bv", bv, b_se, "N m s/rad")
        est["bc"] = Estimate("bc", 0.0, math.nan, "N m")
    if bv < 0:
        warns.append(f"the back-EMF damping km ke/R = {b_emf:.3g} N m s/rad exceeds the steps' "
                     f"total damping {d_eff:.3g}: km, ke or R is off; bv set to 0")
        est["bv"] = Estimate("bv", 0.0, bv_se, "N m s/rad")
    if not math.isfinite(tm):
        raise FitError("no step shows a transient in its samples (each speed at its level from "
                       "the first sample): J cannot be read from these steps",
                       ", ".join(dict.fromkeys(s.path for s in moving)))
    J = slow_pole_inertia(tm, d_eff, b_emf, tau_e)
    J_se = J * math.hypot(tm_se / tm, bv_se / d_eff if d_eff else 0.0)
    est["J"] = Estimate("J", J, J_se, "kg m^2")
    # the breakaway torque from the delays of steps from rest only (a moving rotor has none)
    tb = [km * abs(s.amplitude) / R * -math.expm1(-s.dead_time / tau_e) for s in moving
          if s.from_rest]
    est["T_break"] = Estimate("T_break", float(np.median(tb)) if tb else math.nan,
                              float(np.std(tb, ddof=1) / math.sqrt(len(tb)))
                              if len(tb) > 1 else math.nan, "N m")
    if not tb:
        warns.append("no step starts from rest: the breakaway and the dead zone are not seen by "
                     "these steps (no T_break, no dz written); a step from rest or through zero "
                     "shows them")
    stats = FitStats(ndata, 5 * len(moving), chisqr)
    return MechanicalResult(est, steps, stats, km_given, warns)
