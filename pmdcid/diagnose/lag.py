"""A sensor delay on a lumped model without an electrical lag: the armature's L/R instead.

On voltage and speed alone (a lumped, per-volt model, :mod:`pmdcid.model.lumped`) a late start
of the speed after each edge of the input is either the speed read late (``sensor_delay``) or
the armature current rising with its time constant L/R (the lumped model's ``tau_e``), which
every motor has. Where fit-mechanical's steps did not resolve the lag (the model has none),
diagnose's delay finds L/R (issue 24's checks: 1.91 ms on a motor with L/R 2 ms and no
latency). The round that would add the delay already tries the lag in its place
(:mod:`pmdcid.diagnose.lawlag`); a delay that got past it (added in a later round, kept
there, or the model's own: fit-mechanical's latency, fitted without the speed law diagnose
found) is tried once more in the final model: the same model with the delay off and the lag
free in its place (from :func:`~pmdcid.diagnose.lawlag.lag_start`'s grid, refitted with every
parameter the final fit frees, on all data); unless the delay fits decisively better
(:func:`~pmdcid.diagnose.lawlag.lag_holds`) or the lag is not determined (tau_e under the rules'
``min_z`` standard errors, :func:`~pmdcid.diagnose.lawlag.lag_resolved`; its error with the
back-EMF share held, :func:`~pmdcid.diagnose.lawlag.share_rho`: along the share's valley tau_e
trades with J and stays positive, and a share the logs do not tell inflates its marginal
error, not the lag's), the lag is written
(``tau_e``, ``ke_share``) and the delay is not; a note gives both chi-squares either way. The
lag's fit frees what the final fit freed, the delay excepted: a dead zone the final fit settled
at a point (:func:`~pmdcid.diagnose.final.settle_dead_zone`) stays there for that fit, and is
settled again once the lag replaced the delay, on its profile refitted with the lag
(:mod:`pmdcid.diagnose.lagdz`).
"""

from __future__ import annotations

import dataclasses
import math

from pmdcid.diagnose.final import honest_errors, settle_dead_zone
from pmdcid.diagnose.lagvalley import valley_restart
from pmdcid.diagnose.lawlag import (
    DELAY,
    DELAY_EFFECT,
    LAG_PARAMS,
    TAU_SAMPLES,
    delta_bic,
    lag_holds,
    lag_resolved,
    lag_starts,
    lag_z,
    share_rho,
)
from pmdcid.diagnose.starts import staged_fit
from pmdcid.fit.problem import FitOutcome
from pmdcid.fit.results import bounded
from pmdcid.identify.latency import MIN_SAMPLES
from pmdcid.model.lumped import is_lumped

#: local fits of the lag in a delay's place, from the grid's best back-EMF shares
LAG_STARTS = 3


def lag_applies(run, added: list[str], vals: dict[str, float]) -> bool:
    """On a lumped model whose lag fit-mechanical did not resolve, on logs without current: a
    sensor delay added without a lag (``vals``: the fit's; a delay added beside a lag diagnose
    took was tested against it), or the delay the model came with (fit-mechanical's latency,
    fitted without the effects found here)."""
    if not is_lumped(run.model) or run.problem.measures("i") or run.vals0.get("tau_e", 0.0) > 0:
        return False
    return ((DELAY_EFFECT in added and not vals.get("tau_e", 0.0) > 0)
            or DELAY_EFFECT in run.model.effects)


def _lag_fit(run, final: FitOutcome, lag_free: list[str], start: dict[str, float],
             taus, move_dz: bool = False) -> FitOutcome:
    """The final fit's parameters ``lag_free`` refitted on all data from ``start``, from the
    best of a grid over tau_e (``taus``), the back-EMF's share and the dead zone when the fit
    has no lag yet (lawlag.lag_start: from a share of 1 alone a local fit stopped at 3x the
    delay's chi-square beside a friction curve), from the :data:`LAG_STARTS` best shares of
    that grid (lawlag.lag_starts), the lowest kept and refitted from its share's valley's other
    dips (:func:`~pmdcid.diagnose.lagvalley.valley_restart`: the grid holds J, the valley moves
    it with the share); the final fit's other estimates carried.
    With ``move_dz`` (the lag in the delay's place), a dead zone the final fit settled at a
    point of an interval (:func:`_settled_dz`) moves within that interval (:func:`_within`);
    beside the delay it stays at the point settled with it."""
    interval = _settled_dz(final, lag_free) if move_dz else None
    starts = [start]
    if not final.values.get("tau_e", 0.0) > 0:
        taus = [t for t in taus if t > 0]
        starts = lag_starts(run, start, "all", taus, LAG_STARTS)
        if interval is not None:  # the interval's low end: a dead zone the delay needed
            lo, hi = interval
            starts += [lag_starts(run, {**start, "dz": lo + f * (hi - lo)}, "all", taus, 1)[0]
                       for f in DZ_POINTS]
    fits = [_within(run, s, lag_free, interval) for s in starts]
    fo = valley_restart(run, min(fits, key=lambda f: f.chi2["all"]), lag_free)
    for name, est in final.estimates.items():
        if name not in lag_free and name != DELAY:
            fo.estimates.setdefault(name, est)  # the settled dead zone's interval
    if interval is not None:
        est = final.estimates["dz"]
        fo.estimates["dz"] = bounded("dz", *interval, est.unit, est.caveat, fo.values["dz"])
    return fo


