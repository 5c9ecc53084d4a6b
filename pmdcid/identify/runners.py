"""The stages as every entry runs them: the command line (through :mod:`pmdcid.files`), the
library's front door (:mod:`pmdcid.api`) and ``identify`` (:mod:`pmdcid.pipeline`).

Voltage and speed logs without current, on a model without R, make a lumped (per-volt) model
(:mod:`pmdcid.model.lumped`). That path is written once, in two halves:
:func:`fit_stage` (mark the model lumped when the logs want it, fit, relabel the result per
volt) and :func:`apply_stage` (write the result into a model, which a per-volt result marks
lumped again). Each stage's own choices are :func:`stage_electrical`,
:func:`stage_mechanical`, :func:`stage_nonlinear` and :func:`stage_inverse_dynamics`.
"""

from __future__ import annotations

import math

from pmdcid.errors import ModelError, PmdcidError
from pmdcid.fit.results import Estimate, held_elsewhere, kept_from_elsewhere
from pmdcid.identify.instant import (
    bounded_by_lag,
    lag_bound_of,
    reach_of,
    with_instant_current_if_better,
)
from pmdcid.identify.linstart import STAGE as LINEAR_START_STAGE
from pmdcid.identify.mechanical import STAGE as MECH_STAGE
from pmdcid.model.effects import param_spec
from pmdcid.model.lumped import ELECTRICAL, is_lumped, lumped_unit, mark_lumped, wants_lumped
from pmdcid.notes import Note
from pmdcid.runtime.cpus import pmap
from pmdcid.simulate import logs_for


def fit_stage(fit, logs, model):
    """``fit(logs, work)`` on a copy of ``model`` marked lumped when ``logs`` can only identify
    a per-volt model (:func:`lumped_if_wanted`), the result relabelled per volt
    (:func:`per_volt`) when it was fitted so. ``model`` is not modified."""
    work = lumped_if_wanted(logs, model.copy())
    start = work.copy()
    result = fit(logs, work)
    if is_lumped(work):
        per_volt(result)
    if hasattr(result, "fitted_on"):  # result.plot(): these logs, from this model
        result.fitted_on(logs, start)
    return result


def apply_stage(result, model) -> None:
    """Write ``result`` into ``model``; a result fitted per volt (:func:`fit_stage`) leaves
    ``model`` lumped, so that its per-volt values are never read as SI."""
    result.apply(model)
    if getattr(result, "lumped", False):
        mark_lumped(model)


def lumped_if_wanted(logs, model):
    """``model``, marked lumped (in place) when ``logs`` can only identify a per-volt model
    (:func:`~pmdcid.model.lumped.wants_lumped`)."""
    if wants_lumped(logs, model) and not is_lumped(model):
        mark_lumped(model)
    return model


def per_volt(result) -> None:
    """Relabel a result's estimates in per-volt units (a lumped model, :mod:`..model.lumped`);
    its ``apply`` then marks the model it writes into as lumped."""
    for name, e in getattr(result, "estimates", {}).items():
        if name not in ELECTRICAL:
            e.unit = lumped_unit(e.unit)
    result.lumped = True
    result.warnings[:] = [_per_volt_text(w) for w in result.warnings]
    note = Note("lumped model: per-volt parameters (no current, no datasheet); see the model "
                "file", severity="note")
    if note not in result.warnings:
        result.warnings.insert(0, note)


def _per_volt_text(text: str) -> str:
    """A message's torque units as per-volt ones (the values in it are per volt already); a
    :class:`~pmdcid.notes.Note` stays one."""
    new = (text.replace("kg m^2", "V s^2/rad").replace("N m s/rad", "V s/rad")
           .replace(" N m", " V"))
    if isinstance(text, Note):
        return Note(new, text.about, severity=text.severity, stage=text.stage, log=text.log)
    return new


def stage_electrical(logs, model):
    """fit-electrical: R, L (blocked-rotor logs), or R, L, ke (free-running logs with
    current)."""
    from pmdcid.identify.electrical import fit_electrical

    return fit_electrical(logs, model)


