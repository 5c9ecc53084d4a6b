"""``pmdcid plan --check``: what logs a user already has leave poorly determined, and the fix.

The logs' own inputs are simulated with the model and the Fisher information computed as for a
plan (:mod:`.fisher`), each signal weighted by the noise measured on the log itself (robust,
from its second difference). A parameter whose predicted relative standard error exceeds
:data:`POOR` is poorly determined; for each such parameter the candidate profile whose added
recording lowers its standard error the most is named, with the time it needs to bring it under
the threshold (within the budget). Logs whose measured speed runs against the model's (a speed
sensor counting the other way) are said so in the one line diagnose and report give
(:func:`pmdcid.fit.results.speed_against`), with the mapping that fixes them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from pmdcid.errors import LogError, ModelError, PmdcidError, warn
from pmdcid.model import Model
from pmdcid.plan import fisher as fi
from pmdcid.plan import profiles as pr
from pmdcid.plan.design import (
    DEFAULT_UMAX_BREAKAWAY,
    NOISE_FRACTION,
    Settings,
    breakaway_input,
    candidates,
    parameter_scales,
)

#: relative standard error above which a parameter is poorly determined
POOR = 0.25
#: the head of the effects' lines
EFFECTS_HEAD = ("effects diagnose screens, and whether the data it holds out could test them "
                "(a necessary condition, judged before any refit):")


@dataclass
class CheckResult:
    """Per parameter: value, predicted stderr, relative; and the fixes of the poor ones."""

    names: list[str]
    values: dict[str, float]
    stderr: dict[str, float]
    fixes: dict[str, dict] = field(default_factory=dict)
    paths: list[str] = field(default_factory=list)
    #: per effect diagnose screens: whether these logs can test it, what to record
    #: (:mod:`pmdcid.plan.testable`)
    effects: list[dict] = field(default_factory=list)
    #: why the effects were not judged ('' when they were)
    effects_skipped: str = ""
    #: what the logs show wrong beyond precision (a reversed speed), one line each
    findings: list[str] = field(default_factory=list)

    def relative(self) -> dict[str, float]:
        return {n: (self.stderr[n] / abs(self.values[n]) if self.values[n] else math.inf)
                for n in self.names}

    def poor(self) -> list[str]:
        return [n for n, r in self.relative().items() if not r <= POOR]

    def as_dict(self) -> dict:
        rel = self.relative()
        fin = (lambda x: float(x) if math.isfinite(x) else None)  # noqa: E731
        return {"logs": self.paths, "threshold": POOR,
                "parameters": {n: {"value": self.values[n], "stderr": fin(self.stderr[n]),
                                   "relative": fin(rel[n]), "poor": n in self.poor(),
                                   "fix": self.fixes.get(n)} for n in self.names},
                "effects": self.effects, "effects_skipped": self.effects_skipped or None,
                "findings": self.findings, "notes": fi.bound_notes(self.names)}

    def lines(self) -> list[str]:
        rel = self.relative()
        out = [f"{'parameter':<10} {'value':>12} {'stderr':>11} {'relative':>9}"]
        for n in self.names:
            se = f"{self.stderr[n]:.3g}" if math.isfinite(self.stderr[n]) else "free"
            r = f"{100 * rel[n]:.2g} %" if math.isfinite(rel[n]) else "-"
            flag = "  poorly determined" if n in self.poor() else ""
            out.append(f"{n:<10} {self.values[n]:12.5g} {se:>11} {r:>9}{flag}")
        for n, fx in self.fixes.items():
            if fx.get("kind"):
                done = ("" if fx["reaches"] else
                        f" (still {100 * fx['relative_after']:.2g} % within the budget)")
                out.append(f"{n}: record {fx['seconds']:.3g} s of {fx['kind']} up to "
                           f"{fx['amplitude']:.3g} ({pr.PURPOSES[fx['kind']]}){done}")
            else:
                out.append(f"{n}: no candidate profile helps: {fx.get('why', '')}")
        out += fi.bound_notes(self.names)
        if not self.poor():
            out.append(f"every parameter is determined within {100 * POOR:.0f} %")
        return out + self.effect_lines()

    def effect_lines(self) -> list[str]:
        """The effects diagnose screens: testable with these logs, or what to record."""
        if self.effects_skipped:
            return [f"effects: not judged ({self.effects_skipped})"]
        out = [EFFECTS_HEAD]
        for r in self.effects:
            out.append(f"  {r['effect']:<20} " + ("testable" if r["testable"] else
                       f"possible, not testable with these logs: record {r['record']}"))
        return out


def _log_drive(logs, model: Model) -> fi.Drive:
    drive = fi.drive_of(model)
    kinds = {lg.drive for lg in logs}
    if len(kinds) > 1:
        raise LogError("logs mix voltage (v) and torque (tau) inputs: check them separately",
                       logs[0].path)
    if kinds == {"tau"} and drive.column == "v":
        return fi.Drive("tau", True)
    if kinds == {"v"} and drive.column == "tau":
        raise ModelError("the logs are voltage-driven but the model has no R, L, km (and is "
                         "not marked lumped)", model.path)
    return drive


def _log_signals(log, drive: fi.Drive, blocked: bool) -> tuple[str, ...]:
    sig = () if blocked or not log.has("omega") else ("omega",)
    return sig + (("i",) if drive.electrical and log.has("i") else ())


def check_logs(logs, model: Model, settings: Settings) -> CheckResult:
    """Predicted standard errors from ``logs`` (their inputs, their noise) at ``model``. A log
    whose sample period no motor log has (t in ms or us) is refused first, naming the mapping:
    its simulations at the model's time constants would take minutes, and predict nothing."""
    from pmdcid.fit.problem import noise_level
    from pmdcid.identify.plausibility import time_unit_issue

    for lg in logs:
        msg = time_unit_issue(lg)
        if msg:
            raise LogError(msg, lg.path)

    drive = _log_drive(logs, model)
    vals = fi.model_values(model, drive)
    names = fi.identified(model, drive)
    speed = max([float(np.max(np.abs(lg["omega"]))) for lg in logs if lg.has("omega")]
                + [1e-6])
    scales = parameter_scales(vals, drive, speed)
    F = fi.range_information(names)
    noises = []
    for lg in logs:
        blocked = lg.blocked
        sigs = _log_signals(lg, drive, blocked)
        if not sigs:
            continue
        noise = {s: noise_level(lg[s]) for s in sigs}
        noises.append(noise)
        sens = fi.sensitivities(lg.t, lg.u, vals, names, drive, blocked, scales, sigs)
        F += fi.information(sens, noise)
    if not noises:
        raise LogError("no log measures the speed (omega) or the current (i): nothing to check",
                       logs[0].path)
    se = fi.stderr(F)
    res = CheckResult(names, {n: vals[n] for n in names},
                      {n: float(s) for n, s in zip(names, se, strict=True)},
                      paths=[str(lg.path) for lg in logs])
    _speed_against(res, logs, model)
    poor = res.poor()
    if poor:
        res.fixes = fixes(poor, F, logs, vals, names, drive, scales, noises, settings)
    _judge_effects(res, logs, model)
    return res


