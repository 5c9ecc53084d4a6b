"""Choose and size the profiles of an identification plan.

Candidates (:mod:`.profiles`) are sized within the input limit and, by simulating the model, the
speed limit; then the recording time is shared among them in the proportions that minimise the
worst relative standard error among the identified parameters (the information of a profile
taken as proportional to its length, from one unit of it). Each profile is its unit repeated,
the last repeat cut short, to its share; the predicted standard errors are then recomputed on
the final profiles exactly (:mod:`.fisher`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from pmdcid.errors import ModelError
from pmdcid.model import Model
from pmdcid.plan import fisher as fi
from pmdcid.plan import profiles as pr
from pmdcid.plan.effect_errors import effect_table

#: default budget [s], rate [Hz]
BUDGET = 120.0
RATE = 1000.0
#: default noise, when not given: this fraction of the plan's top speed / current
NOISE_FRACTION = 0.01
#: default input limit without --vmax/--taumax: this multiple of the breakaway input
DEFAULT_UMAX_BREAKAWAY = 3.0


@dataclass
class Settings:
    """Plan options: input limit ``umax`` (V or N m; None: default), ``speed_max`` [rad/s],
    ``rate`` [Hz], ``budget`` [s], noise std ``noise_omega`` [rad/s] and ``noise_i`` [A]
    (None: default), ``taumax`` when the limit is a torque, ``effects`` for the effect table."""

    umax: float | None = None
    speed_max: float = math.inf
    rate: float = RATE
    budget: float = BUDGET
    noise_omega: float | None = None
    noise_i: float | None = None
    taumax: bool = False
    effects: bool = True  # also the catalogue-effect table


@dataclass
class Plan:
    """Profiles to record and what they predict (absolute standard errors, SI)."""

    profiles: list[pr.Profile]
    drive: fi.Drive
    names: list[str]
    values: dict[str, float]
    stderr: dict[str, float]
    noise: dict[str, float]
    umax: float
    umax_default: bool = False
    speed_max: float = math.inf
    effects: list[dict] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    guess: bool = False
    sens: list[dict[str, np.ndarray]] = field(default_factory=list, repr=False)

    @property
    def seconds(self) -> float:
        return sum(p.seconds for p in self.profiles)

    def relative(self) -> dict[str, float]:
        return {n: (self.stderr[n] / abs(self.values[n]) if self.values[n] else math.inf)
                for n in self.names}

    def __repr__(self) -> str:  # one line, no arrays (a notebook's pmdcid.plan(...))
        rel = ", ".join(f"{n} ± {100 * r:.2g} %" for n, r in self.relative().items()
                        if math.isfinite(r))
        return (f"Plan({len(self.profiles)} profiles, {self.seconds:.1f} s: "
                f"{', '.join(p.name for p in self.profiles)}{'; ' + rel if rel else ''})")

    def worst(self, among=None) -> tuple[str, float]:
        rel = {n: r for n, r in self.relative().items() if among is None or n in among}
        name = max(rel, key=rel.get)
        return name, rel[name]


# --- scales of the motor -------------------------------------------------------------------------

def time_constants(vals: dict[str, float], drive: fi.Drive) -> tuple[float, float]:
    """(electrical L/R, mechanical J/bv) [s]; the mechanical one 1 s without viscous friction."""
    te = vals["L"] / vals["R"] if drive.electrical else 0.0
    tm = vals["J"] / vals["bv"] if vals.get("bv", 0.0) > 0 else 1.0
    return te, float(np.clip(tm, 1e-3, 10.0))


def breakaway_input(vals: dict[str, float], drive: fi.Drive) -> float:
    """Input (V or N m) whose steady torque reaches the breakaway max(bc + fs, dz)."""
    tb = max(vals.get("bc", 0.0) + vals.get("fs", 0.0), vals.get("dz", 0.0))
    return tb * vals["R"] / vals["km"] if drive.electrical else tb


def parameter_scales(vals: dict[str, float], drive: fi.Drive, speed: float) -> dict[str, float]:
    """Typical size of a zero-valued parameter (finite-difference steps), by its unit."""
    from pmdcid.model.effects import effect_param_specs
    from pmdcid.model.spec import BASE_PARAMS

    torque = max(vals.get("bc", 0.0) + vals.get("bv", 0.0) * speed, vals.get("dz", 0.0), 1e-12)
    by_unit = {"N m": torque, "rad/s": speed, "N m s/rad": torque / speed,
               "N m s^2/rad^2": torque / speed**2, "s": 1e-3, "V": 1.0, "V s/rad": 1.0 / speed}
    specs = {**BASE_PARAMS, **effect_param_specs()}
    return {n: by_unit.get(sp.unit, 1.0) for n, sp in specs.items()}


# --- sizing --------------------------------------------------------------------------------------

def size_to_speed(make_u, amp: float, vals, drive, speed_max: float, rate: float):
    """Scale ``amp`` down until the simulated |omega| stays within ``speed_max``.

    ``make_u(amp)`` gives the profile unit. Returns (u, amp, peak speed [rad/s]).
    """
    for _ in range(8):
        u = make_u(amp)
        t = np.arange(len(u)) / rate
        peak = float(np.max(np.abs(fi.simulate_profile(t, u, vals, drive, False).omega)))
        if peak <= speed_max:
            break
        amp *= 0.95 * speed_max / peak
    return u, amp, peak


def candidates(vals, drive: fi.Drive, umax: float, speed_max: float, rate: float,
               with_blocked: bool) -> list[tuple[str, np.ndarray, bool]]:
    """Profile units (kind, u, blocked) sized within ``umax`` and ``speed_max``."""
    te, tm = time_constants(vals, drive)
    ub = breakaway_input(vals, drive)
    makers = {
        "steps": lambda a: pr.free_steps(a, tm, rate),
        "triangle": lambda a: pr.triangle(a, max(40 * tm, 4.0), rate),  # quasi-static
        "staircase": lambda a: pr.staircase(ub if ub > 0 else 0.3 * a, a, tm, rate),
        "levels": lambda a: pr.levels(ub if ub > 0 else 0.3 * a, a, tm, rate),
        "slow_triangle": lambda a: pr.slow_triangle(ub if ub > 0 else 0.3 * a, a, tm, rate),
        "prbs": lambda a: pr.prbs(a, tm, rate),
    }
    out = [("blocked", pr.blocked_step(umax, te, rate), True)] if with_blocked else []
    for kind, mk in makers.items():
        u, _, _ = size_to_speed(mk, umax, vals, drive, speed_max, rate)
        out.append((kind, u, False))
    return out


# --- information and the greedy allocation -------------------------------------------------------

def profile_sens(t, u, blocked, vals, names, drive, scales, signals=None):
    return fi.sensitivities(t, u, vals, names, drive, blocked, scales, signals)


def allocate(unit_F: list[np.ndarray], unit_s: list[float], budget: float, values: np.ndarray,
             targets: np.ndarray, fixed: list[bool]) -> list[float]:
    """Seconds of each profile for ``budget`` seconds.

    ``fixed`` profiles get one unit; the rest of the budget is shared out in the proportions
    minimising the worst relative standard error (:func:`optimal_shares`). A profile given less
    than one unit (a part of a cycle does not carry a whole one's information: half a triangle
    visits one direction only) is, one at a time, either dropped or given exactly one unit,
    whichever leaves the lower worst relative standard error once the rest is shared again.
    """
    seconds = [unit_s[k] if fixed[k] else 0.0 for k in range(len(unit_F))]
    left = max(budget - sum(seconds), 0.0)
    F0 = sum((unit_F[k] for k in range(len(unit_F)) if fixed[k]),
             np.zeros_like(unit_F[0]))
    kept = [k for k in range(len(unit_F)) if not fixed[k]]

    def solve(ks, F, room):
        w = optimal_shares([unit_F[k] / unit_s[k] for k in ks], F, room, values, targets)
        G = F + sum((wk * unit_F[k] / unit_s[k] for wk, k in zip(w, ks, strict=True)),
                    np.zeros_like(F))
        return w, worst_relative(G, values, targets)

    kept = [k for k in kept if unit_s[k] <= left + 1e-9]  # a whole unit must fit
    shares, _ = solve(kept, F0, left) if kept else (np.zeros(0), math.inf)
    while kept:
        short = [(shares[j] / unit_s[k], k) for j, k in enumerate(kept)
                 if shares[j] < unit_s[k] * (1.0 - 1e-9)]
        if not short:
            break
        options = []
        for _, k in sorted(short)[:3]:  # the three furthest below one unit
            rest = [i for i in kept if i != k]
            w, obj = solve(rest, F0, left) if rest else (np.zeros(0), math.inf)
            options.append((obj, k, False, w))
            if unit_s[k] <= left:
                w, obj = solve(rest, F0 + unit_F[k], left - unit_s[k]) if rest else \
                    (np.zeros(0), worst_relative(F0 + unit_F[k], values, targets))
                options.append((obj, k, True, w))
        obj, k, whole, shares = min(options, key=lambda o: o[0])
        kept.remove(k)
        if whole:
            seconds[k] = unit_s[k]
            left -= unit_s[k]
            F0 = F0 + unit_F[k]
            if any(unit_s[i] > left + 1e-9 for i in kept):
                kept = [i for i in kept if unit_s[i] <= left + 1e-9]
                shares, _ = solve(kept, F0, left) if kept else (np.zeros(0), math.inf)
    for j, k in enumerate(kept):
        seconds[k] = float(shares[j])
    if not any(seconds[k] for k in range(len(unit_F)) if not fixed[k]):
        best = min((k for k in range(len(unit_F)) if not fixed[k]),
                   key=lambda k: worst_relative(F0 + unit_F[k], values, targets))
        seconds[best] = unit_s[best]  # too short a budget: the one unit that helps most
    return seconds


#: the smooth stand-in for the largest relative variance: its power mean of this order
POWER = 16
#: ridge added to the relative information (a fraction of its mean diagonal) while optimising,
#: so that a share of 0 leaves it invertible
RIDGE = 1e-9


def optimal_shares(rate_F: list[np.ndarray], F0, budget: float, values: np.ndarray,
                   targets: np.ndarray) -> np.ndarray:
    """Seconds of each profile (information per second ``rate_F``) summing to ``budget`` that
    minimise the worst relative variance among ``targets``.

    The worst is smoothed as the power mean of order :data:`POWER` of the relative variances,
    a convex function of the shares; minimised by SLSQP on the simplex with its exact gradient
    (d var_i / d w_k = -(G^-1 R_k G^-1)_ii). ``F0``: information recorded anyway.
    """
    from scipy.optimize import minimize

    m = len(rate_F)
    if m == 0 or budget <= 0:
        return np.zeros(m)
    scale = np.where(values != 0, np.abs(values), 1.0)
    S = np.outer(scale, scale)
    Rs = [budget * R * S for R in rate_F]  # information on relative changes, whole budget
    G0 = F0 * S if not np.isscalar(F0) else np.zeros_like(Rs[0])
    ridge = RIDGE * float(np.mean(np.diagonal(sum(Rs)))) * np.eye(len(values))
    idx = np.flatnonzero(targets)
    n = len(idx)

    def fun(w):
        Gi = np.linalg.inv(G0 + ridge + sum(wk * R for wk, R in zip(w, Rs, strict=True)))
        var = np.diag(Gi)[idx]
        top = float(np.max(var))
        mean = float(np.mean((var / top) ** POWER))
        f = top * mean ** (1.0 / POWER)
        dvar = (var / top) ** (POWER - 1) * mean ** (1.0 / POWER - 1.0) / n
        grad = np.array([-float(np.sum(dvar * np.einsum("ij,jk,ki->i", Gi[idx], R, Gi[:, idx])))
                         for R in Rs])
        return f, grad

    f0 = fun(np.full(m, 1.0 / m))[0]

    def scaled(w):
        f, g = fun(w)
        return f / f0, g / f0

    res = minimize(scaled, np.full(m, 1.0 / m), jac=True, method="SLSQP",
                   bounds=[(0.0, 1.0)] * m,
                   constraints=[{"type": "eq", "fun": lambda w: np.sum(w) - 1.0,
                                 "jac": lambda w: np.ones(m)}],
                   options={"maxiter": 200, "ftol": 1e-10})
    w = np.clip(res.x, 0.0, None)
    if not (np.all(np.isfinite(w)) and w.sum() > 0) or scaled(w / w.sum())[0] > 1.0:
        w = np.full(m, 1.0 / m)
    return budget * w / w.sum()


def recorded_noise(model: Model) -> dict[str, float]:
    """Noise std per signal a model file records from its fits (``fits.<stage>.sigma``: per log,
    signal -> std), the median over logs; empty when it records none."""
    out: dict[str, list[float]] = {}
    for fit in (model.extra.get("fits") or {}).values():
        sig = fit.get("sigma") if isinstance(fit, dict) else None
        for per_log in sig if isinstance(sig, list) else []:
            for s, v in (per_log.items() if isinstance(per_log, dict) else []):
                if s in ("omega", "i") and isinstance(v, (int, float)) and v > 0:
                    out.setdefault(s, []).append(float(v))
    return {s: float(np.median(v)) for s, v in out.items()}


def default_noise(settings: Settings, peak_speed: float, peak_current: float,
                  recorded: dict[str, float] | None = None) -> dict[str, float]:
    """Noise std per signal: the options, else what the model's fits recorded, else 1 % of the
    plan's top speed and current."""
    rec = recorded or {}
    w = settings.noise_omega or rec.get("omega") or NOISE_FRACTION * max(peak_speed, 1e-9)
    i = settings.noise_i or rec.get("i") or NOISE_FRACTION * max(peak_current, 1e-12)
    return {"omega": w, "i": i}