def stage_mechanical(logs, model, km=None):
    """fit-mechanical as the command runs it: per volt for a lumped model, else with ``km``;
    torque step logs in SI with no km (:func:`~pmdcid.identify.mechanical.torque_steps`)."""
    from pmdcid.identify.mechanical import fit_mechanical

    if is_lumped(model) and any(lg.drive == "tau" for lg in logs):
        raise ModelError("the model is lumped (per-volt parameters, from voltage logs): torque "
                         "steps give J, bv, bc in SI; fit them into another model file")
    if is_lumped(model):
        return lumped_mechanical(logs, model, fit_mechanical)
    return fit_mechanical(logs, model, km=km)


def stage_nonlinear(logs, model, controller=None, *, replaces: frozenset[str] = frozenset(),
                    **opts):
    """fit-nonlinear as the command runs it: a lumped model's logs seen as torque-driven
    (:func:`~pmdcid.simulate.logs_for`), J, bv, bc, dz free unless ``free`` says otherwise.
    Closed-loop logs (:mod:`pmdcid.identify.closedfit`): with ``controller`` (a
    :class:`~pmdcid.simulate.controller.ControllerSpec`) the loop is simulated from the logged
    reference; without, the logged output is fitted with a noise model. A lumped model whose
    lag no step tested (:func:`lag_untested`) is fitted with the lag too, the lower BIC kept
    (:func:`_with_lag_if_better`). ``replaces``: the parameters whose values came from these
    logs (identify's joint fit: its stages' on the same logs), which the result replaces as one
    set, one these logs leave undetermined included (with its words); any other such parameter
    keeps the value other data determined and the others are fitted with it
    (:func:`_held_where_kept`)."""
    start = _linear_start_if_needed(logs, model)
    untested = controller is None and not opts.get("free") and lag_untested(model, logs)
    bound = (steps_lag_bound(model) if controller is None and not opts.get("free")
             and not untested and lag_open(model, logs) else math.nan)
    instant = lag_bound_of(model) if controller is None and not opts.get("free") else math.nan
    res = _fit_nonlinear(logs, model, controller, dict(opts), replaces)

    def fit(work, free, local_only):  # fit-nonlinear of these logs, for identify/instant.py
        return _fit_nonlinear(logs, work, None, {**opts, "free": free, "local_only": local_only},
                              replaces)

    if untested:
        res = _with_lag_if_better(logs, model, opts, res)
    elif math.isfinite(bound):
        res = with_instant_current_if_better(fit, model, res, bound)
    elif math.isfinite(instant):
        res = bounded_by_lag(fit, model, res, instant)
    if start:
        res.warnings.insert(0, Note(start, about=["J", "bv"], severity="note"))
    res.replaces = replaces
    return res


def _fit_nonlinear(logs, model, controller, opts, replaces: frozenset[str] = frozenset()):
    """:func:`stage_nonlinear`'s one fit of ``model`` with ``opts`` (fit-nonlinear's or the
    controller route's): a lumped model's lag and share freed where it has a lag."""
    from pmdcid.identify.closedfit import (
        closed_loop_logs,
        fit_closed_loop,
        logged_output_route,
        noise_model_for,
    )
    from pmdcid.identify.nonlinear import fit_nonlinear

    if is_lumped(model) and not opts.get("free"):
        opts["free"] = ["J", "bv", "bc", "dz"]
        if model.has("tau_e") and model.value("tau_e") > 0:  # its electrical lag, and the
            opts["free"] += ["tau_e", "ke_share"]  # back-EMF's share of bv (model/lumped.py)
        elif model.has("ke_share"):  # an instant current (identify/instant.py): the share
            opts["free"] += ["ke_share"]
    seen = logs_for(logs, model)
    if controller is not None:
        opts.pop("dead_zone", None)
        return fit_closed_loop(seen, model, controller, **opts)
    opts.setdefault("noise_model", noise_model_for(seen))
    res = fit_nonlinear(seen, model, **opts)
    res = _held_where_kept(res, model, replaces,
                           lambda free: fit_nonlinear(seen, model, **{**opts, "free": free}))
    if closed_loop_logs(seen):
        res.route = logged_output_route(seen, filters=res.fit.noise_filters)
    return res


def _held_where_kept(res, model, replaces, refit):
    """``res``, or where the model file would keep values other data determined beside it
    (:func:`pmdcid.fit.results.kept_from_elsewhere`; not those of ``replaces``, which came
    from these logs), ``refit(free)`` with those held at them: the model written is then one
    fit's."""
    held = [n for n in kept_from_elsewhere(res.estimates, model) if n not in replaces]
    free = [n for n, e in res.estimates.items() if e.vary and n not in held]
    if not held or not free:
        return res
    out = refit(free)
    out.estimates.update({n: held_elsewhere(model, n) for n in held})
    return out


