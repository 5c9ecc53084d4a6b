"""The diagnose loop: screen the catalogue, refit the strongest, keep what holds out, repeat.

1. Simulate the model on every log; refit the base parameters the logs inform (J, bv, bc, dz from
   moving logs; R from currents) on the fit part of each log, so that the comparison is fair.
2. Screen every catalogue effect not in the model by regressing the residual on its simulated
   signature (:mod:`pmdcid.diagnose.signatures`).
3. Refit the strongest few by simulation error (own parameters and the base parameters they
   interact with) on the fit part. Keep the best only if its BIC drops decisively
   (``delta_bic < bic_threshold``) AND the fit improves the held-out part of the logs, never
   used to fit it, by a decisive likelihood ratio (``heldout < heldout_threshold``).
4. Repeat until no effect passes; refit the result on all the data (values, standard errors).
5. ``unexplained``: the final residual of some current or speed signal is still clearly not white
   (std over 1.5 noise levels and Ljung-Box p < 1e-6).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np

from pmdcid.diagnose.problem import FitOutcome, Problem
from pmdcid.diagnose.residuals import (
    context,
    drift_notes,
    error_table,
    pooled,
    typical_scales,
    whiteness,
)
from pmdcid.diagnose.signatures import Screen, Screener
from pmdcid.diagnose.starts import grid_start, profile_best, profile_stderr
from pmdcid.errors import ModelError
from pmdcid.identify.nonlinear import masked_upper
from pmdcid.identify.results import Estimate, ResultProtocol
from pmdcid.identify.simfit import blas_single_thread
from pmdcid.model import EFFECTS, Model
from pmdcid.model.params import copy_model_into
from pmdcid.simulate import param_values

STAGE = "diagnose"
#: base parameters diagnose refits along with the effects (those the logs inform)
MECHANICAL_BASE = ("J", "bv", "bc", "dz")
ELECTRICAL_BASE = ("R", "L")
#: friction start (fraction of the torque scale) tried when the model has none
NUDGE = 0.2


@dataclass
class Candidate:
    """What diagnose found about one effect in one round."""

    effect: str
    round: int
    screen_gain: float
    delta_bic: float
    refit: bool = False
    heldout: float | None = None  # held-out n log(chi2 ratio); < 0 means better
    omega_nrmse: float | None = None
    chosen: bool = False
    values: dict[str, float] = field(default_factory=dict)
    z: float | None = None  # the effect's size in standard errors
    gain_fit: float | None = None  # relative chi-square drop, fit part
    gain_held: float | None = None  # relative chi-square drop, held-out part
    outcome: FitOutcome | None = None

    def to_json(self) -> dict:
        def num(x):
            return float(x) if x is not None and math.isfinite(x) else None

        return {"effect": self.effect, "delta_bic": num(self.delta_bic),
                "omega_nrmse": num(self.omega_nrmse), "refit": self.refit,
                "heldout_delta": num(self.heldout), "screen_gain": num(self.screen_gain),
                "round": self.round, "chosen": self.chosen, "size_sigmas": num(self.z),
                "chi2_drop_fit": num(self.gain_fit), "chi2_drop_heldout": num(self.gain_held),
                "parameters": {k: num(v) for k, v in self.values.items()}}


@dataclass
class DiagnoseResult(ResultProtocol):
    """The new model, the summary (CONTRACT.md), per-log errors and the candidates."""

    model: Model
    summary: dict
    candidates: list[Candidate]
    paths: list[str]
    before: list[dict[str, float]]
    after: list[dict[str, float]]
    history: list[Candidate] = field(default_factory=list)

    def table(self) -> str:
        from pmdcid.diagnose.report import format_table

        return format_table(self)

    def rows(self) -> list[tuple[str, float, float, str]]:
        """The new model's parameters."""
        return self.model.rows()

    def apply(self, model: Model) -> None:
        """Make ``model`` the diagnosed model: its parameters, effects and records."""
        copy_model_into(self.model, model)