#: where in a settled dead zone's interval the lag's fit also starts (fractions from its low end)
DZ_POINTS = (0.05, 0.25)


def _settled_dz(final: FitOutcome, lag_free: list[str]) -> tuple[float, float] | None:
    """The interval of a dead zone the final fit settled at a point (these logs bound it, do
    not determine it: :func:`~pmdcid.diagnose.final.settle_dead_zone`), or None."""
    est = final.estimates.get("dz")
    if "dz" in lag_free or est is None or est.interval is None:
        return None
    return est.interval


def _within(run, start: dict[str, float], free: list[str], interval) -> FitOutcome:
    """``run.fit`` of ``free`` on all data; with a settled dead zone's ``interval``, the dead
    zone free within it too. Settled with the delay in the model, its point is the delay's: a
    dead zone above the breakaway holds a rotor from rest a little longer, a late start (the
    friction-curve red team, lawlag.py: 0.63 V where the truth had 0.05; held there, the lag
    in the delay's place fitted worse by 80 in chi-square, freed inside the interval better by
    560 with the truth's 4.0 ms). Free only inside the interval: refitted unbounded, it drifts
    along the flat cost (3.3 +- 17 V on the L298N rig)."""
    if interval is None:
        return run.fit(start, free, "all")
    lo, hi = interval
    start = {**start, "dz": min(max(start["dz"], lo), hi)}
    return staged_fit(run.problem, start, [*free, "dz"], "all", run.settings.max_nfev, run.typ,
                      {**(run.limits or {}), "dz": (lo, hi)})


def lag_for_delay(run, final: FitOutcome, free: list[str], added: list[str],
                  notes: list[str]) -> tuple[FitOutcome, list[str], str]:
    """The final fit with the armature's lag in place of its sensor delay (added, or the
    model's own) where that fits all data about as well (a latency of whole samples: decisively
    better, :func:`_decisive_latency_free`), else beside it where that is decisive and the
    held-out data bear it out (module docstring): (fit, its free parameters, "replaced",
    "beside" or "" for neither); ``added`` and ``notes`` updated in place."""
    if not lag_applies(run, added, final.values):
        return final, free, ""
    delay = final.values[DELAY]
    n, dt = run.problem.count("all"), min(lg.dt for lg in run.problem.logs)
    taus = sorted({delay, *(f * dt for f in TAU_SAMPLES)})
    # the final fit's free parameters (a dead zone it settled at a point stays there: refitted,
    # it drifts along the flat cost, once to 3.3 +- 17 V on the L298N rig) but the delay's
    lag_free = list(dict.fromkeys([p for p in free if p != DELAY] + list(LAG_PARAMS)))
    lag = _lag_fit(run, final, lag_free, {**final.values, DELAY: 0.0}, taus, move_dz=True)
    min_z = run.settings.rules.min_z
    holds = lag_holds(n, lag.chi2["all"], final.chi2["all"], run.settings.rules.bic, delay / dt)
    tie = holds and delay / dt >= MIN_SAMPLES and not _decisive_latency_free(run, final, free,
                                                                               lag)
    rho = share_rho(run, lag, lag_free)  # tau_e's error with the back-EMF share held
    if holds and not tie and lag_resolved(lag, min_z, rho):
        lag, lag_free = _replaced(run, final, lag, lag_free, added, notes)
        return lag, lag_free, "replaced"
    place = ("fits worse" if not holds else "fits about as well, not decisively better on the "
             "residual's effective samples (the latency, of whole samples, may be real)" if tie
             else f"fits as well but is not determined ({lag_z(lag, rho):.2g} standard errors < "
             f"{min_z:g})")
    kept = (f"{DELAY_EFFECT} ({1e3 * delay:.3g} ms) kept: the armature's electrical lag in its "
            f"place (tau_e {1e3 * lag.values['tau_e']:.3g} ms, no delay) {place} "
            f"(chi-square {lag.chi2['all']:.6g} against {final.chi2['all']:.6g})")
    shorter = [f * dt for f in TAU_SAMPLES if f * dt < delay]
    if not shorter:  # refitted to under a tenth of a sample (the model's own delay standing
        # in for an effect found here): no lag shorter than it to try beside it
        notes.append(f"{kept}; no lag shorter than it tried beside it")
        return final, free, ""
    # a real latency: the lag beside it, where decisive (fit-mechanical's latency holds the
    # lag too when its steps saw both: 6.2 ms for a 2 ms L/R and a 4 ms latency) and borne out
    # by the held-out data
    both_free = list(dict.fromkeys([*free, DELAY, *LAG_PARAMS]))
    both = _lag_fit(run, final, both_free, final.values, shorter)
    dbic, held = _pair(run, final, free, both, both_free, min_z)
    if held < 0:
        honest_errors(run, both, both_free, notes)
        notes.append(
            f"{DELAY_EFFECT} kept ({1e3 * both.values[DELAY]:.3g} ms, {1e3 * delay:.3g} ms "
            f"alone) beside the armature's electrical lag tau_e = "
            f"{1e3 * both.values['tau_e']:.3g} ms (L/R, the lumped model's own): the lag in its "
            f"place fits worse (chi-square {lag.chi2['all']:.6g} against "
            f"{final.chi2['all']:.6g}), beside it better (ΔBIC {dbic:+.0f}; held-out Δχ² "
            f"{held:+.4g}, both refitted on the fitted part)")
        return both, both_free, "beside"
    notes.append(
        f"{kept}, beside it not decisively better, determined and borne out by the held-out "
        f"data (ΔBIC {dbic:+.0f}, {lag_z(both):.2g} standard errors"
        + (f", held-out Δχ² {held:+.4g})" if held else ")"))
    return final, free, ""