#: the electrical lags a lumped fit whose lag no stage examined starts from [sample periods]
#: (:func:`_with_lag_if_better`): along tau_e a slow input's cost is flat and rough, and from one
#: start the fit stopped short (bench/pervolt_coverage.py lr-tri-only seed 8 at 1 kHz from 2
#: samples: tau_e -76 %, chi-square 8196; from 6: -22 %, 8158; over 20 seeds J', bv', bc' within
#: 2 standard errors 15, 15, 19 from 2 samples alone, 18, 15, 17 from 4, 20, 15, 15 from 6, and
#: 19, 18, 20 from both). Their local stages run on two CPUs where there are (runtime/cpus.py)
LAG_START_SAMPLES = (2.0, 6.0)


def lag_untested(model, logs) -> bool:
    """A lumped model with no electrical lag whose mechanics no stage fitted (none yet, or the
    first-order start of :mod:`pmdcid.identify.linstart`): no step log tested L/R
    (:func:`_step_latency` does where there are steps), so fit-nonlinear tests it on open-loop
    ``logs`` (:func:`_with_lag_if_better`). Not on closed-loop logs: their input is the
    controller's answer to the measured speed, and a fit reads the loop's own phase as a lag
    (micromouse-pid, bench/realbench.py: the lag kept on BIC, the held-out period's speed
    0.207 -> 0.292)."""
    from pmdcid.identify.closedfit import closed_loop_logs

    if not is_lumped(model) or model.has("tau_e") or closed_loop_logs(logs_for(logs, model)):
        return False
    return not model.has("J") or model.parameters["J"].stage == LINEAR_START_STAGE


def lag_open(model, logs) -> bool:
    """A lumped model with neither a lag nor a share whose mechanics fit-mechanical's steps
    gave, the steps having left the lag open (:func:`steps_lag_bound`) and found no latency in
    its place: fit-nonlinear then fits the current as instant too
    (:mod:`pmdcid.identify.instant`). Not on closed-loop logs (:func:`lag_untested`)."""
    from pmdcid.identify.closedfit import closed_loop_logs

    if (not is_lumped(model) or model.has("tau_e") or model.has("ke_share")
            or model.has("delay") or not model.has("J")):
        return False
    return (model.parameters["J"].stage == MECH_STAGE and math.isfinite(steps_lag_bound(model))
            and not closed_loop_logs(logs_for(logs, model)))


def steps_lag_bound(model) -> float:
    """The electrical lag [s] fit-mechanical's steps left open
    (:func:`pmdcid.identify.latency.step_lag`'s ``tau_e_bound``, kept in the model file's
    record of the stage), at most the bound on tau_e a model file holds (a file written before
    :func:`pmdcid.identify.latency.lag_ceiling`); NaN where the steps resolved it, found a
    latency instead, or never tested it."""
    rec = model.extra.get("fits", {}).get(MECH_STAGE, {})
    got = rec.get("tau_e_bound") if isinstance(rec, dict) else None
    if not isinstance(got, (int, float)) or not got > 0:
        return math.nan
    return min(float(got), param_spec("tau_e").upper)


