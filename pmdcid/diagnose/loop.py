"""The diagnose loop, in named steps: baseline, screen, evaluate, accept, finalise, summarise.

1. *baseline*: refit the base parameters the logs inform (J, bv, bc, dz from moving logs; R, L
   from currents) on the fit part (:mod:`pmdcid.diagnose.folds`: a repeat of a protocol held out
   whole, a log without repeats split in time), so that the comparison is fair.
2. *screen*: regress the residual on every missing effect's simulated signature
   (:mod:`pmdcid.diagnose.screen`).
3. *evaluate* the strongest few: refit from several starts (:mod:`pmdcid.diagnose.candidates`);
   a failed or degenerate refit is flagged, never counted.
4. *accept* (:mod:`pmdcid.diagnose.rules`, the one rule set): the passing candidate with the
   lowest ΔBIC; every row says which rule refused it. Repeat until none passes, or the model
   predicts the repeated logs within their repeatability floor.
5. *finalise* (:mod:`pmdcid.diagnose.final`): refit on all the data, prune, polish; an effect
   that fails its size rule in the final model is removed and the rest refitted.
6. *summarise*: errors before and after (all logs, and the logs held out whole), and when the
   residual is still clearly not white (``unexplained``), its shape in physical terms
   (:mod:`pmdcid.diagnose.shape`) and drift notes where drift can show.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from pmdcid.diagnose.candidates import Candidate, effect_free, evaluate
from pmdcid.diagnose.crosslog import Folds
from pmdcid.diagnose.final import finalise, two_se
from pmdcid.diagnose.folds import floor_of, holdout_plan, repeatability
from pmdcid.diagnose.lag import lag_applies, lag_for_delay
from pmdcid.diagnose.lawlag import DELAY, DELAY_EFFECT, LAG_PARAMS, decide, lag_note
from pmdcid.diagnose.named import generalises, prefer_named, with_named
from pmdcid.diagnose.residuals import context, error_table, typical_scales
from pmdcid.diagnose.rules import Rules, judge, same_rows
from pmdcid.diagnose.screen import Screen, Screener
from pmdcid.diagnose.settings import Settings
from pmdcid.diagnose.slow_inputs import read_slow_inputs
from pmdcid.diagnose.starts import grid_start, profile_best, staged_fit
from pmdcid.diagnose.summary import DiagnoseResult, summarise, write_model
from pmdcid.errors import FitError, ModelError
from pmdcid.fit.problem import FitOutcome, Problem
from pmdcid.fit.results import speed_against
from pmdcid.fit.solver import blas_single_thread
from pmdcid.model import EFFECTS, Model
from pmdcid.model.lumped import is_lumped
from pmdcid.runtime.cpus import pmap
from pmdcid.simulate import param_values

#: base parameters diagnose refits along with the effects (those the logs inform)
MECHANICAL_BASE = ("J", "bv", "bc", "dz")
ELECTRICAL_BASE = ("R", "L")
#: friction start (fraction of the torque scale) tried when the model has none
NUDGE = 0.2


def free_base(problem: Problem, vals: dict[str, float], model: Model) -> list[str]:
    """Parameters refitted with every candidate: those of J, bv, bc (and dz when the model has a
    dead zone) that moving logs inform, R and L when a current is logged (else a lumped model's
    lag tau_e and ke_share where it has one), and the parameters of the effects the model
    already declares."""
    out = []
    moving = problem.has_signal("omega", moving=True) or problem.has_signal("theta", moving=True)
    if moving:
        out += [p for p in MECHANICAL_BASE if p != "dz" or model.has("dz")]
    if problem.has_signal("i"):
        out += list(ELECTRICAL_BASE)
    elif moving and is_lumped(model) and vals.get("tau_e", 0.0) > 0:
        # a lumped model's armature lag, fitted by identify without the effects diagnose
        # adds: refitted with them (a speed law the steps lacked moves it; lawlag.py)
        out += list(LAG_PARAMS)
    for e in model.effects:
        if e in EFFECTS and (moving or EFFECTS[e].acts_on == "electrical"):
            out += [p for p in EFFECTS[e].param_names if p not in EFFECTS[e].held]
    return [p for p in dict.fromkeys(out) if math.isfinite(vals.get(p, math.nan))]


class Run:
    """One diagnose run's shared state: the problem, the start, the rules, the refits."""

    def __init__(self, problem: Problem, model: Model, settings: Settings):
        self.problem = problem
        self.model = model
        self.settings = settings
        self.say = lambda msg: None  # progress: told each round and refit
        torque_only = all(log.drive == "tau" for log in problem.logs)
        self.vals0 = param_values(model, torque_driven=torque_only)
        self.base_free = free_base(problem, self.vals0, model)
        self.refresh()
        self.floors = repeatability(problem.logs)
        #: each log's transient held out across logs (:mod:`pmdcid.diagnose.crosslog`)
        self.folds: Folds | None = None
        #: the armature's lag taken into the base parameters (:mod:`pmdcid.diagnose.lawlag`)
        self.lag_taken = False
        #: the effects the run searches (:func:`search_pool`)
        self.pool: list[str] = []
        #: the lag taken in a sensor delay's place after the final fit (:mod:`.lag`)
        self.lag_late = False

    def refresh(self) -> None:
        """The start's residual context, typical scales and the effects' limits (again after
        the problem's input readings changed)."""
        self.ctx0 = context(self.problem, self.vals0, self.problem.simulate_all(self.vals0))
        self.typ = typical_scales(self.ctx0)
        self.limits = {k: v for e in EFFECTS.values() if e.limits
                       for k, v in e.limits(self.ctx0).items()}

    def fit(self, start, free, part="fit", nfev=None) -> FitOutcome:
        """Local refit of ``free`` from ``start`` (:func:`staged_fit`)."""
        budget = nfev or self.settings.max_nfev
        return staged_fit(self.problem, start, free, part, budget, self.typ, self.limits)

    def robust_fit(self, start, free, part="fit", nfev=None) -> FitOutcome:
        """Grid start over the friction, local fit, then a profile polish of bc and dz (the cost
        is piecewise flat in them) and a refit when the polish found a clearly better point."""
        problem = self.problem
        fo = self.fit(grid_start(problem, start, free, self.ctx0.torque_scale, part), free,
                      part, nfev)
        pol = profile_best(problem, fo.values, free, part)
        thr = 4.0 * max(fo.chi2[part] / max(problem.count(part), 1), 1.0)
        if problem.cost(pol, part) < fo.chi2[part] - thr:
            fo = self.fit(pol, free, part, nfev)
        return fo

    def heldout_rise(self, table, ref_vals) -> tuple[float | None, str | None]:
        """Largest relative rise of the speed NRMSE of a log held out whole (``table``: the
        candidate's per-log errors) over the reference ``ref_vals``; (None, None) when no log
        is held out whole."""
        held = self.problem.held_logs
        if not held:
            return None, None
        ref = error_table(self.problem, self.problem.simulate_all(ref_vals))
        worst, where = -math.inf, None
        for k in held:
            a, b = table[k].get("omega"), ref[k].get("omega")
            if a is not None and b and math.isfinite(a) and math.isfinite(b):
                if a / b - 1.0 > worst:
                    worst, where = a / b - 1.0, self.problem.logs[k].path
        return (worst, where) if where else (None, None)

    def at_floor(self, fo: FitOutcome) -> float | None:
        """The pooled repeatability floor when every log repeats a protocol and the fit ``fo``
        predicts each protocol's runs within that protocol's floor (mean speed NRMSE), else
        None (a log without repeats, or a protocol above its floor, may still hold structure
        to chase)."""
        paths = {p for f in self.floors for p in f.logs}
        if not self.floors or any(log.path not in paths for log in self.problem.logs):
            return None
        tab = error_table(self.problem, self.problem.simulate_all(fo.values))
        err = {log.path: r.get("omega", math.nan)
               for log, r in zip(self.problem.logs, tab, strict=True)}
        for f in self.floors:
            if not float(np.mean([err[p] for p in f.logs])) <= f.value:
                return None
        return floor_of(self.floors)


