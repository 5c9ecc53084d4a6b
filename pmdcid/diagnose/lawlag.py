"""The speed law and the armature's lag decided together, on a lumped model whose lag is folded.

On voltage and speed alone a lumped model without ``tau_e`` (fit-mechanical's steps did not
resolve the lag: L/R a fraction of a sample, or a speed law the steps lacked hid it) carries the
armature's L/R folded into J (:mod:`pmdcid.model.lumped`). That folded lag leaves a residual at
every edge of the input which two kinds of candidate chase: a ``sensor_delay`` (a delay of about
L/R: a delay where there is none), and a speed law, the flexible friction curve more than a
named one (issue 24: the curve beat a true quadratic drag by 77 in ΔBIC; given the true lag the
drag alone was chosen). Freeing the lag in the baseline does not help: a speed law the model
still lacks hides it there (tau_e went to 0). So the two are decided together, in the round
that would add either (:func:`decide`):

- the round's choice is a **sensor delay**: the same refit with the delay off and the lag free in
  its place (:func:`with_lag`) is tried first; where it fits every sample (fit and held-out
  part) as well, or the delay is under two samples and does not fit decisively better
  (:func:`lag_holds`: every motor has its L/R, a delay must earn its place), and the lag's
  tau_e is determined (:func:`lag_resolved`: the rules' ``min_z`` standard errors, the size the
  delay had to reach), the lag is taken instead (a base parameter of the lumped model from then
  on) and the delay is not added;
- the round's choice is a **speed law**: every passing speed law is refitted with the lag free
  too, and the law is chosen on the pairs (lowest ΔBIC, a named law preferred to the curve
  unless the curve beats it by more than :data:`~pmdcid.diagnose.named.NAMED_MARGIN`); the lag
  is kept where it lowers the pair's ΔBIC decisively (by more than the rules' ``bic``).

Either way the lag's parameters (``tau_e``, ``ke_share``) then join the free base parameters
(screened, refitted with every later candidate and in the final fit, written in the model).
The lag's fit starts from a grid (:func:`lag_start`): tau_e over a few sample fractions (and the
delay it replaces) by the back-EMF's share over fit-nonlinear's grid (at a share of 1 a dead
zone above bc holds every steady state: a local fit from there stops far off; a friction
curve's lag was once refused at 3x the delay's chi-square that way).

A lumped model that comes with a lag (fit-mechanical resolved it) has it refitted with every
candidate (:func:`~pmdcid.diagnose.loop.free_base`: it was fitted without the effects diagnose
adds), and tau_e then stands in for a sensor delay in the held-out test
(:func:`~pmdcid.diagnose.candidates.stand_ins`). Measured: ``python bench/lawlag.py`` (docs/
effects.md, "The speed law and the armature's lag").
"""

from __future__ import annotations

import math

from pmdcid.diagnose.lagvalley import share_correlations, valley_restart
from pmdcid.diagnose.named import CURVE, NAMED_LAWS, NAMED_MARGIN
from pmdcid.diagnose.starts import lowest_trial
from pmdcid.fit.problem import FitOutcome
from pmdcid.identify.latency import MIN_SAMPLES
from pmdcid.identify.nonlinear import KE_SHARES
from pmdcid.identify.share_valley import at_share
from pmdcid.model.lumped import is_lumped
from pmdcid.runtime.cpus import pmap

#: the lag's parameters (model/lumped.py)
LAG_PARAMS = ("tau_e", "ke_share")
#: the effect a folded lag is taken for, and its parameter
DELAY_EFFECT, DELAY = "sensor_delay", "delay"
#: the speed laws decided with the lag
SPEED_LAWS = (*NAMED_LAWS, CURVE)
#: tau_e's starts, in sample periods (L/R from a fifth of a sample at 100 Hz to a few at 1 kHz)
TAU_SAMPLES = (0.1, 0.3, 1.0, 3.0)


def lag_folded(run, vals: dict[str, float]) -> bool:
    """A lumped model on logs without current whose lag is not in ``vals`` (folded into J)."""
    return (is_lumped(run.model) and not run.problem.measures("i")
            and not vals.get("tau_e", 0.0) > 0 and "tau_e" not in run.base_free)