def _with_lag_if_better(logs, model, opts, plain):
    """``plain`` (the fit without a lag) or the same fit with the electrical lag tau_e and the
    back-EMF's share free: the local stage from ``plain``'s values and each lag of
    :data:`LAG_START_SAMPLES`, the whole fit from the one that ends lower (its grid over the
    share and the dead zone too: where the share sets what the dead zone acts on, the local
    stage does not cross between their valleys; without it, on a swept sine alone,
    bench/pervolt_coverage.py ``lr-chirp``, the dead zone stayed masked below bc on 7 of 20
    seeds, its interval short of the truth on 3), kept where its BIC is below ``plain``'s;
    said in a note either way.

    Every armature has its L/R; per volt the lag rounds each change of the torque and moves
    the dead zone onto v - ke w (:mod:`pmdcid.model.lumped`). Without it, on a triangle alone
    (bench/pervolt_coverage.py ``lr-tri-only``, L/R 2-4 ms at 0.5-1 kHz) J came out 12-17 % low
    and bc 32-53 % high, 4-6 standard errors off (J', bv', bc', dz' within 2 in 0, 1, 0, 0 of
    20 seeds); with it 19, 18, 20, 18. The test is the likelihood's (BIC), not tau_e's own
    standard error: a slow input tells that a lag of some milliseconds is there (BIC thousands
    lower) long before it tells how long."""
    dt = min(lg.dt for lg in logs)

    def from_start(samples):  # its local stage alone: (chi-square, the model it ends at)
        lagged = model.copy()
        plain.apply(lagged)
        lagged.set("tau_e", samples * dt, stage=LINEAR_START_STAGE)
        try:
            local = _fit_nonlinear(logs, lagged, None, {**opts, "local_only": True})
        except PmdcidError:
            return None
        local.apply(lagged)
        return local.stats.chisqr, lagged

    starts = [s for s in pmap(from_start, LAG_START_SAMPLES) if s is not None]
    res = None
    if starts:  # the whole fit from the start whose local stage ended lowest
        try:
            res = _fit_nonlinear(logs, min(starts, key=lambda s: s[0])[1], None,
                                 dict(opts))
        except PmdcidError:
            res = None
    drop = plain.stats.bic - res.stats.bic if res is not None else -math.inf
    if drop > 0:
        res.warnings.insert(0, Note(_lag_kept_words(res.estimates["tau_e"], drop),
                                    about=["tau_e"], severity="note"))
        return res
    wide = _fold_reach(plain.estimates, res.estimates) if res is not None else []
    if wide:
        plain.warnings.insert(0, Note(
            "standard errors widened so that two reach the fit with an electrical lag's own "
            "two (the lag these logs leave open moves them): " + ", ".join(wide),
            about=[w.split()[0] for w in wide], severity="note"))
    plain.warnings.insert(0, Note(
        "no electrical lag: the fit with one (tau_e and the back-EMF share free) is no better "
        "in BIC; the lumped model has none (tau_e = 0), the lag is folded into J and the dead "
        "zone acts on the applied voltage", about=["tau_e"], severity="note"))
    return plain


#: the words a parameter widened by :func:`_fold_reach` carries
FOLD_CAVEAT = ("its standard error reaches the fit with an electrical lag: the lag the lumped "
               "model folds in is not determined by these logs")


def _fold_reach(est: dict, lagged: dict) -> list[str]:
    """``est`` (the fit without a lag, kept on BIC) widened in place where the fit with the
    lag lands elsewhere: each standard error at least half the distance to the lagged fit's
    value plus the lagged fit's own standard error, so that two standard errors reach the far
    end of its two (an interval: the union with its). Every armature has its L/R; where the
    logs do not show it, the plain fit's small errors are conditional on a lag of zero. On a
    triangle alone of the paper's motor (bench/pervolt_coverage.py ``paper-tri-only-1k``, L/R
    7.5 ms at 1 kHz), the 13 of 20 seeds that kept no lag had J' +7-8 % at 20-24 standard
    errors, bv' at 3.5-6, bc' at 2-5; the fit with the lag, +2-5 % at 0.6-4. Returns
    "name xfactor" for each widened."""
    wide = []
    for k, e in list(est.items()):
        o = lagged.get(k)
        if o is None or not e.vary or k in ("tau_e", "ke_share") or not math.isfinite(o.value):
            continue
        if e.interval is not None:
            reach = o.interval or (o.value - 2 * _finite(o.stderr), o.value + 2 * _finite(o.stderr))
            span = (min(e.interval[0], reach[0]), max(e.interval[1], reach[1]))
            if span != tuple(e.interval):
                est[k] = Estimate(k, e.value, e.stderr, e.unit, interval=span,
                                  caveat=_with_caveat(e))
                wide.append(f"{k} (interval)")
            continue
        if not math.isfinite(e.stderr):
            continue
        far = reach_of(e.value, o)
        if k == "J":
            far = max(far, _folded_inertia(est, lagged))
        se = max(e.stderr, 0.5 * far)
        if se > 1.01 * e.stderr:
            est[k] = Estimate(k, e.value, se, e.unit, caveat=_with_caveat(e))
            wide.append(f"{k} x{se / e.stderr:.2g}")
    return wide