def baseline(run: Run) -> FitOutcome:
    """The base parameters refitted on the fit part, from the model and (a model without
    friction) from some friction, the better kept: the fair reference for every candidate."""
    cur = run.robust_fit(run.vals0, run.base_free)
    friction = [p for p in ("bc", "dz") if p in run.base_free]
    if friction and all(run.vals0[p] < 0.01 * run.ctx0.torque_scale for p in friction):
        nudge = {p: NUDGE * run.ctx0.torque_scale for p in friction}
        alt = unseen_dead_zone(run, run.fit({**run.vals0, **nudge}, run.base_free))
        if alt.chi2["fit"] < cur.chi2["fit"]:
            cur = alt
    return cur


def unseen_dead_zone(run: Run, fo: FitOutcome) -> FitOutcome:
    """``fo`` refitted from the model's own dead zone where the nudge's stayed unseen: on the
    fit part it fits as well there (a chi-square rise of at most two standard errors,
    :func:`~pmdcid.diagnose.final.two_se`). A dead zone the logs' inputs never dwell in keeps
    the value other data gave it rather than the nudge's, which a lag taken later turns into a
    dead zone on the lagged torque that holds a logged steady speed at its edge
    (bench/thinlogs.py b2:viscous_asymmetry seed 39: 2.9 V nudged on steps of 5, 15 and -8 V,
    then 2.7 +- 0.06 V with the lag for a true 0.10 V, the held-out 3 V step 0.10 -> 0.29)."""
    dz0 = run.vals0["dz"]
    if "dz" not in run.base_free or fo.values["dz"] == dz0:
        return fo
    back = {**fo.values, "dz": dz0}
    if run.problem.chi2(back)["fit"] - fo.chi2["fit"] > two_se(run.problem, fo, "fit"):
        return fo
    return run.fit(back, run.base_free)