def worst_relative(F: np.ndarray, values: np.ndarray, targets: np.ndarray) -> float:
    """Largest relative standard error among the ``targets`` (boolean mask)."""
    rel = fi.relative(fi.stderr(F), values)
    return float(np.max(rel[targets])) if targets.any() else 0.0


def build(cands, seconds, rate, vals, names, drive, scales, noise):
    """Profiles of the given lengths, their sensitivities, and their information by index."""
    profiles, sens, infos = [], [], {}
    for k, ((kind, u, b), s) in enumerate(zip(cands, seconds, strict=True)):
        if s <= 0:
            continue
        p = pr.make(f"{len(profiles) + 1:02d}_{kind}", kind, u, rate, b, s)
        p.meta = {"amplitude": f"{float(np.max(np.abs(u))):.6g}"}
        profiles.append(p)
        sens.append(profile_sens(p.t, p.u, b, vals, names, drive, scales))
        infos[k] = fi.information(sens[-1], noise)
    return profiles, sens, infos


def _allocate_build(cands, budget: float, ctx):
    """Share ``budget`` among the candidates (:func:`allocate`) and build the profiles."""
    vals, names, drive, scales, noise, rate = ctx
    values = np.array([vals[n] for n in names])
    unit_F, unit_s = [], []
    for _, u, b in cands:
        t = np.arange(len(u)) / rate
        unit_F.append(fi.information(profile_sens(t, u, b, vals, names, drive, scales), noise))
        unit_s.append(len(u) / rate)
    seconds = allocate(unit_F, unit_s, budget, values, values != 0, [b for _, _, b in cands])
    return build(cands, seconds, rate, vals, names, drive, scales, noise)