def _folded_inertia(est: dict, lagged: dict) -> float:
    """The most J' [V s^2/rad] a lumped fit without a lag folds in: tau_e bv', tau_e at the
    lagged fit's upper end (two standard errors; 0 where it has none). Per volt the motor is
    (tau_e s + 1)(J' s + bv' - ke) + ke; a first-order fit matches its s term, J' + tau_e
    (bv' - ke), and bv' - ke <= bv'. On the paper's motor (L/R 7.5 ms, bv' 1.53 V s/rad, ke
    3 % of it) that is +0.0111 against the folded fits' +0.0113 (bench/pervolt_coverage.py
    ``paper-tri-only-1k`` seed 7), where the lagged fit, its share undetermined at 0.5,
    still lay +6 % high."""
    tau, bv = lagged.get("tau_e"), est.get("bv")
    if tau is None or bv is None or not math.isfinite(tau.stderr):
        return 0.0
    return max(tau.value + 2 * tau.stderr, 0.0) * abs(bv.value)


def _with_caveat(e) -> str:
    return f"{e.caveat}; {FOLD_CAVEAT}" if e.caveat else FOLD_CAVEAT


def _finite(x: float) -> float:
    return x if math.isfinite(x) else 0.0


def _lag_kept_words(tau, drop: float) -> str:
    """The note on a lag :func:`_with_lag_if_better` kept: its value, or where the logs do
    not determine it (under :data:`~pmdcid.identify.latency.LAG_SIGMAS` standard errors), the
    bound, and why the fit with it is better all the same (the dead zone on v - ke w)."""
    from pmdcid.identify.latency import LAG_SIGMAS

    said = (f"an electrical lag tau_e = {1e3 * tau.value:.3g} ms (L/R), tested here (no step "
            f"log tested it): the fit with it, the dead zone on the lagged torque v - ke w as "
            f"the physics puts it, has BIC {drop:.3g} below the fit without; kept")
    if math.isfinite(tau.stderr) and tau.value > LAG_SIGMAS * tau.stderr:
        return said
    bound = tau.value + 2.0 * tau.stderr if math.isfinite(tau.stderr) else math.inf
    return (said + f", though these logs do not determine the lag itself (below "
            f"{1e3 * bound:.3g} ms at two standard errors)")


#: the start fit-nonlinear takes when MODEL holds no mechanics (said in a note)
LINEAR_START_NOTE = ("MODEL has no J, bv (no fit-mechanical): started from a first-order "
                     "least-squares fit of these logs (identify's start)")


def _linear_start_if_needed(logs, model) -> str:
    """A voltage-driven SI model without J or bv (fit-mechanical found no step it could use:
    a measured voltage that is never held, plateaus too short to settle) starts fit-nonlinear
    from the first-order least squares of its logs (:mod:`pmdcid.identify.linstart`), written
    into ``model`` (the stage's working copy) with stage ``start``: identify's own start,
    never a prior. Torque-driven logs and lumped models have theirs (inverse dynamics). Returns
    the note to give, or ''."""
    from pmdcid.errors import FitError
    from pmdcid.identify.linstart import linear_start

    if (is_lumped(model) or model.has("J") and (model.has("bv") or model.has("b"))
            or not model.has("km") or all(lg.drive == "tau" for lg in logs)):
        return ""
    try:
        linear_start(logs, model).apply(model)
    except FitError:
        return ""  # fit-nonlinear then says what the model lacks
    return LINEAR_START_NOTE


def lumped_mechanical(logs, model, fit):
    """fit-mechanical per volt: R = km = 1 and no electrical lag, so that b, bv, J come out
    in V s/rad and V s^2/rad and bc in V (:mod:`pmdcid.model.lumped`)."""
    work = model.copy()
    work.set("R", 1.0)
    work.set("L", 1e-9)
    # no joint refinement: its extra is the breakaway timed by the current's rise, which does
    # not exist per volt; on exact lumped logs it biased J +9 % and bc -40 % (the line: -0.7 %)
    result = fit(logs, work, km=1.0, joint=False)
    result.km_from_option = False
    if not result.joint:  # a dead time with no electrical lag is latency, not a breakaway
        tb = result.estimates["T_break"]
        result.estimates["T_break"] = type(tb)("T_break", math.nan, math.nan, tb.unit)
        _step_latency(result, logs, model)
    return result


