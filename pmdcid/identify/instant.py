"""A lumped model whose steps left the electrical lag open: the current as instant.

Logged at 100-200 Hz, a motor's L/R of a few milliseconds is under a sample: fit-mechanical's
steps bound it (tau_e below some milliseconds at two standard errors, :mod:`.latency`) and the
lumped model has no lag. Without it every later fit put the dead zone on the applied voltage v,
not on the torque, per volt ``v - ke w`` (:mod:`pmdcid.model.lumped`). Where the back-EMF is
most of the damping and the dead zone lies above the running friction, the torque of a running
rotor is pinned at the dead zone's edge, which a fit on v reads as Coulomb friction:
bench/pervolt_coverage.py ``--rate 100 --cases lr-tri`` (L/R 2-4 ms, steps and a triangle),
bc' +22 % and J' -4 % on average, J', bv', bc', dz' within two standard errors on 5, 3, 2, 3
of 12 seeds.

Fitting the lag itself where the steps leave it open costs 64 internal steps a sample as the
fit runs towards tau_e = 0 (a lag-free motor at 1 kHz: fit-nonlinear 6 s -> 150 s, session 33
in docs/identification.md). Its structure costs nothing: a current that follows ``v - ke w``
at once (tau_e = 0 with the back-EMF's share free, :func:`pmdcid.simulate.terms.instant_current`),
the dead zone where the physics puts it. :func:`with_instant_current_if_better` fits that
model beside the plain one and keeps the lower BIC; the lag it leaves out (below the steps'
bound) still moves the dead zone by about tau_e times the torque's rate at the breakaway, so a
local fit at the bound itself is read and every standard error widened to reach it
(:func:`reach_the_bound`).
"""

from __future__ import annotations

import math

from pmdcid.errors import PmdcidError
from pmdcid.fit.results import Estimate, bounded
from pmdcid.notes import Note

#: the stage name an instant-current start carries in the model file
STAGE = "instant current"
#: what fit-nonlinear frees in the instant-current model: the base parameters and the share
FREE = ("J", "bv", "bc", "dz", "ke_share")
#: the share the instant-current fit starts from: the middle of [0, 1] (its grid over the share
#: and the dead zone, :func:`pmdcid.identify.nonlinear.share_points`, looks at the rest)
START_SHARE = 0.5
#: the words tau_e carries in an instant-current model
LAG_CAVEAT = ("the steps left the electrical lag open: the current is taken as instant (tau_e "
              "= 0), the dead zone on v - ke w; the other parameters' standard errors reach a "
              "fit with the lag at the bound")


def with_instant_current_if_better(fit, model, plain, bound: float):
    """``plain`` (a lumped fit without lag or share) or the fit with the current instant and
    the back-EMF's share free, whichever has the lower BIC, said in a note either way.

    ``fit(model, free, local_only)``: fit-nonlinear of the stage's logs from ``model`` with
    ``free`` parameters (raising :class:`~pmdcid.errors.PmdcidError` where it fails);
    ``bound`` [s]: the lag the steps left open (:func:`pmdcid.identify.latency.profile_bound`)."""
    work = model.copy()
    plain.apply(work)
    work.set("tau_e", 0.0, stage=STAGE)
    work.set("ke_share", START_SHARE, stage=STAGE)
    try:
        res = fit(work, list(FREE), False)
    except PmdcidError:
        return plain
    drop = plain.stats.bic - res.stats.bic
    if not drop > 0:
        plain.warnings.insert(0, Note(
            f"the current taken as instant (tau_e = 0, the back-EMF's share free, the dead "
            f"zone on v - ke w) fits no better in BIC ({-drop:.3g} above): the dead zone acts "
            "on the applied voltage", about=["tau_e"], severity="note"))
        return plain
    return bounded_by_lag(fit, work, res, bound,
                          f"the current taken as instant, the back-EMF's share free (ke_share "
                          f"{res.estimates['ke_share'].value:.3g}) and the dead zone on v - ke "
                          f"w as the physics puts it, BIC {drop:.3g} below the dead zone on v; "
                          "kept")


def lag_bound_of(model) -> float:
    """The bound [s] on the lag of an instant-current model (tau_e = 0 inside an interval
    [0, bound], a back-EMF share: :func:`with_instant_current_if_better` wrote it); NaN for
    any other model."""
    tau = model.parameters.get("tau_e")
    if (tau is None or tau.value != 0.0 or tau.interval is None or not model.has("ke_share")
            or not tau.interval[1] > 0):
        return math.nan
    return float(tau.interval[1])


def bounded_by_lag(fit, model, res, bound: float, said: str = ""):
    """``res``, a fit of the instant-current ``model`` (its parameters written over), with its
    standard errors reaching the fit with the lag at ``bound`` [s] (:func:`reach_the_bound`),
    tau_e the interval [0, bound] and a note (``said`` after the bound's words)."""
    work = model.copy()
    res.apply(work)
    wide = reach_the_bound(fit, work, res, bound)
    res.estimates["tau_e"] = bounded("tau_e", 0.0, bound, "s", LAG_CAVEAT, value=0.0)
    words = (f"the steps left the electrical lag open (below {1e3 * bound:.3g} ms, "
             "fit-mechanical's bound)" + (f": {said}" if said else ": the current taken as "
                                          "instant"))
    if wide:
        words += ("; standard errors widened to reach a fit with the lag at that bound: "
                  + ", ".join(wide))
    res.warnings.insert(0, Note(words, about=["tau_e", "ke_share"], severity="note"))
    return res


def reach_of(value: float, other: Estimate) -> float:
    """How far from ``value`` the far end of ``other``'s two standard errors (or its interval)
    lies: an error of half this lets two reach it (every "widened to reach another fit" rule:
    here and :func:`pmdcid.identify.runners._fold_reach`)."""
    if other.interval is not None:
        return max(abs(x - value) for x in other.interval)
    se = other.stderr if math.isfinite(other.stderr) else 0.0
    return abs(other.value - value) + 2.0 * se


def reach_the_bound(fit, work, res, bound: float) -> list[str]:
    """``res``'s standard errors widened in place so that two reach the local fit with the lag
    at ``bound`` [s] (held, the rest free from ``res``'s values in ``work``): half the
    distance plus that fit's own standard error. The lag lies anywhere in [0, bound]; the
    estimates move with it (the dead zone by about the lag times the torque's rate where the
    rotor breaks away). Returns "name xfactor" for each widened; nothing where that fit fails."""
    lagged = work.copy()
    lagged.set("tau_e", bound, stage=STAGE)
    try:
        far = fit(lagged, list(FREE), True).estimates
    except PmdcidError:
        return []
    wide = []
    for k, e in list(res.estimates.items()):
        o = far.get(k)
        if o is None or not e.vary or e.interval is not None or not math.isfinite(e.stderr):
            continue
        se = max(e.stderr, 0.5 * reach_of(e.value, o))
        if se > 1.01 * e.stderr:
            res.estimates[k] = Estimate(k, e.value, se, e.unit, caveat=e.caveat)
            wide.append(f"{k} x{se / e.stderr:.2g}")
    return wide


__all__ = ["FREE", "LAG_CAVEAT", "STAGE", "bounded_by_lag", "lag_bound_of", "reach_of",
           "reach_the_bound",
           "with_instant_current_if_better"]