def screen(run: Run, cur: FitOutcome, pool: list[str]) -> list[Screen]:
    """Every effect of ``pool`` screened against the residual of ``cur``."""
    sims = run.problem.simulate_all(cur.values)
    # a lumped model's lag is not a column of the screen: its sensitivity is nearly J's (the
    # folded lag is J's share), and a linearised step along both threw J negative on the L298N
    # rig (a start no refit survives); the refits free it
    base = [p for p in run.base_free if p not in LAG_PARAMS]
    scr = Screener(run.problem, cur.values, context(run.problem, cur.values, sims), base)
    pmap(scr.base_column, base)  # shared by every effect's screen: made first
    return pmap(lambda e: scr.screen(EFFECTS[e]), pool)


def _screen_reason(s: Screen, ranked: list[Screen], refit_top: int) -> str:
    if not s.start:
        return "screen: the residual does not point at it (no starting guess)"
    if not s.approx_delta_bic < 0:
        return f"screen: approximate ΔBIC {s.approx_delta_bic:+.1f} ≥ 0"
    return f"screen: not among the {refit_top} largest screening gains"


def accept(cands: list[Candidate], rules: Rules) -> Candidate | None:
    """The one rule set: flag identical rows, judge every counted candidate, choose the
    passing one with the lowest ΔBIC; every row's ``reason`` says why."""
    counted = [c for c in cands if c.counted]
    for name, other in same_rows(counted).items():
        c = next(x for x in counted if x.effect == name)
        c.status, c.reason = "degenerate", f"degenerate: identical to {other}'s row; not counted"
    passing = []
    for c in cands:
        if c.counted:
            ok, c.reason = judge(c, rules)
            if ok and generalises(c):
                ok, c.reason = False, generalises(c)
            if ok:
                c.passed = True
                passing.append(c)
    if not passing:
        return None
    lowest = min(passing, key=lambda c: c.delta_bic)
    best = prefer_named(lowest, passing)
    best.chosen = True
    best.reason = "chosen: " + best.reason + (
        f" (lowest ΔBIC of {len(passing)} passing)" if len(passing) > 1 and best is lowest
        else "")
    for c in passing:
        if c is not best and "not chosen" not in c.reason:
            c.reason += f"; {best.effect} dropped the ΔBIC more ({best.delta_bic:+.0f})"
    return best