#: multiples of the blocked-rotor step's default hold a plan tries: identify takes R from the
#: blocked-rotor log alone, and R's error moves bv and J through the torque km v/R
BLOCKED_LONGER = (1.0, 2.0, 4.0, 8.0, 16.0, 32.0)
#: the blocked-rotor step never takes more than this fraction of the budget
BLOCKED_SHARE = 0.1


def blocked_hold(profiles, sens, ctx, umax: float, budget: float) -> float:
    """How many times the default hold the blocked-rotor step should last: the multiple (of
    :data:`BLOCKED_LONGER`, within :data:`BLOCKED_SHARE` of the budget) that minimises the
    worst relative standard error of the mechanical parameters as identify's stages determine
    them (:func:`~pmdcid.plan.fisher.staged_from`); the free profiles shortened to pay for it."""
    vals, names, drive, scales, noise, rate = ctx
    blocked = [p.blocked for p in profiles]
    F_el, F_sp = fi.stage_information(sens, blocked, noise, len(names))
    free_s = sum(p.seconds for p in profiles if not p.blocked)
    base_s = sum(p.seconds for p in profiles if p.blocked)
    mech = np.array([n not in fi.ELECTRICAL and vals[n] != 0 for n in names])
    values = np.array([vals[n] for n in names])
    te, _ = time_constants(vals, drive)
    best, best_obj = 1.0, math.inf
    for m in BLOCKED_LONGER:
        u = pr.blocked_step(umax, te, rate, m)
        extra = len(u) / rate - base_s
        if extra > BLOCKED_SHARE * budget or extra >= free_s:
            break
        t = np.arange(len(u)) / rate
        Fb = fi.information(profile_sens(t, u, True, vals, names, drive, scales), noise)
        se = fi.staged_from(Fb, F_sp * (free_s - extra) / free_s, names)
        obj = float(np.max(fi.relative(se, values)[mech])) if mech.any() else 0.0
        if obj < best_obj * (1 - 1e-3):
            best, best_obj = m, obj
    return best


