"""A transient held out across logs: the test of an effect whose signature sits in transients.

A log without repeats is split in time (:mod:`pmdcid.diagnose.folds`): its head, which holds
its steps' transients, is fitted, and its steady tail held out. An effect whose signature sits
in transients (a sensor delay, a Stribeck breakaway) changes nothing on the tails the other
parameters could not: *possible, not testable* (:mod:`pmdcid.diagnose.testable`), even where
another log's transient could test it.

With two or more such logs, each log's transient tests what the others' fitted. A *fold*
holds out the heads (the transients) of its logs and fits their tails (their steady levels at
those operating points) and every other split log whole; there are at most :data:`MAX_FOLDS`
(the logs, ordered by operating point, dealt round the folds: each fold spans the operating
points, and twenty logs cost three folds, not twenty); the candidate and the model it extends
are each refitted on the fold, and the held-out test is
:func:`~pmdcid.diagnose.testable.heldout_test` on the fold's heads with *every* free parameter
of the model able to stand in for the effect (not only those the effect interacts with: a refit
on fewer logs extrapolates, and an effect must not be credited with correcting that). The
candidate's refit on a fold starts from the model refitted there with the effect's size at
neutral, never from its own refit, which saw the heads the fold holds out. The effect is
testable when at least one fold can tell it from the other parameters, and confirmed only when
*every* fold that can tell it bears it out (the rule of testable.py, per fold). The held-out
likelihood ratio, the held-out gain and the rise of a fold's held-out speed error (diagnose's
other held-out rules) are then taken over the folds' held-out heads; the rise on the speed
channels alone where the logs measure the speed (:func:`speed_rise`), the whole chi-square's
otherwise.

Cost: two refits per fold (the candidate's and the model it extends, the latter shared by the
round's candidates) and the test's simulations, for candidates the time split could not test
and whose fit-part ΔBIC passes.
"""

from __future__ import annotations

import math
import os
import threading
from dataclasses import dataclass

import numpy as np

from pmdcid.diagnose.rules import failed_refit
from pmdcid.diagnose.starts import staged_fit
from pmdcid.diagnose.testable import HeldoutTest, heldout_floor, heldout_test
from pmdcid.fit.problem import FitOutcome, Problem
from pmdcid.model import EFFECTS

#: fewest logs split in time for the folds (one log's transient tests the other's)
MIN_LOGS = 2
#: most folds (each a refit of the model a round extends and of each candidate tested)
MAX_FOLDS = 3


@dataclass(frozen=True)
class FoldsTest:
    """The held-out test over the folds (chi-square units, summed over the folds that can
    test the effect; ``folds``: (log, its own test) per fold)."""

    folds: tuple[tuple[str, HeldoutTest], ...]

    @property
    def _testing(self) -> list[HeldoutTest]:
        return [t for _, t in self.folds if t.testable]

    @property
    def distinct(self) -> float:
        return float(sum(t.distinct for t in self._testing))

    @property
    def confirmed(self) -> float:
        return float(sum(t.confirmed for t in self._testing))

    @property
    def floor(self) -> float:
        testing = self._testing or [t for _, t in self.folds]
        return float(min(t.floor for t in testing)) if testing else 1.0

    @property
    def testable(self) -> bool:
        return bool(self._testing)

    @property
    def confirms(self) -> bool:
        return self.testable and all(t.confirms for t in self._testing)

    @property
    def where(self) -> str:
        return ", ".join(os.path.basename(p) for p, t in self.folds if t.testable)


def fold_logs(problem: Problem) -> list[tuple[int, ...]]:
    """The folds: the logs whose heads each holds out. Every log split in time, when there are
    at least :data:`MIN_LOGS`, ordered by operating point (mean absolute input) and dealt round
    :data:`MAX_FOLDS` folds at most; none otherwise."""
    split = [k for k, p in enumerate(problem.plan) if p == "split"]
    if len(split) < MIN_LOGS:
        return []
    split.sort(key=lambda k: float(np.mean(np.abs(np.asarray(problem.logs[k].u, float)))))
    n = min(len(split), MAX_FOLDS)
    return [tuple(sorted(split[j::n])) for j in range(n)]


def fold_problem(problem: Problem, ks, max_samples: int | None) -> Problem:
    """The fold holding out the heads of logs ``ks``: their tails and every other split log
    fitted, the other logs as planned (at most ``max_samples`` compared samples per
    channel)."""
    plan = ["head" if j in ks else ("fit" if p == "split" else p)
            for j, p in enumerate(problem.plan)]
    fold = Problem(problem.logs, problem.split, max_samples, plan,
                   simulation=problem.simulation)
    fold.set_readings(problem.readings)
    return fold


class Folds:
    """The folds of one diagnose run and, per model a round extends, its refit on each fold
    (made once, shared by the round's candidates: threads may ask at once)."""

    def __init__(self, run):
        self.run = run
        self.logs = fold_logs(run.problem)
        self.problems = {ks: fold_problem(run.problem, ks, run.settings.max_samples)
                         for ks in self.logs}
        #: (the values of the model a round extends, its refit per fold): the values are kept,
        #: not their id, which a later round's values could reuse
        self._refs: tuple[dict | None, dict[tuple[int, ...], FitOutcome]] = (None, {})
        self._lock = threading.Lock()

    def __bool__(self) -> bool:
        return bool(self.logs)

    def fit(self, k: tuple[int, ...], start: dict[str, float], free: list[str]) -> FitOutcome:
        run = self.run
        return staged_fit(self.problems[k], start, free, "fit", run.settings.max_nfev, run.typ,
                          run.limits)

    def references(self, cur: FitOutcome, free: list[str]) -> dict[tuple[int, ...], FitOutcome]:
        """The model ``cur`` (its parameters ``free``) refitted on every fold."""
        with self._lock:
            if self._refs[0] is not cur.values:
                self._refs = (cur.values, {k: self.fit(k, cur.values, free) for k in self.logs})
            return self._refs[1]