def _speed_against(res: CheckResult, logs, model: Model) -> None:
    """The logs' measured speed against the model's simulated one, as report and diagnose
    judge it (:func:`~pmdcid.fit.results.speed_against`): a finding, warned about."""
    from pmdcid.fit.results import speed_against
    from pmdcid.simulate.measured import simulate_for

    pairs = []
    for lg in logs:
        if lg.has("omega") and not lg.blocked:
            try:
                sim = simulate_for(lg, model)
            except PmdcidError:  # a log the model cannot simulate: the check says the rest
                continue
            pairs.append((sim.omega, np.asarray(lg["omega"], float)))
    line = speed_against(pairs)
    if line:
        res.findings.append(line)
        warn(line, ", ".join(str(lg.path) for lg in logs))


def _judge_effects(res: CheckResult, logs, model: Model) -> None:
    """Which effects these logs could test (:mod:`pmdcid.plan.testable`); where diagnose could
    not judge any on them (too short, nothing compared), why."""
    from pmdcid.errors import PmdcidError
    from pmdcid.plan.testable import effects_testable

    try:
        res.effects = effects_testable(logs, model)
    except PmdcidError as exc:
        res.effects_skipped = str(exc)


def _logged_umax(logs, vals, drive) -> float:
    """The fixes' input limit without --vmax/--taumax: the largest input the logs applied, or,
    when they applied none (an input of zeros), plan's default: 3 x the model's breakaway
    input; neither: one line asking for the limit."""
    top = max(float(np.max(np.abs(lg.u))) for lg in logs)
    if top > 0 and math.isfinite(top):
        return top
    umax = DEFAULT_UMAX_BREAKAWAY * breakaway_input(vals, drive)
    if not umax > 0:
        opt = "--taumax" if drive.column == "tau" else "--vmax"
        raise LogError(f"the logs apply no input and the model has no friction to size one "
                       f"from: give {opt}", ", ".join(str(lg.path) for lg in logs))
    return umax


