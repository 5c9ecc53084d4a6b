"""What earlier stages knew, as Gaussian priors of later fits (issue: no information lost).

Each stage writes its estimates with honest standard errors (the correlated-residual sandwich).
A later simulation-error fit adds one residual row ``(x - value)/stderr`` per such parameter,
so the posterior combines both data sets; the covariance step counts the prior's information
(:func:`pmdcid.fit.simfit.fit_simulation`). The statistics: docs/identification.md.
"""

from __future__ import annotations

import math

from pmdcid.model import Model

#: relative width below which a prior is widened: a stage's standard error counts the noise of
#: its own logs, not the model-form error that differs between data sets (a step response and
#: a slow ramp weigh friction and inertia differently); 1 % keeps a well-determined value in
#: place without letting a spurious 1e-6 pin it
FLOOR = 0.01
#: a relative standard error below this is degenerate (a parameter that never moved in the
#: earlier fit, reported with a zero column): not a prior
DEGENERATE = 1e-6


def stage_priors(model: Model, names, stage: str) -> dict[str, tuple[str, float, float]]:
    """Gaussian priors from what earlier stages wrote: name -> (source stage, value, stderr).

    A parameter in ``model`` with a finite, positive standard error written by another stage
    (not ``stage`` itself, which would count its own logs twice) enters the fit as a prior of
    that width, so a parameter the new logs do not determine stays where the earlier data put
    it, and one they do determine is combined with it (docs/identification.md).
    """
    out = {}
    for n in names:
        par = model.parameters.get(n)
        if par is None or not par.stage or par.stage.startswith(stage):
            continue
        if par.stage in ("start", "datasheet", "given"):
            continue
        if not (math.isfinite(par.stderr) and math.isfinite(par.value)):
            continue
        scale = abs(par.value)
        if par.stderr <= DEGENERATE * scale:
            continue  # a zero Jacobian column: the earlier stage did not determine it
        out[n] = (par.stage, par.value, max(par.stderr, FLOOR * scale))
    return out


def prior_terms(prior) -> dict[str, tuple[float, float]]:
    """name -> (mean, std) for :func:`~pmdcid.fit.simfit.fit_simulation`."""
    return {n: (v, se) for n, (_, v, se) in prior.items()}