@dataclass
class FoldEvidence:
    """What the folds say about one candidate (:class:`Candidate`'s held-out fields)."""

    test: FoldsTest
    heldout: float  # summed held-out n log(chi-square ratio); < 0 better
    chi2_ref: float  # held-out chi-square of the model it extends, summed
    chi2_cand: float
    n_held: int
    rise: float  # largest relative rise of a held-out head's speed error
    rise_log: str


def fold_start(name: str, refit: dict[str, float], ref: dict[str, float]) -> dict[str, float]:
    """Where a fold's refit of effect ``name`` starts: the model it extends as refitted on the
    fold (``ref``), the effect's size at neutral and its other parameters (a Stribeck speed, a
    cogging order and phase) as the candidate's refit ``refit`` found them. Never the refit's
    size: that refit saw the head the fold holds out, and a size the fold's own data cannot
    pull away from neutral must not be carried into its test."""
    eff = EFFECTS[name]
    size = set(eff.size_params or (eff.params[0].name,))
    start = {**ref, **{p: refit[p] for p in eff.param_names}}
    start.update({p.name: p.neutral for p in eff.params
                  if p.name in size and math.isfinite(p.neutral)})
    return start


def fold_refit(folds: Folds, k: tuple[int, ...], name: str, refit: dict[str, float],
               ref: dict[str, float], free: list[str]) -> FitOutcome:
    """The candidate ``name`` refitted on the fold ``k``: from :func:`fold_start` on the fold's
    reference ``ref`` and from the candidate's own refit ``refit`` with the effect's size at
    neutral alike, the lower chi-square of the fold's fitted part kept (its held-out head is
    read by neither choice). From the reference alone, whose base parameters had stood in for
    the effect, the fold's refit stopped beside them: bench/thinlogs.py d:input_delay seed 40
    (current logged, a true 20 ms input delay at 100 Hz), the fold holding out the 5 -> 15 V
    step's transient ended at 8.5 ms with L 48 mH standing in for the rest (chi-square 44816 on
    its fitted part, the truth's L 1.1 mH); from the refit's base values (20 ms, L 2.9 mH) the
    held-out step's speed error, which had risen 40 %, falls 24 %."""
    starts = [fold_start(name, refit, ref), fold_start(name, refit, refit)]
    fits = [folds.fit(k, s, free) for s in starts]
    return min(fits, key=lambda f: f.chi2["fit"])


def fold_evidence(folds: Folds, name: str, fo: FitOutcome, cur: FitOutcome, cur_free: list[str],
                  free: list[str]) -> FoldEvidence | None:
    """The candidate ``name`` (refitted as ``fo`` on the time split, ``free`` its refit's
    parameters) refitted and tested on every fold against ``cur`` (parameters ``cur_free``)
    refitted there; None without folds."""
    if not folds:
        return None
    refs = folds.references(cur, cur_free)
    eff = EFFECTS[name]
    off = {p.name: p.neutral for p in eff.params if p.name not in eff.held}
    run = folds.run
    tests, ho, c_ref, c_cand, n_held, rise, rise_log = [], 0.0, 0.0, 0.0, 0, -math.inf, ""
    for k in folds.logs:
        prob, ref = folds.problems[k], refs[k]
        cand = fold_refit(folds, k, name, fo.values, ref.values, free)
        if failed_refit(cand.chi2["fit"], ref.chi2["fit"]):
            cand = FitOutcome({**ref.values, **off}, {}, ref.stats, ref.chi2, ref.n)
        n = prob.count("held")
        floor = heldout_floor(run.settings.rules, n, ref.chi2["held"])
        others = [p for p in free if p not in off]
        test = heldout_test(prob, cand.values, name, others, run.ctx0.torque_scale, floor)
        path = ", ".join(os.path.basename(prob.logs[j].path) for j in k)
        tests.append((path, test))
        a, b = max(cand.chi2["held"], 1e-300), max(ref.chi2["held"], 1e-300)
        ho += n * math.log(a / b)
        c_ref, c_cand, n_held = c_ref + b, c_cand + a, n_held + n
        up = speed_rise(prob, cand.values, ref.values)
        up = math.sqrt(a / b) - 1.0 if up is None else up
        if up > rise:
            rise, rise_log = up, os.path.basename(path)
    return FoldEvidence(FoldsTest(tuple(tests)), ho, c_ref, c_cand, n_held, rise, rise_log)


def speed_rise(prob: Problem, cand: dict[str, float], ref: dict[str, float]) -> float | None:
    """Relative rise of the held-out speed error from ``ref`` to ``cand`` on ``prob``'s held
    part: the root of the ratio of the speed channels' chi-squares (None without a speed
    channel there). The whole chi-square would let a better current hide a worse speed (a
    brush drop that fitted the current of three step logs better raised every log's speed
    error 8-11 %, bench/newrigs.py freerun-vmeas seed 2)."""
    blocks = [(a, b) for ch, a, b in prob.blocks("held") if ch.signal == "omega"]
    if not blocks:
        return None

    def chi2(vals):
        r = prob.weighted(prob.simulate_all(vals, "held"), "held")
        return sum(float(np.sum(r[a:b] ** 2)) for a, b in blocks)

    return math.sqrt(max(chi2(cand), 1e-300) / max(chi2(ref), 1e-300)) - 1.0


__all__ = ["MIN_LOGS", "FoldEvidence", "Folds", "FoldsTest", "fold_evidence", "fold_logs",
           "fold_problem", "speed_rise"]