def blocked_current_notes(profiles, vals: dict[str, float], drive: fi.Drive) -> list[str]:
    """What each blocked-rotor step draws: V/R [A] (no back-EMF with the rotor held), for how
    long, so that the user checks the drive's and the motor's ratings before recording it."""
    out = []
    for p in profiles:
        if not (p.blocked and drive.electrical and vals.get("R", 0) > 0):
            continue
        v = float(np.max(np.abs(p.u)))
        held = float(np.count_nonzero(np.abs(p.u) > 0)) / pr.rate_of(p.t)
        out.append(f"{p.name}.csv: the blocked-rotor step of {v:.3g} V draws {v / vals['R']:.3g} A "
                   f"(V/R, R = {vals['R']:.3g} ohm, no back-EMF with the rotor held) for "
                   f"{held:.3g} s: check that the drive and the motor take it (a lower --vmax "
                   "lowers it)")
    return out


def plan_for_model(model: Model, settings: Settings) -> Plan:
    """The plan for a model: profiles, units, predicted standard errors, the effect table."""
    drive = fi.drive_of(model, settings.taumax)
    if drive.column == "tau" and not settings.taumax and settings.umax is not None:
        raise ModelError("the model is torque-driven (no R, L, km): give --taumax, not --vmax",
                         model.path)
    vals = fi.model_values(model, drive)
    names = fi.identified(model, drive)
    if "J" not in names:
        raise ModelError("model lacks J: run fit-mechanical (or plan --guess)", model.path)
    umax, umax_default = settings.umax, settings.umax is None
    if umax is None:
        umax = DEFAULT_UMAX_BREAKAWAY * breakaway_input(vals, drive)
        if not umax > 0:
            raise ModelError("model has no friction to size a default input from: give "
                             f"--{'taumax' if drive.column == 'tau' else 'vmax'}", model.path)
    with_blocked = "R" in names
    cands = candidates(vals, drive, umax, settings.speed_max, settings.rate, with_blocked)
    rate = settings.rate
    sims = [fi.simulate_profile(np.arange(len(u)) / rate, u, vals, drive, b) for _, u, b in cands]
    peak_w = max(float(np.max(np.abs(s.omega))) for s in sims)
    peak_i = (max(float(np.nanmax(np.abs(s.i))) for s in sims) if drive.electrical else 0.0)
    noise = default_noise(settings, peak_w, peak_i, recorded_noise(model))
    scales = parameter_scales(vals, drive, max(peak_w, 1e-6))
    ctx = (vals, names, drive, scales, noise, rate)
    profiles, sens, infos = _allocate_build(cands, settings.budget, ctx)
    longer = blocked_hold(profiles, sens, ctx, umax, settings.budget) if with_blocked else 1.0
    if longer > 1:
        te, _ = time_constants(vals, drive)
        cands[0] = ("blocked", pr.blocked_step(umax, te, rate, longer), True)
        profiles, sens, infos = _allocate_build(cands, settings.budget, ctx)
    F = sum(infos.values())
    se = fi.staged_stderr(sens, [p.blocked for p in profiles], names, noise)
    plan = Plan(profiles, drive, names, {n: vals[n] for n in names},
                {n: float(s) for n, s in zip(names, se, strict=True)}, noise, umax,
                umax_default, settings.speed_max, sens=sens)
    plan.notes += blocked_current_notes(profiles, vals, drive) + fi.bound_notes(names)
    if settings.effects:
        plan.effects = effect_table(profiles, sens, F, vals, names, drive, noise, scales, model)
    if plan.seconds > settings.budget + 1e-6:
        plan.notes.append(f"the budget of {settings.budget:g} s is shorter than one unit of each "
                          f"profile: the plan takes {plan.seconds:.1f} s")
    return plan


def plan_information(plan: Plan) -> np.ndarray:
    F = np.zeros((len(plan.names), len(plan.names)))
    for s in plan.sens:
        F += fi.information(s, plan.noise)
    return F

__all__ = ["BUDGET", "RATE", "Plan", "Settings", "allocate", "breakaway_input", "candidates",
           "default_noise", "effect_table", "plan_for_model", "plan_information",
           "size_to_speed", "time_constants"]