def _free_base(problem: Problem, vals: dict[str, float], model: Model) -> list[str]:
    """Parameters refitted with every candidate: those of J, bv, bc (and dz when the model has a
    dead zone) that moving logs inform, R and L when a current is logged, and the parameters of
    the effects the model already declares."""
    out = []
    moving = problem.has_signal("omega", moving=True) or problem.has_signal("theta", moving=True)
    if moving:
        out += [p for p in MECHANICAL_BASE if p != "dz" or model.has("dz")]
    if problem.has_signal("i"):
        out += list(ELECTRICAL_BASE)
    for e in model.effects:
        if e in EFFECTS and (moving or EFFECTS[e].acts_on == "electrical"):
            out += [p for p in EFFECTS[e].param_names if p not in EFFECTS[e].held]
    return [p for p in dict.fromkeys(out) if math.isfinite(vals.get(p, math.nan))]


def effect_z(eff, fo: FitOutcome) -> float:
    """Size of an effect in standard errors: its first parameter's distance from neutral."""
    spec = eff.params[0]
    est = fo.estimates.get(spec.name)
    if est is None:
        return math.inf
    if not math.isfinite(spec.neutral):
        return math.inf
    d = abs(est.value - spec.neutral)
    return d / est.stderr if est.stderr > 0 else (math.inf if d > 0 else 0.0)


def dead_zone_range(problem: Problem, fo: FitOutcome, n: int = 13,
                    rel: float = 1e-3) -> float | None:
    """Upper end [N m] of the dead zones that fit as well as the fit ``fo`` does, or None.

    A dead zone below the breakaway torque never acts on a rotor that turns only while the
    torque exceeds it: every dz from 0 up to some level fits equally (within two standard errors,
    4 x the reduced chi-square, or ``rel`` of the chi-square). Returns that level when dz = 0 is
    among them (the dead zone is not identified), None when the data see the dead zone.
    """
    v = fo.values
    c = fo.chi2["all"]
    thr = max(4.0 * max(c / max(problem.count("all") - len(fo.estimates), 1), 1.0), rel * c)
    top = 1.5 * max(v.get("bc", 0.0) + max(v.get("fs", 0.0), 0.0), v.get("dz", 0.0), 1e-300)
    dzs = np.linspace(0.0, top, n)
    cost = np.array([problem.chi2({**v, "dz": d})["all"] for d in dzs])
    if cost[0] - c > thr:
        return None
    return masked_upper(dzs, cost, thr)


def _gain(before: float, after: float, n: int) -> float:
    """Share of the chi-square in excess of the noise (n samples) that a refit removed.

    On a model that misses something large (real logs) this is the relative chi-square drop;
    where the residual is mostly noise, a real effect removes most of the small excess. The
    excess is taken as at least 5 % of the chi-square (noise levels are estimates).
    """
    return (before - after) / max(before - n, 0.05 * before, 1e-300)


def _fits_as_well(problem: Problem, fo: FitOutcome, change: dict[str, float]) -> bool:
    """True when ``change`` applied to the fit ``fo`` raises the chi-square (all data) by at
    most two standard errors (4 x the reduced chi-square)."""
    c = fo.chi2["all"]
    thr = 4.0 * max(c / max(problem.count("all") - len(fo.estimates), 1), 1.0)
    return problem.chi2({**fo.values, **change})["all"] - c <= thr