def fixes(poor, F, logs, vals, names, drive, scales, noises, settings: Settings) -> dict:
    """For each poor parameter: the candidate profile (and seconds) that fixes it best."""
    umax = settings.umax or _logged_umax(logs, vals, drive)
    rate = settings.rate or 1.0 / min(lg.dt for lg in logs)
    noise = {s: float(np.median([n[s] for n in noises if s in n]))
             for s in ("omega", "i") if any(s in n for n in noises)}
    if "omega" not in noise:
        noise["omega"] = 0.01 * max(abs(vals.get("bv", 1.0)), 1e-9)
    if "i" not in noise and vals.get("R", 0) > 0:  # logs without current: plan's default
        noise["i"] = settings.noise_i or NOISE_FRACTION * umax / vals["R"]
    cands = candidates(vals, drive, umax, settings.speed_max, rate, "R" in names)
    unit = []
    for kind, u, b in cands:
        t = np.arange(len(u)) / rate
        sigs = tuple(s for s in fi.signals_of(b, drive) if s in noise)
        if not sigs:  # nothing this profile records has a known noise: it cannot be scored
            continue
        sens = fi.sensitivities(t, u, vals, names, drive, b, scales, sigs)
        unit.append((kind, fi.information(sens, noise), len(u) / rate,
                     float(np.max(np.abs(u)))))
    out = {}
    values = np.array([vals[n] for n in names])
    for name in poor:
        j = names.index(name)
        best = None
        for kind, Fu, s, amp in unit:
            k, G = 0, F.copy()
            while (k + 1) * s <= settings.budget:
                k += 1
                G = G + Fu
                if fi.relative(fi.stderr(G), values)[j] <= POOR:
                    break
            if k == 0:
                continue
            rel = float(fi.relative(fi.stderr(G), values)[j])
            key = (rel > POOR, k * s if rel <= POOR else rel)
            if best is None or key < best[0]:
                best = (key, {"kind": kind, "seconds": k * s, "amplitude": amp,
                              "relative_after": rel, "reaches": rel <= POOR})
        out[name] = _fix_or_why(best)
    return out


def _fix_or_why(best) -> dict:
    """The best candidate's fix, or why there is none: the budget is shorter than any unit, or
    the best still leaves the parameter's error larger than its value (a dead zone below the
    Coulomb friction, which no profile within the limits shows: "record 119 s of steps (still
    inf %)" named a recording that determines nothing)."""
    if best is None:
        return {"why": "the budget is shorter than one profile unit"}
    fix = best[1]
    rel = fix["relative_after"]
    if not fix["reaches"] and not rel <= 1.0:
        left = f"at {100 * rel:.2g} %" if math.isfinite(rel) else "free"
        return {"why": f"within the budget and the input limit, the best ({fix['seconds']:.3g} "
                       f"s of {fix['kind']}) leaves it {left}"}
    return fix


__all__ = ["POOR", "CheckResult", "check_logs"]