def search(run: Run, cur: FitOutcome, pool: list[str], notes: list[str]):
    """Rounds of screen, refit the strongest, accept; returns (fit, added, every row seen,
    every refit in order)."""
    added: list[str] = []
    seen: dict[str, Candidate] = {}
    history: list[Candidate] = []
    cur_free = list(run.base_free)
    refit_top = run.settings.refit_top
    for rnd in range(1, run.settings.max_rounds + 1):
        fl = run.at_floor(cur)
        if fl is not None:
            notes.append(f"the model predicts the repeated logs within their repeatability floor "
                         f"(speed NRMSE {fl:.3g}): structure below it is not chased")
            break
        if not pool:
            break
        run.say(f"diagnose round {rnd}: screening {len(pool)} effect(s)")
        screens = screen(run, cur, pool)
        ranked = with_named(sorted((s for s in screens if s.start and s.approx_delta_bic < 0),
                                   key=lambda s: -s.gain)[:refit_top], screens)
        for s in screens:
            seen[s.effect] = Candidate(s.effect, rnd, s.gain, s.approx_delta_bic,
                                       reason=_screen_reason(s, ranked, refit_top))
        rebase = None  # a better point of the current model met while refitting a candidate
        cands = []
        for s in ranked:
            run.say(f"diagnose round {rnd}: refitting {s.effect}")
        # the candidates' refits are independent: shared with the spare CPUs (runtime/cpus.py;
        # the same results in the same order for any number of threads)
        done = pmap(lambda s, cur=cur, free=cur_free, rnd=rnd:
                    evaluate(run, s, cur, effect_free(s.effect) + free, rnd), ranked)
        for s, (c, ref) in zip(ranked, done, strict=True):
            seen[s.effect] = c
            history.append(c)
            cands.append(c)
            if ref["values"] is not cur.values and (rebase is None
                                                    or ref["chi2"]["fit"] < rebase[1]["fit"]):
                rebase = (ref["values"], ref["chi2"])
        best = accept(cands, run.settings.rules)
        # on a lumped model whose armature lag is folded, a delay or a speed law and the lag
        # are decided together (lawlag.py): the lag may take the delay's place or join the law
        best, lagged = decide(run, best, [c for c in cands if c.passed], cur, cur_free,
                              effect_free)
        if lagged is not None:
            cur_free = run.base_free + [p for e in added for p in effect_free(e)]
        if best is None and lagged is not None:
            cur = run.robust_fit(lagged.values, cur_free, nfev=4 * run.settings.max_nfev)
            continue
        if best is None:
            gain = run.settings.rules.min_gain
            if rebase is not None and rebase[1]["fit"] < (1 - gain) * cur.chi2["fit"]:
                # no effect, but the current model fits clearly better elsewhere: move there
                # and screen again
                better = run.fit(rebase[0], cur_free)
                if better.chi2["fit"] < cur.chi2["fit"]:
                    cur = better
                    continue
            break
        added.append(best.effect)
        pool.remove(best.effect)
        cur_free = run.base_free + [p for e in added for p in effect_free(e)]
        cur = run.robust_fit(best.outcome.values, cur_free, nfev=4 * run.settings.max_nfev)
    return cur, added, seen, history


def diagnose(logs: Sequence, model: Model, effects: Sequence[str] | None = None,
             settings: Settings | None = None, progress=None,
             ramp: float | None = None) -> DiagnoseResult:
    """Find the catalogue effects ``model`` lacks on ``logs``, add them, refit, report.

    ``effects`` restricts the catalogue searched (default: every effect screened by default,
    i.e. all but ``lugre``, not already in the model). ``settings``: how the search runs and
    the rules a candidate must pass (:class:`~pmdcid.diagnose.settings.Settings`).
    The input model is not modified. ``progress(msg)`` is called as each round starts and
    before each candidate's refit. ``ramp``: how slowly logged, continuously varying inputs
    varied between samples (fit-nonlinear's reading; :mod:`pmdcid.diagnose.slow_inputs`), profiled
    here when such a log is given without it.
    """
    from pmdcid.io import bounds

    bounds.check_rows(logs, bounds.MAX_DIAGNOSE_ROWS, "diagnose")  # before the work
    with blas_single_thread():
        return _diagnose(logs, model, effects, settings or Settings(),
                         progress or (lambda msg: None), ramp)