def _weakest(problem: Problem, fo: FitOutcome, added: list[str], base_free: list[str],
             fit, bic_threshold: float) -> tuple[str, FitOutcome] | None:
    """Backward check of several added effects: each is removed in turn and the rest refitted;
    returns (the effect whose removal costs least, the refit without it) when that cost is not
    decisive (ΔBIC of the removal, all data, below -``bic_threshold``), else None."""
    if len(added) < 2:
        return None
    n = problem.count("all")
    worst = None
    for e in added:
        rest = base_free + [p for a in added if a != e for p in _effect_free(a)]
        off = {p.name: p.neutral for p in EFFECTS[e].params}
        without = fit({**fo.values, **off}, rest, "all")
        d = n * math.log(max(without.chi2["all"], 1e-300) / max(fo.chi2["all"], 1e-300))
        d -= len(_effect_free(e)) * math.log(max(n, 2))
        if worst is None or d < worst[2]:
            worst = (e, without, d)
    return (worst[0], worst[1]) if worst[2] < -bic_threshold else None


def _effect_free(name: str) -> list[str]:
    eff = EFFECTS[name]
    return [p for p in eff.param_names if p not in eff.held]


def diagnose(logs: Sequence, model: Model, effects: Sequence[str] | None = None,
             split: float = 0.6, max_samples: int = 20000, refit_top: int = 3,
             bic_threshold: float = -10.0, heldout_threshold: float = -10.0,
             max_nfev: int = 40, max_rounds: int = 4, min_z: float = 5.0,
             min_gain: float = 0.01, progress=None) -> DiagnoseResult:
    """Find the catalogue effects ``model`` lacks on ``logs``, add them, refit, report.

    ``effects`` restricts the catalogue searched (default: all not already in the model).
    The input model is not modified. ``progress(msg)`` is called as each round starts and
    before each candidate's refit.
    """
    with blas_single_thread():
        return _diagnose(logs, model, effects, split, max_samples, refit_top, bic_threshold,
                         heldout_threshold, max_nfev, max_rounds, min_z, min_gain,
                         progress or (lambda msg: None))


