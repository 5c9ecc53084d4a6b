"""An inductance the data do not determine, carried into what the speed steps give.

fit-mechanical holds the electrical lag tau_e = L/R from fit-electrical. When the blocked-rotor
logs are sampled slower than about three tau_e, L is not identifiable (fit-electrical writes the
interval of 0 to 3 sample periods of L/R), yet the lag still moves the speed steps'
inertia: on the paper's logs at 10 Hz, an L off by -80 % moved J by +6 % while its standard
error said 0.6 %. :func:`carry_inductance_error` fits the steps again at L minus and plus its
standard error (an interval's uniform spread) and adds half the spread of each lag-sensitive
parameter to its error (in quadrature), with a warning naming the range of J.
"""

from __future__ import annotations

import math

from pmdcid.errors import PmdcidError
from pmdcid.fit.results import Estimate

#: an L whose standard error exceeds this fraction of its value is carried into J, bv, bc
L_POOR = 0.25
#: the fitted parameters the electrical lag L/R moves
LAG_SENSITIVE = ("J", "bv", "bc", "T_break", "tau_mot", "J_paper")


def carry_inductance_error(res, model, refit) -> None:
    """Widen the standard errors of :data:`LAG_SENSITIVE` in ``res.estimates`` by the spread
    L's error gives them; ``refit(model)`` fits the steps again on a model (returns estimates)."""
    par = model.parameters.get("L")
    spread = _spread(par)
    if par is None or not (math.isfinite(spread) and spread > L_POOR * par.value):
        return
    fits = []
    for L in (max(par.value - spread, 1e-3 * par.value), par.value + spread):
        m = model.copy()
        m.set("L", L, spread, par.unit, stage=par.stage)
        try:
            fits.append(refit(m))
        except PmdcidError:
            return
    moved = []
    for name in LAG_SENSITIVE:
        e = res.estimates.get(name)
        if e is None or not all(name in f for f in fits):
            continue
        half = 0.5 * abs(fits[1][name].value - fits[0][name].value)
        # an error the fit did not give (one step: no scatter) stays unknown, never L's part
        res.estimates[name] = Estimate(name, e.value, math.hypot(e.stderr, half), e.unit,
                                       e.vary)
        if name == "J":
            moved.append(f"J {fits[0][name].value:.4g} to {fits[1][name].value:.4g} {e.unit}")
    said = (f"L between {par.interval[0]:.3g} and {par.interval[1]:.3g} H is not identified"
            if par.interval is not None else
            f"L = {par.value:.3g} ± {par.stderr:.2g} H is poorly determined")
    res.warnings.append(f"{said} ({par.stage or 'the model'}): over L ± {spread:.2g} H (its "
                        f"{'uniform spread' if par.interval is not None else 'error'}) the "
                        f"electrical lag moves {', '.join(moved) or 'the fit'}; the standard "
                        "errors include that")


def _spread(par) -> float:
    """L's standard error [H], or for an L the logs only bound, its interval's uniform spread
    (width over sqrt(12)): what L leaves open in the speed steps' parameters."""
    if par is None:
        return math.nan
    if par.interval is not None:
        return (par.interval[1] - par.interval[0]) / math.sqrt(12.0)
    return par.stderr


__all__ = ["L_POOR", "LAG_SENSITIVE", "carry_inductance_error"]