def _pair(run, ref: FitOutcome, ref_free: list[str], both: FitOutcome, both_free: list[str],
          min_z: float) -> tuple[float, float]:
    """The lag beside the delay against the delay alone (``ref``): (ΔBIC on all data, the
    held-out part's Δχ² (:func:`_held_gain`) where the pair is decisive and its lag determined
    (``min_z`` standard errors, locally and as the model would print its error,
    :func:`_printed_resolved`), else 0: the pair is taken where it is negative)."""
    dbic = delta_bic(run, both.chi2["all"], ref.chi2["all"], len(set(both_free) - set(ref_free)),
                     "all")
    if not (dbic < run.settings.rules.bic and lag_resolved(both, min_z)
            and _printed_resolved(run, both, both_free, min_z)):
        return dbic, 0.0
    return dbic, _held_gain(run, ref, ref_free, both, both_free)


def _printed_resolved(run, both: FitOutcome, both_free: list[str], min_z: float) -> bool:
    """Whether the lag of the pair ``both`` is determined (``min_z`` standard errors) with its
    error widened by the residual's correlation in time (the block sandwich's inflation,
    :meth:`~pmdcid.fit.problem.Problem.correlated_stderr`), as the model would print it. The
    refit's own error counts every sample as independent: fra233-2025-pboon, with the sliding
    dead-zone edge tried in session 17, split its 11 ms latency into 2.8 ms and a 3.4 ms lag at
    15 such errors on a residual correlated over 566 samples (8 x the white error), and every
    held-out run got worse, chirp_100000 0.137 -> 0.145. The marginal error, as before (the
    lag in a delay's place is judged with the share held: two rules, left open). The lag's own
    sandwich error where it is the larger: the inflation is the largest over the parameters of
    the envelope's errors, and the refit's white error of the lag, once its covariance was no
    longer cut by the parameters' units (session 37), was 47 times smaller than the lag's own
    correlated one on the same rig (1.7e-5 against 7.9e-4 s for a 3.4 ms lag, inflation 7.9):
    the lag then passed at 25 such errors, not 4.3, and chirp_100000 rose 0.137 -> 0.145
    again."""
    se, info = run.problem.correlated_stderr(both.values, both_free)
    tau = both.estimates["tau_e"]
    widened = [tau.stderr * info.inflation if info is not None and info.inflation > 1.0
               else tau.stderr, se.get("tau_e", math.nan)]
    stderr = max((s for s in widened if math.isfinite(s)), default=tau.stderr)
    if not stderr > tau.stderr:
        return lag_resolved(both, min_z)
    est = {**both.estimates, "tau_e": dataclasses.replace(tau, stderr=stderr)}
    return lag_resolved(dataclasses.replace(both, estimates=est), min_z)