def _diagnose(logs, model, effects, split, max_samples, refit_top, bic_threshold,
              heldout_threshold, max_nfev, max_rounds, min_z, min_gain,
              say) -> DiagnoseResult:
    if effects is not None:
        unknown = [e for e in effects if e not in EFFECTS]
        if unknown:
            raise ModelError(f"unknown effect(s) {', '.join(unknown)} "
                             f"(known: {', '.join(EFFECTS)})")
    problem = Problem(logs, split, max_samples)
    torque_only = all(log.drive == "tau" for log in problem.logs)
    vals0 = param_values(model, torque_driven=torque_only)
    before = error_table(problem, problem.simulate_all(vals0))
    base_free = _free_base(problem, vals0, model)
    ctx0 = context(problem, vals0, problem.simulate_all(vals0))
    typ = typical_scales(ctx0)

    limits = {k: v for e in EFFECTS.values() if e.limits for k, v in e.limits(ctx0).items()}

    def fit(start, free, part="fit", nfev=max_nfev):
        return problem.fit(start, free, part, nfev, typ, limits)

    tscale = ctx0.torque_scale

    def robust_fit(start, free, part="fit", nfev=max_nfev):
        """Grid start over the friction, local fit, then a profile polish of bc and dz (the cost
        is piecewise flat in them) and a refit when the polish found a clearly better point."""
        fo = fit(grid_start(problem, start, free, tscale, part), free, part, nfev)
        pol = profile_best(problem, fo.values, free, part)
        thr = 4.0 * max(fo.chi2[part] / max(problem.count(part), 1), 1.0)
        if problem.chi2(pol)[part] < fo.chi2[part] - thr:
            fo = fit(pol, free, part, nfev)
        return fo

    cur = robust_fit(vals0, base_free)
    friction = [p for p in ("bc", "dz") if p in base_free]
    if friction and all(vals0[p] < 0.01 * ctx0.torque_scale for p in friction):
        # a model without friction: also try from some, keep the better polish
        alt = fit({**vals0, **{p: NUDGE * ctx0.torque_scale for p in friction}}, base_free)
        if alt.chi2["fit"] < cur.chi2["fit"]:
            cur = alt
    n_fit, n_held = problem.count("fit"), problem.count("held")
    pool = [e for e in EFFECTS if e not in model.effects and (effects is None or e in effects)
            and all(problem.measures(s) for s in EFFECTS[e].requires)]
    added: list[str] = []
    notes: list[str] = []
    seen: dict[str, Candidate] = {}
    history: list[Candidate] = []  # every refit, in order
    cur_free = list(base_free)
    for rnd in range(1, max_rounds + 1):
        if not pool:
            break
        say(f"diagnose round {rnd}: screening {len(pool)} effect(s)")
        sims = problem.simulate_all(cur.values)
        scr = Screener(problem, cur.values, context(problem, cur.values, sims), base_free)
        screens: list[Screen] = [scr.screen(EFFECTS[e]) for e in pool]
        for s in screens:
            seen[s.effect] = Candidate(s.effect, rnd, s.gain, s.approx_delta_bic)
        ranked = sorted((s for s in screens if s.start and s.approx_delta_bic < 0),
                        key=lambda s: -s.gain)[:refit_top]
        passing = []
        rebase = None  # a better point of the current model met while refitting a candidate
        for s in ranked:
            eff = EFFECTS[s.effect]
            say(f"diagnose round {rnd}: refitting with {s.effect}")
            free = _effect_free(s.effect) + cur_free
            fo = robust_fit({**cur.values, **s.start}, free)
            # ablation: the refit's values with the effect switched off. A refit may also move
            # the base parameters to a better point that the current model could reach without
            # the effect (the cost is only piecewise smooth): the effect is credited only with
            # what it adds over the better of that point and the current fit.
            off = {**fo.values, **{p.name: p.neutral for p in eff.params}}
            abl = problem.chi2(off)
            ref = cur.chi2
            if abl["fit"] < cur.chi2["fit"]:
                ref = abl
                if rebase is None or abl["fit"] < rebase[1]["fit"]:
                    rebase = (off, abl)
            k = len(_effect_free(s.effect))
            dbic = n_fit * math.log(max(fo.chi2["fit"], 1e-300) / max(ref["fit"], 1e-300))
            dbic += k * math.log(max(n_fit, 2))
            held = (n_held * math.log(max(fo.chi2["held"], 1e-300) / max(ref["held"], 1e-300))
                    if n_held else None)
            om = pooled(error_table(problem, problem.simulate_all(fo.values)))["omega_nrmse"]
            c = Candidate(s.effect, rnd, s.gain, dbic, True, held, om,
                          values={p: fo.values[p] for p in eff.param_names}, outcome=fo)
            seen[s.effect] = c
            history.append(c)
            c.z = effect_z(eff, fo)
            c.gain_fit = _gain(ref["fit"], fo.chi2["fit"], n_fit)
            c.gain_held = _gain(ref["held"], fo.chi2["held"], n_held) if n_held else 1.0
            if (dbic < bic_threshold and (held is None or held < heldout_threshold)
                    and c.z >= min_z and min(c.gain_fit, c.gain_held) >= min_gain):
                passing.append(c)
        if not passing:
            if rebase is not None and rebase[1]["fit"] < (1 - min_gain) * cur.chi2["fit"]:
                # no effect, but the current model fits clearly better elsewhere: move there
                # and screen again
                better = fit(rebase[0], cur_free)
                if better.chi2["fit"] < cur.chi2["fit"]:
                    cur = better
                    continue
            break
        best = min(passing, key=lambda c: c.delta_bic)
        best.chosen = True
        added.append(best.effect)
        pool.remove(best.effect)
        cur_free = base_free + [p for e in added for p in _effect_free(e)]
        cur = robust_fit(best.outcome.values, cur_free, nfev=4 * max_nfev)
    new = model.copy()
    if added:
        free = base_free + [p for e in added for p in _effect_free(e)]
        final = robust_fit(cur.values, free, "all")
        weak = _weakest(problem, final, added, base_free, fit, bic_threshold)
        while weak is not None:
            # an effect that the final fit no longer needs (another one took its part) goes
            added.remove(weak[0])
            final = weak[1]
            notes.append(f"{weak[0]} dropped: with the other added effects it no longer "
                         "improves the fit decisively")
            for c in history:
                if c.effect == weak[0]:
                    c.chosen = False
            free = base_free + [p for e in added for p in _effect_free(e)]
            weak = _weakest(problem, final, added, base_free, fit, bic_threshold)
        upper = dead_zone_range(problem, final) if "dz" in free else None
        if upper is not None:
            # its refit value and standard error would mean nothing: written as the interval's
            # midpoint +- its uniform std, as fit-nonlinear does, the others refitted with it
            free = [p for p in free if p != "dz"]
            final = fit({**final.values, "dz": 0.5 * upper}, free, "all")
            final.estimates["dz"] = Estimate("dz", 0.5 * upper, upper / math.sqrt(12.0), "N m")
            notes.append(f"dz is not identifiable with the added effects: any dead zone from 0 "
                         f"to {upper:.3g} N m fits equally (below the breakaway torque); written "
                         "as the interval's midpoint +- its uniform std")
        elif "dz" in free and _fits_as_well(problem, final, {"dz": vals0["dz"]}):
            # the dead zone shows only at a few switching instants: when the model's own dz (from
            # fit-nonlinear's slow reversals) fits these logs as well, these logs do not move it
            free = [p for p in free if p != "dz"]
            final = fit({**final.values, "dz": vals0["dz"]}, free, "all")
            notes.append("dz kept from the model: it fits these logs as well as a refitted one")
    if added:
        for name in ("bc", "dz"):
            est = final.estimates.get(name)
            if est is not None and name in free:
                se = profile_stderr(problem, final.values, name, final.stats.redchi)
                if math.isfinite(se) and not se <= est.stderr:
                    final.estimates[name] = Estimate(name, est.value, se, est.unit)
        # the refits' errors assume white residuals; on real data the residual is correlated
        hac, info = problem.correlated_stderr(final.values, list(final.estimates))
        for name, se in hac.items():
            est = final.estimates[name]
            if math.isfinite(se) and se > est.stderr and name in free:
                final.estimates[name] = Estimate(name, est.value, se, est.unit)
        if info is not None and info.inflation > 1.5:
            notes.append(info.describe())
        for e in added:
            new.add_effect(e)
            for p in EFFECTS[e].held:
                new.set(p, final.values[p], stage=STAGE)
        for name, est in final.estimates.items():
            new.set(name, est.value, est.stderr, est.unit, stage=STAGE)
        final_vals = final.values
        after = error_table(problem, problem.simulate_all(final_vals))
    else:
        final_vals = cur.values
        after = before
    white = whiteness(problem, problem.simulate_all(final_vals))
    unexplained = any(w.structured for w in white)
    if unexplained:
        notes.extend(drift_notes(problem, final_vals, max_nfev))
    cands = sorted(seen.values(), key=lambda c: (not c.chosen, c.delta_bic))
    new.extra.setdefault("fits", {})[STAGE] = {
        "logs": [log.path for log in problem.logs], "added": list(added)}
    summary = {
        "added": list(added),
        "candidates": [c.to_json() for c in cands],
        "before": pooled(before),
        "after": pooled(after),
        "unexplained": bool(unexplained),
        "notes": notes,
        "logs": [{"path": log.path, "before": b, "after": a}
                 for log, b, a in zip(problem.logs, before, after, strict=True)],
        "whiteness": [{"log": problem.logs[w.log].path, "signal": w.signal,
                       "std_over_noise": w.ratio, "rho1": w.rho1, "ljung_box_p": w.p_value,
                       "structured": w.structured} for w in white],
    }
    return DiagnoseResult(new, summary, cands, [log.path for log in problem.logs], before, after,
                          history)


__all__ = ["Candidate", "DiagnoseResult", "diagnose"]