def lag_start(run, vals: dict[str, float], free, part: str, taus) -> dict[str, float]:
    """Start for a refit with the lag free: the best of tau_e over ``taus`` [s] and the
    back-EMF's share over fit-nonlinear's grid (chi-square of ``part``), the rest at ``vals``.
    The dead zone stays where it is: with the lag it acts on the lagged torque, and a step from
    rest just above it starts late, so a grid over it found a dead zone standing in for a delay
    (5.6 V on the L298N rig, whose commands never fall below 6 V; the model's 1.8 V fits as
    well without the onset)."""
    problem = run.problem
    trials = [{**vals, "tau_e": t, "ke_share": s} for t in taus for s in KE_SHARES]
    best, _ = lowest_trial(problem, trials, part, trials[0], problem.cost(trials[0], part))
    return best


def lag_starts(run, vals: dict[str, float], part: str, taus, k: int) -> list[dict[str, float]]:
    """The ``k`` lowest-cost starts of :func:`lag_start`'s grid, each at another back-EMF share
    (each share's best tau_e), lowest first: local fits from a share at its bound (0) stopped
    there or crossed to the valley's middle on differences of 1e-11 in the start (issue 24:
    chi-square 1128 against 1094.8 on one motor)."""
    problem = run.problem
    trials = [{**vals, "tau_e": t, "ke_share": s} for t in taus for s in KE_SHARES]
    costs = pmap(lambda v: problem.cost(v, part), trials)
    best: dict[float, tuple[float, int]] = {}
    for j, (trial, c) in enumerate(zip(trials, costs, strict=True)):
        share = trial["ke_share"]
        if share not in best or c < best[share][0]:
            best[share] = (c, j)
    return [trials[j] for _, j in sorted(best.values())[:k]]


def with_lag(run, vals: dict[str, float], free, part: str = "fit", taus=None,
             nfev: int | None = None) -> FitOutcome:
    """Refit of ``free`` and the lag from :func:`lag_start` (``taus``: tau_e's starts [s],
    default :data:`TAU_SAMPLES` sample periods), then from the back-EMF share's valley's
    other dips (:func:`~pmdcid.diagnose.lagvalley.valley_restart`): the grid holds the
    friction and the dead zone, and the local fit, whose cost is a staircase in dz, leaves
    them where the lag-less fit had them (bench/lawlag.py --family hobby, seed 1, 500 Hz, L/R
    2 ms: share 0.26, bc' 0.139 for 0.094, chi-square 65185 on all data; from the valley's
    dip 6428, the truth's 6109; stopped there, a friction curve, a torque offset and a
    quadratic drag then stood in for the friction, the held-out step from rest 0.017 ->
    0.031)."""
    dt = min(log.dt for log in run.problem.logs)
    taus = taus or [f * dt for f in TAU_SAMPLES]
    lag_free = [p for p in dict.fromkeys([*free, *LAG_PARAMS])]
    fo = run.fit(lag_start(run, vals, lag_free, part, taus), lag_free, part, nfev)
    return valley_restart(run, fo, lag_free, part=part)


def lag_holds(n: int, chi2_lag: float, chi2_delay: float, bic: float,
              delay_samples: float) -> bool:
    """Whether the lumped model's own lag (chi-square ``chi2_lag`` over ``n`` samples) stands
    against a sensor delay of ``delay_samples`` sample periods in its place (``chi2_delay``):
    where it fits at least as well; and, for a delay under
    :data:`~pmdcid.identify.latency.MIN_SAMPLES` samples (the least latency fit-mechanical
    keeps: the zero-order hold and a speed counted over the last sample offset the speed by
    half a sample each), unless the delay fits decisively better (n log of the ratio beyond the
    rules' ``bic``, -10). Every motor has its L/R, a delay is an effect: within a sample the two
    make the same late start (issue 24: a 2 ms L/R at 100 Hz read as a 1.8 ms delay, the
    chi-squares 0.7 apart in 1100)."""
    if chi2_lag <= chi2_delay:
        return True
    if delay_samples >= MIN_SAMPLES:
        return False
    return n * math.log(max(chi2_lag, 1e-300) / max(chi2_delay, 1e-300)) <= -bic


def lag_z(fo: FitOutcome, rho: float = math.nan) -> float:
    """tau_e's size in the fit ``fo`` in standard errors (0 where it has none or no finite
    error: a lag the fit cannot bound away from zero); with ``rho``, tau_e's local correlation
    with the back-EMF share, its error with the share held
    (:func:`~pmdcid.identify.share_valley.at_share`)."""
    est = fo.estimates.get("tau_e")
    if est is None or not (est.stderr > 0 and math.isfinite(est.stderr)):
        return 0.0
    return abs(est.value) / at_share(est.stderr, rho)


