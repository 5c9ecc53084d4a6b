"""A sensor delay on a lumped model without an electrical lag: the armature's L/R instead.

On voltage and speed alone (a lumped, per-volt model, :mod:`pmdcid.model.lumped`) a late start
of the speed after each edge of the input is either the speed read late (``sensor_delay``) or
the armature current rising with its time constant L/R (the lumped model's ``tau_e``), which
every motor has. Where fit-mechanical's steps did not resolve the lag (the model has none),
diagnose's delay finds L/R (issue 24's checks: 1.91 ms on a motor with L/R 2 ms and no
latency). So once the final model holds a sensor delay, the same model with the delay off and
a lag of the same time in its place (the back-EMF's share 1, refitted with every parameter the
final fit frees, on all data) is fitted too; where it fits better without any delay, the lag
is written (``tau_e``, ``ke_share``) and the delay is not; a note gives both chi-squares
either way. The lag's fit frees what the final fit freed, the delay excepted: a dead zone the
final fit settled at a point (:func:`~pmdcid.diagnose.final.settle_dead_zone`) stays there.
"""

from __future__ import annotations

from pmdcid.diagnose.final import honest_errors
from pmdcid.fit.problem import FitOutcome
from pmdcid.model.lumped import is_lumped

#: the effect replaced, its parameter, and the lag's parameters (model/lumped.py)
DELAY_EFFECT, DELAY = "sensor_delay", "delay"
LAG_PARAMS = ("tau_e", "ke_share")


def lag_applies(run, added: list[str]) -> bool:
    """A sensor delay added to a lumped model without a lag, on logs without current."""
    return (DELAY_EFFECT in added and is_lumped(run.model) and not run.problem.measures("i")
            and not run.vals0.get("tau_e", 0.0) > 0)


def lag_for_delay(run, final: FitOutcome, free: list[str], added: list[str],
                  notes: list[str]) -> tuple[FitOutcome, list[str], bool]:
    """The final fit with the armature's lag in place of its sensor delay where that fits all
    data better (module docstring): (fit, its free parameters, whether the lag replaced the
    delay); ``added`` and ``notes`` updated in place."""
    if not lag_applies(run, added):
        return final, free, False
    delay = final.values[DELAY]
    # the final fit's free parameters (a dead zone it settled at a point stays there: refitted,
    # it drifts along the flat cost, once to 3.3 +- 17 V on the L298N rig) but the delay's
    lag_free = [p for p in free if p != DELAY] + list(LAG_PARAMS)
    start = {**final.values, DELAY: 0.0, "tau_e": delay, "ke_share": 1.0}
    lag = run.fit(start, lag_free, "all")
    for name, est in final.estimates.items():
        if name not in lag_free and name != DELAY:
            lag.estimates.setdefault(name, est)  # the settled dead zone's interval
    if not lag.chi2["all"] < final.chi2["all"]:
        notes.append(
            f"{DELAY_EFFECT} ({1e3 * delay:.3g} ms) kept: the armature's electrical lag in its "
            f"place (tau_e {1e3 * lag.values['tau_e']:.3g} ms, no delay) fits worse "
            f"(chi-square {lag.chi2['all']:.6g} against {final.chi2['all']:.6g})")
        return final, free, False
    added.remove(DELAY_EFFECT)
    honest_errors(run, lag, lag_free, notes)
    notes.append(
        f"{DELAY_EFFECT} ({1e3 * delay:.3g} ms) replaced by the armature's electrical lag tau_e "
        f"= {1e3 * lag.values['tau_e']:.3g} ms (L/R, the lumped model's own): without any delay "
        f"the lag fits every log better (chi-square {lag.chi2['all']:.6g} against "
        f"{final.chi2['all']:.6g}); fit-mechanical's steps had not resolved it")
    return lag, lag_free, True


__all__ = ["LAG_PARAMS", "lag_for_delay"]
