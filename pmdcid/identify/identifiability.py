"""Say when the data do not pin a parameter down (the brief: physics is right or flagged).

The fitting stages' checks on their logs and results: :func:`require_motion` (refuse a log
where nothing moves), :func:`fit_warnings` (a simulation-error fit's warnings), :func:`hold_warning`
(an input varying at every sample, logged slowly) and :func:`poorly_determined`:

A parameter is **poorly determined** when its standard error (allowing for correlated
residuals, :mod:`.covariance`) exceeds :data:`MAX_REL_STDERR` of its value or, for a parameter
that may legitimately be near zero (a torque offset, a dead zone), of the friction level.

Why the standard error and not a rule on the sampling (such as the electrical stage's "L/R under
three sample periods"): the inertia stays well determined at a sample period of three mechanical
time constants when the noise is low (J off by 3.4 % +- 2 % at dt = 3 J/bv, 2 % noise), and is
lost at five; the standard error sees both, a fixed ratio only one.
"""

from __future__ import annotations

import math

import numpy as np

from pmdcid.errors import FitError

#: a standard error above this fraction of the value: the value means little
MAX_REL_STDERR = 0.25
#: parameters that may be near zero, judged against the friction level instead of themselves
NEAR_ZERO = ("tau0", "dz")


def poorly_determined(estimates, friction_level: float) -> list[str]:
    """Names with their relative (or, for :data:`NEAR_ZERO`, absolute) standard error, e.g.
    ``['J (± 55 %)', 'tau0 (± 0.0017 N m)']``, for the estimates the data do not determine.

    ``estimates``: name -> :class:`~pmdcid.fit.results.Estimate`; ``friction_level``: the
    torque [N m] a near-zero parameter is judged against (e.g. max(bc, 1 % of the largest
    torque)).
    """
    out = []
    for name, e in estimates.items():
        if not e.vary or not math.isfinite(e.stderr):
            continue
        if name in NEAR_ZERO:
            if friction_level > 0 and e.stderr > MAX_REL_STDERR * friction_level:
                out.append(f"{name} (± {e.stderr:.2g} {e.unit})".replace(" )", ")"))
        elif e.value != 0 and e.stderr > MAX_REL_STDERR * abs(e.value):
            out.append(f"{name} (± {100 * e.stderr / abs(e.value):.0f} %)")
    return out


def poorly_determined_warning(estimates, friction_level: float) -> str | None:
    """One warning line for :func:`poorly_determined`, or None."""
    bad = poorly_determined(estimates, friction_level)
    if not bad:
        return None
    return (f"{', '.join(bad)} {'is' if len(bad) == 1 else 'are'} poorly determined by these "
            "logs: the value means little. Give logs with more excitation (torque levels in "
            "both directions, transients, several speeds), faster sampling or less noise")


#: a sample period above this fraction of the mechanical time constant makes the input's hold
#: matter: a ramp applied continuously but modelled as held lags by dt/2
HOLD_TAU_FRACTION = 0.1
#: fraction of samples at which the input changes for it to count as continuously varying
RAMP_FRACTION = 0.8


def hold_matters(log, J: float, bv: float) -> bool:
    """True when ``log``'s input changes at nearly every sample (a ramp, a sine) and its sample
    period exceeds :data:`HOLD_TAU_FRACTION` of the mechanical time constant J/bv [s]: read as
    held (docs/io.md: zero-order) or as varying between samples, the input then moves the
    fitted inertia (docs/identification.md: J -63 % at 10 Hz when a continuous ramp is read as
    held). Never for a loop-timed log stepped inside its samples (:meth:`~pmdcid.io.Log.
    input_within`): its input is known between the samples, held from each logged instant."""
    if not (J > 0 and bv > 0) or log.dt <= HOLD_TAU_FRACTION * J / bv:
        return False
    if log.input_within() is not None:
        return False
    du = np.diff(np.asarray(log.u, float))
    du = du[np.isfinite(du)]
    return bool(len(du)) and float(np.mean(du != 0)) >= RAMP_FRACTION


def hold_warning(logs, J: float, bv: float, ramp=None) -> str | None:
    """A warning for the first log where :func:`hold_matters`; ``ramp``: the fitted reading of
    the input between samples (an :class:`~pmdcid.fit.results.Estimate`), when the fit
    found it."""
    for log in logs:
        if not hold_matters(log, J, bv):
            continue
        head = (f"{log.path}: the input changes at almost every sample and the sample period "
                f"({log.dt * 1e3:.3g} ms) is over a tenth of the mechanical time constant J/bv "
                f"= {J / bv * 1e3:.3g} ms")
        if ramp is not None:
            return (f"{head}: whether the input was held between samples or varied "
                    "continuously moves J, so the fit also read how it varied: "
                    f"{_ramp_words(ramp)} (0: held, 1: straight to the next "
                    "sample); J's standard error includes that. Log faster to pin J down")
        return (f"{head}: the model holds each input value for a whole period; if the drive "
                "did not (a continuous ramp or sine logged slowly), J is biased. Log faster, "
                "or log the drive's own updates")
    return None


def _ramp_words(ramp) -> str:
    if ramp.interval is not None:
        return f"anywhere from {ramp.interval[0]:.2g} to {ramp.interval[1]:.2g}"
    return f"ramp = {ramp.value:.2g} ± {ramp.stderr:.2g}"


#: a signal whose span is below this many noise levels shows no motion
MOTION_SIGMAS = 10.0


def require_motion(logs, sigma) -> None:
    """Refuse logs where nothing moves: inertia and friction leave no trace in them."""
    for lg, sg in zip(logs, sigma, strict=True):
        for s, sd in sg.items():
            x = np.asarray(lg[s], float)
            x = x[np.isfinite(x)]
            if len(x) and float(np.ptp(x)) > MOTION_SIGMAS * sd and float(np.ptp(x)) > 0:
                return
    names = ", ".join(sorted({s for sg in sigma for s in sg}))
    raise FitError(f"nothing moves in this log ({names} stay within their noise, estimated "
                   "from sample-to-sample changes): J, bv, bc, dz cannot be identified from it; "
                   "give a log where the rotor turns (e.g. the triangular input), sampled "
                   "faster than its mechanical time constant", logs[0].path)


def fit_warnings(fit, est, tscale: float, masked: bool) -> list[str]:
    """Warnings on a simulation-error fit: parameters the logs do not determine, bc-dz
    correlation, dz at 0, no convergence, a residual far above the noise."""
    warns: list[str] = []
    # a masked dz has its own warning (the interval that fits equally)
    judged = {k: e for k, e in est.items() if not (masked and k == "dz") and k != "ramp"}
    bc = est["bc"].value if "bc" in est else 0.0
    w = poorly_determined_warning(judged, max(bc, 0.01 * tscale))
    if w:
        warns.append(w)
    r = fit.correlation("bc", "dz")
    if math.isfinite(r) and abs(r) > 0.9:
        warns.append(f"bc and dz are strongly correlated ({r:+.2f}): the logs hardly tell "
                     "Coulomb friction from the dead zone (use slower reversals)")
    if "dz" in fit.estimates and est["dz"].value < 1e-6 * tscale:
        warns.append("dz is at 0: no dead zone visible in these logs")
    if not fit.stats.success:
        warns.append(f"the least-squares stage did not converge ({fit.stats.message})")
    if fit.stats.redchi > 10:
        warns.append(f"reduced chi-square {fit.stats.redchi:.3g} >> 1: the model leaves "
                     "structure in the residual (try pmdcid diagnose)")
    return warns