def lag_resolved(fo: FitOutcome, min_z: float, rho: float = math.nan) -> bool:
    """Whether the fit ``fo`` determines its lag: tau_e at least ``min_z`` standard errors
    (the rules' size an effect must reach; ``rho`` as :func:`lag_z`). A lag taken in a delay's
    place stands in for an effect that passed that rule and the held-out test; one the logs do
    not determine only moves what they did (issue 24, LEGO-like rig on an 11 ms loop-timed
    grid: tau_e 4.6 +- 4.6 ms for an L/R of 0.75 ms, the back-EMF's share 0.04 +- 9 for 0.98,
    and the dead zone, masked below 0.8 V, moved to 1.38 V on the lagged voltage to make the
    delay's late start: the held-out sines' error 0.023 -> 0.031)."""
    return lag_z(fo, rho) >= min_z


def share_rho(run, fo: FitOutcome, free: list[str]) -> float:
    """tau_e's local correlation with the back-EMF share in the fit ``fo`` of ``free`` (from
    the envelope Jacobian's ``(J'J)^-1``), NaN where either is not free or it cannot be read.
    Along the share's valley J and tau_e trade with the share at equal linear response
    (:mod:`pmdcid.identify.share_valley`), and tau_e stays positive at every share of it: where
    the logs do not tell the share, tau_e's marginal error is the valley's, not the lag's
    (bench/lawlag.py --family share03, 500 Hz, L/R 2 ms, seed 2: the lag in a delay's place
    fitting 32 chi-square units better, tau_e 2.05 ms at 0.73 standard errors)."""
    names = [n for n in free if n in fo.values]
    if "tau_e" not in names or "ke_share" not in names:
        return math.nan
    _, _, curv = run.problem.envelope_errors(fo.values, names)
    return share_correlations(names, curv).get("tau_e", math.nan)


def delta_bic(run, chi2: float, ref: float, k: int, part: str = "fit") -> float:
    """BIC of a fit with chi-square ``chi2`` and ``k`` more parameters than one with ``ref``,
    less that one's, on ``part``'s samples."""
    n = run.problem.count(part)
    return n * math.log(max(chi2, 1e-300) / max(ref, 1e-300)) + k * math.log(max(n, 2))


def decide(run, best, passing: list, cur: FitOutcome, free: list[str], effect_free):
    """The round's choice ``best`` (of the candidates ``passing``) decided with the lag on a
    lumped model whose lag is folded (module docstring). Returns (the candidate to add or None,
    the fit with the lag to continue from or None); ``run.base_free`` gains the lag when it is
    taken, and the rows' reasons say so."""
    if best is None or not lag_folded(run, cur.values):
        return best, None
    if best.effect == DELAY_EFFECT:
        return _delay_or_lag(run, best, free)
    if best.effect not in SPEED_LAWS:
        return best, None
    laws = [c for c in passing if c.effect in SPEED_LAWS]
    pairs = {c.effect: with_lag(run, c.outcome.values, free + effect_free(c.effect))
             for c in laws}
    k_lag = len(LAG_PARAMS)
    score = {c.effect: delta_bic(run, pairs[c.effect].chi2["fit"], cur.chi2["fit"],
                             len(effect_free(c.effect)) + k_lag) for c in laws}
    chosen = min(laws, key=lambda c: score[c.effect])
    named = [c for c in laws if c.effect in NAMED_LAWS]
    if chosen.effect == CURVE and named:
        law = min(named, key=lambda c: score[c.effect])
        if not score[CURVE] < score[law.effect] - NAMED_MARGIN:
            chosen = law
    pair = pairs[chosen.effect]
    gain = delta_bic(run, pair.chi2["fit"], chosen.outcome.chi2["fit"], k_lag)
    if not gain < run.settings.rules.bic:
        return best, None  # the lag is not decisive beside the law: the round's choice stands
    alone = _lag_without_law(run, [best, chosen], pair, cur, free, effect_free)
    if alone is not None:
        return None, alone
    if chosen is not best:
        best.chosen = False
        best.reason = best.reason.replace("chosen: ", "", 1) + (
            f"; not chosen: with the armature's lag free, {chosen.effect} explains it about as "
            f"well or better (ΔBIC {score[chosen.effect]:+.0f} vs {score[best.effect]:+.0f})")
        chosen.chosen = True
        chosen.reason = "chosen with the armature's lag: " + chosen.reason
    others = ", ".join(f"{c.effect} {score[c.effect]:+.0f}" for c in laws if c is not chosen)
    chosen.reason += (f"; the lag tau_e = {1e3 * pair.values['tau_e']:.3g} ms taken with it "
                      f"(ΔBIC {gain:+.0f} beside the law alone"
                      + (f"; the pairs' ΔBIC: {chosen.effect} {score[chosen.effect]:+.0f}, "
                         f"{others})" if others else ")"))
    chosen.outcome = pair
    _take_lag(run)
    return chosen, pair


