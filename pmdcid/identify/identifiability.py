"""Say when the data do not pin a parameter down (the brief: physics is right or flagged).

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

#: a standard error above this fraction of the value: the value means little
MAX_REL_STDERR = 0.25
#: parameters that may be near zero, judged against the friction level instead of themselves
NEAR_ZERO = ("tau0", "dz")


def poorly_determined(estimates, friction_level: float) -> list[str]:
    """Names with their relative (or, for :data:`NEAR_ZERO`, absolute) standard error, e.g.
    ``['J (± 55 %)', 'tau0 (± 0.0017 N m)']``, for the estimates the data do not determine.

    ``estimates``: name -> :class:`~pmdcid.identify.results.Estimate`; ``friction_level``: the
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


def hold_warning(logs, J: float, bv: float) -> str | None:
    """A warning when a log's input changes at nearly every sample (a ramp, a sine) and its
    sample period exceeds a tenth of the mechanical time constant J/bv [s]: if that input was
    not held between samples (CONTRACT.md: zero-order hold), the model applies it half a
    sample late and J absorbs the lag (docs/identification.md: -63 % at 10 Hz)."""
    if not (J > 0 and bv > 0):
        return None
    tau = J / bv
    for log in logs:
        if log.dt <= HOLD_TAU_FRACTION * tau:
            continue
        du = np.diff(np.asarray(log.u, float))
        du = du[np.isfinite(du)]
        if len(du) and float(np.mean(du != 0)) >= RAMP_FRACTION:
            return (f"{log.path}: the input changes at almost every sample and the sample "
                    f"period ({log.dt * 1e3:.3g} ms) is over a tenth of the mechanical time "
                    f"constant J/bv = {tau * 1e3:.3g} ms: the model holds each input value for "
                    "a whole period; if the drive did not (a continuous ramp or sine logged "
                    "slowly), J is biased. Log faster, or log the drive's own updates")
    return None