def search_pool(problem: Problem, model: Model, effects) -> list[str]:
    if effects is not None:
        unknown = [e for e in effects if e not in EFFECTS]
        if unknown:
            raise ModelError(f"unknown effect(s) {', '.join(unknown)} "
                             f"(known: {', '.join(EFFECTS)})")
    wanted = (lambda e: EFFECTS[e].screened) if effects is None else (lambda e: e in effects)
    # a lumped (per-volt) model folds the electrical side in (model/lumped.py): an effect on the
    # armature circuit (back-EMF, a brush drop) means nothing there, and a brush drop's dead band
    # would only stand in for the per-volt dead zone and Coulomb friction
    lumped = is_lumped(model)
    return [e for e in EFFECTS if e not in model.effects and wanted(e)
            and not (lumped and EFFECTS[e].acts_on == "electrical")
            and all(problem.measures(s) for s in EFFECTS[e].requires)]


def final_model(run: Run, cur: FitOutcome, added: list[str], notes: list[str], history):
    """The final fit on all data (:func:`~pmdcid.diagnose.final.finalise`) and the lag tried in
    a sensor delay's place (:mod:`pmdcid.diagnose.lag`), also the delay the model came with
    (fit-mechanical's latency, fitted without the effects found here) when nothing was added:
    (fit, its free parameters, how the lag came in: ``lag_for_delay``'s "replaced", "beside"
    or ""); (None, [], "") when there is nothing to write."""
    retry = not (added or run.lag_taken) and lag_applies(run, added, cur.values)
    if not (added or run.lag_taken or retry):
        return None, [], ""
    run.say("diagnose: final refit")
    said: list[str] = []  # a retry that keeps the delay writes nothing and says nothing new
    final, free = finalise(run, cur, added, said, history)
    final, free, how = lag_for_delay(run, final, free, added, said)
    if retry and not how:
        notes.extend(n for n in said if n.startswith(DELAY_EFFECT))
        return None, [], ""
    notes.extend(said)
    if how == "replaced":  # the model's own delay is gone too: not refitted after this
        run.base_free = [p for p in run.base_free if p != DELAY]
    if run.lag_taken:
        notes.append(lag_note(final.values))
    return final, free, how


def _refuse_reversed_speed(problem: Problem, vals: dict[str, float]) -> None:
    """A speed that runs against the model's on every log: refused before any refit (the
    friction would grow to hold the rotor back, bc in kN m)."""
    sims = problem.simulate_all(vals)
    pairs = [(sim.omega, np.asarray(log["omega"], float))
             for log, sim in zip(problem.logs, sims, strict=True)
             if sim is not None and log.has("omega") and not log.blocked]
    line = speed_against(pairs)
    if line:
        raise FitError(line, ", ".join(str(log.path) for log in problem.logs))


def _diagnose(logs, model, effects, settings: Settings, say, ramp=None) -> DiagnoseResult:
    problem = Problem(logs, settings.split, settings.max_samples, holdout_plan(logs))
    pool = search_pool(problem, model, effects)
    run = Run(problem, model, settings)
    _refuse_reversed_speed(problem, run.vals0)
    run.pool = pool
    run.say = say
    notes: list[str] = []
    read_slow_inputs(run, ramp, notes)
    run.folds = Folds(run)  # after the input readings: the folds share them
    base = baseline(run)
    cur, added, seen, history = search(run, base, pool, notes)
    new = model.copy()
    final, free, how = final_model(run, cur, added, notes, history)
    lagged = bool(how) or run.lag_taken
    if added or lagged:
        write_model(new, final, free, added)
        if how == "replaced" and DELAY_EFFECT in new.effects:  # the model's own, now the lag
            new.effects.remove(DELAY_EFFECT)
            new.parameters.pop(DELAY, None)
        final_vals = final.values
    else:
        final_vals = cur.values
    return summarise(run, new, base, final_vals, added, seen, history, notes,
                     LAG_PARAMS if lagged else ())


__all__ = ["Candidate", "DiagnoseResult", "Settings", "diagnose", "free_base", "search_pool"]