def _lag_without_law(run, rows: list, pair: FitOutcome, cur: FitOutcome, free: list[str],
                     effect_free):
    """The lag's fit without the speed law (``rows[-1]``, the law chosen on the pairs; every
    row of ``rows`` marked not added), where the law beside the lag (``pair``) is not decisive
    in BIC and the lag alone is determined (:func:`lag_resolved`); None otherwise. The law
    passed its tests against a model whose lag was folded, where the lag's own residual at
    every edge stood behind it: beside the lag it must pay for itself again (lr-encoder, 4096
    counts, seed 9: a quadratic drag worth 1.7 % of the held-out error taken with the lag,
    then a friction curve and Stribeck friction of 0.5 % of bc on a motor with none)."""
    law = rows[-1]
    alone = with_lag(run, cur.values, free)
    extra = delta_bic(run, pair.chi2["fit"], alone.chi2["fit"], len(effect_free(law.effect)))
    if extra < run.settings.rules.bic or not lag_resolved(alone, run.settings.rules.min_z):
        return None
    _lag_instead(run, rows, alone, f"explains it, {law.effect} beside it not decisive (ΔBIC "
                 f"{extra:+.0f} > {run.settings.rules.bic:g})")
    return alone


def _delay_or_lag(run, best, free: list[str]):
    """The lag in the delay's place, both refitted on the fit part, where it holds on every
    sample (:func:`lag_holds`): (None, the lag's fit), else (``best``, None)."""
    delay = best.outcome.values[DELAY]
    dt = min(log.dt for log in run.problem.logs)
    taus = sorted({delay, *(f * dt for f in TAU_SAMPLES)} - {0.0})
    lag = with_lag(run, {**best.outcome.values, DELAY: 0.0}, free, taus=taus)
    # both refitted on the fit part: judged on every sample, the held-out ones too
    n, c_lag, c_delay = run.problem.count("all"), lag.chi2["all"], best.outcome.chi2["all"]
    if not lag_holds(n, c_lag, c_delay, run.settings.rules.bic, delay / dt):
        best.reason += (f"; the armature's lag in its place (tau_e "
                        f"{1e3 * lag.values['tau_e']:.3g} ms) fits worse (chi-square "
                        f"{c_lag:.6g} against {c_delay:.6g}, all data)")
        return best, None
    if not lag_resolved(lag, run.settings.rules.min_z):
        best.reason += (f"; the armature's lag in its place fits as well (chi-square "
                        f"{c_lag:.6g} against {c_delay:.6g}, all data) but is not determined "
                        f"(tau_e {1e3 * lag.values['tau_e']:.3g} ms, {lag_z(lag):.2g} standard "
                        f"errors < {run.settings.rules.min_z:g}): the delay stands")
        return best, None
    _lag_instead(run, [best], lag, f"in its place fits about as well or better (chi-square "
                 f"{c_lag:.6g} against {c_delay:.6g}, all data)")
    return None, lag


def _lag_instead(run, rows: list, lag: FitOutcome, why: str) -> None:
    """The lag's fit ``lag`` taken in the place of the candidates ``rows`` (each marked not
    added, ``why`` said after the lag's size), its parameters freed from now on."""
    for row in {id(r): r for r in rows}.values():
        row.chosen = False
        row.reason = row.reason.replace("chosen: ", "", 1) + (
            f"; not added: the armature's lag tau_e = {1e3 * lag.values['tau_e']:.3g} ms (L/R, "
            f"the lumped model's own) {why}")
    _take_lag(run)


def _take_lag(run) -> None:
    run.base_free = [*run.base_free, *(p for p in LAG_PARAMS if p not in run.base_free)]
    run.lag_taken = True


def lag_note(vals: dict[str, float]) -> str:
    return (f"the armature's electrical lag tau_e = {1e3 * vals['tau_e']:.3g} ms (L/R, the "
            "lumped model's own) written: fit-mechanical's steps had not resolved it, and a "
            "delay or a speed law would have stood in for it")


__all__ = ["LAG_PARAMS", "SPEED_LAWS", "decide", "lag_folded", "lag_holds", "lag_resolved",
           "lag_start", "lag_starts", "lag_z", "share_rho",
           "with_lag"]