def _step_latency(result, logs, model) -> None:
    """The steps' electrical lag and latency (:mod:`pmdcid.identify.latency`) as the result's
    ``tau_e`` (with J less the lag it folded in) and ``delay``: the model with the steps'
    estimates, simulated on them, against their measured speed. The lag first, so that no
    latency stands in for the armature's L/R."""
    from pmdcid.identify.latency import step_lag

    fitted = model.copy()
    result.apply(fitted)
    found = step_lag(logs, fitted)
    if not found:
        return
    if "tau_e" in found:
        tau, se = found["tau_e"]
        result.estimates["tau_e"] = Estimate("tau_e", tau, se, "s")
        result.estimates["J"] = Estimate("J", *found["J"], result.estimates["J"].unit)
        result.warnings.append(_lag_words(tau, found))
    elif "lag_and_latency" in found:
        lag, late = found["lag_and_latency"]
        result.warnings.append(
            f"the steps' late start fits a lag of {1e3 * lag:.3g} ms (L/R) with a latency of "
            f"{1e3 * late:.3g} ms: on voltage and speed alone the two trade off, so it is kept "
            "as a latency (sensor_delay) and the model has no tau_e (a current log would tell "
            "them apart)")
    elif "tau_e_filter" in found:
        result.lag_bound = found["tau_e_filter"]  # the steps' lag lies under it
        result.warnings.append(
            f"the electrical lag L/R is not resolved through the filter that derived the speed "
            f"from the angle (a lag under {1e3 * found['tau_e_filter']:.3g} ms = 1/(2 pi fc), fc "
            "its cut-off, is not told there from the inertia it folds in or from a late first "
            "count of the encoder): the lumped model has none "
            "(tau_e = 0), the lag is folded into J and the dead zone acts on the applied "
            "voltage; a faster sampling, a higher --cutoff or a measured speed would show it; "
            "fit-nonlinear also fits the current as instant (the dead zone on v - ke w)")
    elif "tau_e_bound" in found:
        result.lag_bound = found["tau_e_bound"]
        result.warnings.append(
            f"the electrical lag L/R is not resolved by these logs (tau_e below "
            f"{1e3 * found['tau_e_bound']:.3g} ms {_bound_words(found)}, sample period "
            f"{1e3 * logs[0].dt:.3g} ms): the lumped model has none (tau_e = 0), the lag is "
            "folded into J and the dead zone acts on the applied voltage; fit-nonlinear also "
            "fits the current as instant (the dead zone on v - ke w)")
    if "delay" in found:
        result.estimates["delay"] = Estimate("delay", *found["delay"], "s")


def _bound_words(found: dict) -> str:
    """How the steps bound a lag they leave open (:func:`pmdcid.identify.latency._found`)."""
    if found.get("tau_e_ceiling"):
        return ("only by the steps' own mechanical time constant: their cost does not rise "
                "below it, steps that settle from rest would bound it")
    return "at two standard errors"


def _lag_words(tau: float, found: dict) -> str:
    if found.get("both"):
        late, se = found["delay"]
        return (f"an electrical lag tau_e = {1e3 * tau:.3g} ms (L/R) rounds the steps' starts "
                f"and a latency of {1e3 * late:.3g} +- {1e3 * se:.2g} ms moves them: the steps "
                "need both (with either dropped the fit is worse in BIC), both kept")
    return (f"an electrical lag tau_e = {1e3 * tau:.3g} ms (L/R) rounds the steps' starts: "
            "kept as the lumped model's tau_e, not as a latency (a lag of the speed sensor, "
            "e.g. a firmware's moving average, rounds them the same on voltage and speed alone)")


def stage_inverse_dynamics(logs, model, km=None, as_published=False):
    """fit-inverse-dynamics: J, bv, bc, tau0 by inverse-dynamics least squares (the torque
    regressed on filtered acceleration, speed, sign of speed and 1), with ``km`` [N m/A] (a
    datasheet value, set into ``model``) for voltage logs with current. ``as_published``: the
    EMPS authors' IDIM-LS (every row, torque not centred on the ZOH)."""
    from pmdcid.identify.inverse_dynamics import fit_inverse_dynamics

    if km is not None:
        model.set("km", km, stage="datasheet")
    opts = {"rest_fraction": 0.0, "centre_zoh": False} if as_published else {}
    return fit_inverse_dynamics(logs, model, **opts)