def _decisive_latency_free(run, final: FitOutcome, free: list[str], lag: FitOutcome) -> bool:
    """Whether the lag in place of a latency of whole samples (the final fit's delay, at least
    :data:`~pmdcid.identify.latency.MIN_SAMPLES`: a latency may be real) fits decisively
    better: by the rules' ``bic`` on the residual's effective samples (the samples over its
    integrated correlation time, :meth:`~pmdcid.fit.problem.Problem.correlated_stderr`:
    Sokal's 1 + 2 sum rho_k, 1 for white noise; until session 21 divided by twice that, which
    halved the evidence of white residuals). A residual
    correlated over hundreds of samples makes a fit 0.1 % better no evidence
    (fra233-2025-pboon: its 11 ms latency over USB, replaced by a 4.2 ms lag fitting the fit
    logs 0.08 % better on a residual correlated over 236 samples, left its held-out chirps
    0.20 -> 0.22). On white residuals the effective samples are the samples."""
    n = run.problem.count("all")
    _, info = run.problem.correlated_stderr(final.values, free)
    n_eff = n / max(info.tau_int, 1.0) if info is not None else n
    ratio = max(lag.chi2["all"], 1e-300) / max(final.chi2["all"], 1e-300)
    return n_eff * math.log(ratio) <= run.settings.rules.bic


def _held_gain(run, final: FitOutcome, free: list[str], lag: FitOutcome,
               lag_free: list[str]) -> float:
    """The held-out part's chi-square of the model with the lag (``lag``, in the delay's place
    or beside it) less the final model's, each refitted on the fitted part from its all-data
    fit (negative: the held-out data bear the lag out). The test every effect passes (issue
    24: an effect is added only where held-out data can show it): judged on all data alone, a
    residual correlated over many samples makes any extra freedom look decisive (the course-lab
    kit, fra233-g04, 2 kHz: a lag of 0.054 ms, a tenth of a sample, beside its 4 ms latency at
    ΔBIC -1022 on a residual correlated over 135 samples; its held-out chirps and sines 0.029
    -> 0.037). 0 when the problem holds nothing out."""
    if run.problem.count("held") == 0:
        return 0.0
    without = run.fit(final.values, free, "fit")
    with_lag = run.fit(lag.values, lag_free, "fit")
    return with_lag.chi2["held"] - without.chi2["held"]


def _replaced(run, final, lag, lag_free, added, notes) -> tuple[FitOutcome, list[str]]:
    delay = final.values[DELAY]
    what = f"{DELAY_EFFECT} ({1e3 * delay:.3g} ms)"
    if DELAY_EFFECT in added:
        added.remove(DELAY_EFFECT)
    else:
        what = (f"the model's {DELAY_EFFECT} (fit-mechanical's latency, "
                f"{1e3 * run.vals0.get(DELAY, 0.0):.3g} ms; {1e3 * delay:.3g} ms with the effects "
                "found here)")
    lag, lag_free = _dead_zone_with_lag(run, lag, lag_free, notes)
    honest_errors(run, lag, lag_free, notes)
    notes.append(
        f"{what} replaced by the armature's electrical lag tau_e "
        f"= {1e3 * lag.values['tau_e']:.3g} ms (L/R, the lumped model's own): without any delay "
        f"the lag fits every log about as well or better (chi-square {lag.chi2['all']:.6g} against "
        f"{final.chi2['all']:.6g}); fit-mechanical's steps had not resolved it")
    return lag, lag_free


def _dead_zone_with_lag(run, lag, lag_free, notes) -> tuple[FitOutcome, list[str]]:
    """The dead zone the final fit settled without the lag, settled again with it
    (:func:`~pmdcid.diagnose.final.settle_dead_zone` on its refitted profile,
    :mod:`pmdcid.diagnose.lagdz`): held where the lag-less fit left it, its interval was
    the lag-less one (bench/lawlag.py, 500 Hz, L/R 2 ms, seed 6: [0, 4.81] V)."""
    if "dz" not in run.base_free or "dz" in lag_free:
        return lag, lag_free
    run.lag_late = True
    free = [*lag_free, "dz"]
    return settle_dead_zone(run, valley_restart(run, lag, free, notes), free, notes)


__all__ = ["LAG_PARAMS", "lag_for_delay"]
