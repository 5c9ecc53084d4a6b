"""A lumped model's back-EMF share and what it moves: J and tau_e along the valley of equal
linear response.

Per volt, v -> omega is ``1 / (tau_e J s^2 + (J + tau_e (1 - ke_share) bv) s + bv)``: the share
trades with J and tau_e along a valley of equal linear response
(:func:`pmdcid.model.lumped.same_response`), only the friction and the dead zone (which acts on
the lagged torque) telling its points apart. Along it the cost is a staircase too (the dead
zone's events move by whole internal steps), and a local stage stops in any of its dips: there
the Jacobian's curvature is the dip's, not the valley's. Measured on the paper's motor
(ke_share 0.033, bench/pervolt_coverage.py): fits stopped at shares of 0.72-0.96 with standard
errors of 0.01-0.07, J +7 % at 11-31 of its standard errors, while the cost along the whole
valley varied by under 10 chi-square units.

:func:`share_interval` reads the valley instead: the cost at shares :data:`SHARES` (each with
the J and tau_e that keep the fit's linear response, the other parameters held), the fit's own
point left out (one arbitrary point of a rough floor), the lower convex envelope of those
costs (the staircase's upward steps dropped), and the interval of shares where that envelope
stays within two standard errors' rise of its lowest (4 x the reduced chi-square x the
correlated residual's inflation squared, as :mod:`.dead_zone`). Where the fit's own point lies
more than that threshold below the envelope's lowest, it is a minimum the grid steps over,
not a dip of a rough floor, and the local covariance stands (the bench motors of
bench/lawlag.py, back-EMF 99.6 % of the damping: the valley's minimum at shares 0.996-0.998,
66 chi-square units below every grid share, the mechanical damping (1 - ke_share) bv fixing
where the dead zone's edge lies; read as a flat valley from 0.78 to 1, J was moved 7 of its
standard errors off and bc, bv 4). Where the valley is clearly
narrower than the grid (the envelope rises beyond the threshold at both of the fit's
neighbouring grid shares) the local covariance stands and nothing changes. Else the share, J
and tau_e are moved to the interval's middle share and their standard errors are at least a
quarter of their ranges over it (the 2-standard-error interval's half-width, halved, as
:mod:`.dead_zone` does for dz); a note says so.
"""

from __future__ import annotations

import math

import numpy as np

from pmdcid.fit.results import Estimate, plus_minus, shown
from pmdcid.model.lumped import same_response

#: the shares the valley is read at: the whole range, 0 to 1
SHARES = tuple(np.round(np.linspace(0.0, 1.0, 21), 3))
#: the shares its dips are looked for at (:func:`restart_from_dips`): :data:`SHARES` and
#: 1 - share from 1e-2 to 1e-3 (as fit-nonlinear's grid,
#: :data:`pmdcid.identify.nonlinear.KE_SHARES`): the mechanical damping (1 - share) bv spans
#: decades near 1, where a motor whose back-EMF is nearly all of its damping has its minimum,
#: a dip narrower than the grid's 0.05 (bench/lawlag.py, share 0.996, seed 3, 1 kHz, L/R 2 ms:
#: the dip at 0.995 37 chi-square units below a valley otherwise flat within 1, the dead zone
#: profiled, once a moving start's current is its settled one, pmdcid/simulate/initial.py).
#: The interval a fit's share is read in keeps :data:`SHARES`: its lower convex envelope
#: would draw a chord from share 0 to such a dip and call a stretch of 0.06 flat
DIP_SHARES = tuple(sorted({*SHARES, 0.98, 0.99, 0.995, 0.998, 0.999}))
#: the threshold in standard errors (chi-square rise 4 x the reduced chi-square)
TWO_SE = 2.0
NAMES = ("J", "tau_e", "ke_share")
#: dead-zone values profiled at each valley point (:func:`valley_floor`)
DZ_N = 9
#: refits from the valley's other dips, lowest first (:func:`restart_from_dips`)
VALLEY_STARTS = 2
#: shares a dip is read again at, between its two grid neighbours (:func:`refined_dip`)
FINE_N = 21
#: shares the local stage is also restarted from, whatever the valley's cost there
#: (:func:`restart_from_dips`): the valley line is drawn from the fit's own point, whose
#: linear response is the data's only to within its errors, and the cost across the valley is
#: steep (tau_e to 0.03 %), so far from the fit the line runs beside the floor and its cost
#: says little about the floor's. Measured on the +-6 V PRBS of tests/test_pipeline.py
#: (share 0.35): the line's cost rose monotonically from its lowest at 0.1, while refits
#: from the line's points at 0.2, 0.35, 0.5 ended 1000, 1150, 980 chi-square units below the
#: fit (the one from 0.35 at the truth); refits cost 0.1-0.25 s each there
GRID_STARTS = (0.1, 0.3, 0.5, 0.7, 0.9)
#: evaluations of the residual a restart's probe runs for before it is judged
#: (:func:`probed`)
PROBE_NFEV = 10


def valley_points(point: dict[str, float], shares=SHARES) -> list[dict[str, float]]:
    """``point`` moved along the valley to each share of ``shares`` (the others held); a share
    no pair (J, tau_e) reaches is left out."""
    out = []
    for s in shares:
        moved = same_response(point["J"], point["tau_e"], point["bv"], point["ke_share"], s)
        if moved is not None:
            out.append({**point, "ke_share": float(s), "J": moved[0], "tau_e": moved[1]})
    return out


def lower_hull(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The lower convex envelope of the points (x ascending) evaluated at x."""
    keep: list[int] = []
    for k in range(len(x)):
        while len(keep) >= 2:
            a, b = keep[-2], keep[-1]
            if (y[b] - y[a]) * (x[k] - x[a]) >= (y[k] - y[a]) * (x[b] - x[a]):
                keep.pop()  # b lies on or above the chord a-k
            else:
                break
        keep.append(k)
    return np.interp(x, x[keep], y[keep])


def valley_threshold(fit) -> float:
    """Two standard errors' rise of the chi-square: 4 x the reduced chi-square (at least 1) x
    the correlated residual's inflation squared (``fit.stats.redchi``,
    ``fit.covariance.inflation``)."""
    infl = fit.covariance.inflation if fit.covariance and fit.covariance.inflation > 1 else 1.0
    return TWO_SE ** 2 * max(fit.stats.redchi, 1.0) * infl ** 2


#: the shares the interval's ends are read at (between the grid's points linearly)
READ_SHARES = np.linspace(0.0, 1.0, 1001)


def _interval(shares, rise, thr, fitted) -> tuple[float, float] | None:
    """(low, high) share where the envelope's ``rise`` (above its lowest) is within ``thr``,
    between grid points linearly; None when it rises beyond ``thr`` at the grid shares on
    both sides of ``fitted`` (the valley narrower than the grid: the local covariance
    stands). A grid share closer to ``fitted`` than the ends are read (:data:`READ_SHARES`'
    step) is the fit's own point, not a side: a fit at a share of 0.999996 beside the grid's
    1 had the interval [1, 1], and its standard error 0.023 became 3.6e-6 (bench/thinlogs.py
    b2:viscous_asymmetry seed 39, the truth's share 0.986)."""
    step = float(READ_SHARES[1] - READ_SHARES[0])
    left, right = np.flatnonzero(shares < fitted - step), np.flatnonzero(shares > fitted + step)
    narrow_l = len(left) == 0 or rise[left[-1]] > thr
    narrow_r = len(right) == 0 or rise[right[0]] > thr
    if narrow_l and narrow_r:
        return None
    ok = READ_SHARES[np.interp(READ_SHARES, shares, rise) <= thr]
    return (float(ok.min()), float(ok.max())) if len(ok) else None


def dead_zones(point: dict[str, float]) -> list[float]:
    """The dead zones :func:`valley_floor` profiles: the point's own, :data:`DZ_N` from 0 to
    twice the larger of bc and dz, and, where the fit's dz is over twice its bc, :data:`DZ_N`
    more from 0 to twice bc."""
    bc = max(point.get("bc", 0.0), 1e-12)
    top = 2.0 * max(point["dz"], bc)
    out = [point["dz"], *np.linspace(0.0, top, DZ_N)]
    if point["dz"] > 2.0 * bc:
        out += list(np.linspace(0.0, 2.0 * bc, DZ_N)[1:])
    return [float(d) for d in out]


def valley_floor(cost, pts, point) -> tuple[np.ndarray, list[dict[str, float]]]:
    """(the cost at each valley point of ``pts``, the points with the dead zone that gave it):
    where ``point`` has a dead zone it is profiled (the lowest over :data:`DZ_N` values from 0
    to twice the larger of bc and dz, and the point's own), since where the dead zone acts
    moves with the share and a dz held at the fit's would tilt the valley; else each point's
    cost as it is."""
    if "dz" not in point:
        return np.asarray(cost(pts), float), list(pts)
    dzs = dead_zones(point)
    c = np.asarray(cost([{**p, "dz": d} for p in pts for d in dzs]), float)
    c = c.reshape(len(pts), len(dzs))
    best = np.argmin(c, axis=1)
    return c.min(axis=1), [{**p, "dz": float(dzs[j])} for p, j in zip(pts, best, strict=True)]


def dips(shares: np.ndarray, cost: np.ndarray, own: float) -> list[int]:
    """Indices of the local minima of ``cost`` along ``shares`` (an end counts when below its
    one neighbour), lowest first, but the share nearest ``own`` (the fit's: a dip there is the
    fit's own)."""
    n = len(cost)
    near = int(np.argmin(np.abs(shares - own)))

    def lower(j: int) -> bool:
        return ((j == 0 or cost[j] < cost[j - 1]) and (j == n - 1 or cost[j] <= cost[j + 1]))

    return sorted((j for j in range(n) if lower(j) and j != near), key=lambda j: cost[j])


def refined_dip(cost, point, shares, c, starts, j, n=FINE_N) -> dict[str, float]:
    """The start at the grid's dip ``j`` read again at ``n`` shares between its neighbours
    (``shares``, their floor ``c`` and points ``starts`` from :func:`valley_floor`): the
    lowest of them where lower than the grid's. A minimum between grid shares is otherwise
    started from one step off, on the bound where the dip is the grid's end (bench/lawlag.py
    1 kHz seed 3, L/R 2 ms: the valley's minimum at share 0.994, the grid's dip at 1, the
    local stage from share 1 stopping 40 chi-square above the one from 0.995)."""
    lo, hi = shares[max(j - 1, 0)], shares[min(j + 1, len(shares) - 1)]
    pts = valley_points(point, np.linspace(lo, hi, n))
    if not pts:
        return starts[j]
    fc, fine = valley_floor(cost, pts, point)
    k = int(np.argmin(fc))
    return fine[k] if fc[k] < c[j] else starts[j]


def restart_from_dips(cost, point: dict[str, float], refit, chi2, fine: bool = True,
                      grid: bool = True, probe=None, bar: float = math.inf):
    """The lowest of the refits from the valley's other dips (:data:`VALLEY_STARTS` of them,
    lowest first: the local minima of the cost along :data:`DIP_SHARES`, the dead zone profiled
    by :func:`valley_floor`, but the grid share nearest ``point``'s) and from its points at
    :data:`GRID_STARTS` (those more than a grid step from ``point``'s share); None when
    ``point`` has no free valley or no refit succeeded. ``cost(sets)``: the chi-square of each set;
    ``point``: the fit's free values (J, tau_e, ke_share, bv; dz when free);
    ``refit(start)``: a fit from the start (None when it failed); ``chi2(fit)``: its
    chi-square; ``fine``: each dip read again between its grid neighbours
    (:func:`refined_dip`); ``grid``: the :data:`GRID_STARTS` too; ``probe(start)``: a short
    fit from the start, (its chi-square, its end point) or None, each start then refitted
    from where its probe ended, and only where that is below ``bar`` (:func:`probed`).
    Whether the lowest is decisively lower than the fit is the caller's to judge
    (:func:`valley_threshold`)."""
    if not all(k in point for k in (*NAMES, "bv")):
        return None
    pts = valley_points(point, DIP_SHARES)
    if len(pts) < 3:
        return None
    c, starts = valley_floor(cost, pts, point)
    shares = np.array([p["ke_share"] for p in pts])
    tries = [refined_dip(cost, point, shares, c, starts, j) if fine else starts[j]
             for j in dips(shares, c, point["ke_share"])[:VALLEY_STARTS]]
    if grid:
        tries += grid_starts(point, [p["ke_share"] for p in tries])
    best = None
    for start in probed(tries, probe, bar):
        f = refit(start)
        if f is not None and (best is None or chi2(f) < chi2(best)):
            best = f
    return best


def probed(starts, probe, bar: float) -> list[dict[str, float]]:
    """The points whole refits run from: ``starts`` as they are without a ``probe``; else,
    for each, where its probe (a short local fit, :data:`PROBE_NFEV` evaluations) ended, kept
    only where its chi-square is then below ``bar`` (the fit's less the threshold a restart
    must beat). A refit from a valley where the logs do not tell the share crawls along it
    and ends where the fit is: measured on the paper fixtures (`pmdcid identify
    fixtures/paper/*.csv --no-diagnose`, no km, share 0), each stage's six refits ended 1-5
    chi-square units above the fit after 38-89 evaluations, 31 and 37 s of the command's
    111 s, and none could be kept; a floor the valley line runs beside is seen within a few
    steps (the +-6 V PRBS above: 1000 units below the fit)."""
    if probe is None:
        return list(starts)
    out = []
    for start in starts:
        got = probe(start)
        if got is not None and got[0] < bar:
            out.append(got[1])
    return out


def grid_starts(point: dict[str, float], taken) -> list[dict[str, float]]:
    """``point`` moved along its valley to each share of :data:`GRID_STARTS` more than a grid
    step (0.05) from its own share and from each share of ``taken``."""
    step = SHARES[1] - SHARES[0]
    near = [point["ke_share"], *taken]
    shares = [s for s in GRID_STARTS if all(abs(s - x) > step for x in near)]
    return valley_points(point, shares)


def share_range(cost, fit, est: dict[str, Estimate]) -> tuple[float, float] | None:
    """The interval of back-EMF shares that fit as well as the fit's own (module docstring:
    the valley's lower envelope within two standard errors' rise of its lowest); None when the
    fit has no free share, J and tau_e, or the local covariance stands (a minimum the grid
    steps over, or a valley narrower than the grid). ``est``: the fit's estimates;
    ``cost(sets)``: the chi-square of each set; ``fit``: its ``stats.redchi`` and
    ``covariance.inflation`` set the threshold."""
    if not all(k in est for k in NAMES) or "bv" not in est:
        return None
    point = {k: e.value for k, e in est.items()}
    pts = valley_points(point)
    if len(pts) < 3:
        return None
    shares = np.array([p["ke_share"] for p in pts])
    c, _ = valley_floor(cost, [*pts, point], point)
    env, own = lower_hull(shares, c[:-1]), float(c[-1])
    thr = valley_threshold(fit)
    if own < env.min() - thr:
        return None  # a minimum the grid steps over, deeper than the floor's roughness
    return _interval(shares, env - env.min(), thr, point["ke_share"])


def share_interval(cost, fit, est: dict[str, Estimate]) -> tuple[dict[str, Estimate], str]:
    """(estimates to write in place of ``est``'s J, tau_e, ke_share, the words for the notes)
    from the valley (module docstring, :func:`share_range`); ({}, "") when the fit has no free
    share, J and tau_e, or the local covariance stands. ``est``: the fit's estimates as they
    stand (a standard error already widened kept when larger); ``cost(sets)``: the chi-square
    of each set."""
    found = share_range(cost, fit, est)
    if found is None:
        return {}, ""
    corr = getattr(fit, "correlation", None)  # a fit's local correlations, where it has them
    rho = {k: corr(k, "ke_share") if corr else math.nan for k in NAMES}
    point = {k: e.value for k, e in est.items()}
    moved, why = _moved(point, est, found, rho)
    if moved and not _fits(cost, fit, point, moved):
        return _kept(point, est, found, rho)
    return moved, why


def _fits(cost, fit, point: dict[str, float], moved: dict[str, Estimate]) -> bool:
    """Whether ``point`` with ``moved``'s values (the share interval's middle, the other
    parameters, the dead zone among them, as fitted) fits within two standard errors' rise
    (:func:`valley_threshold`) of ``point`` itself. The interval is read with the dead zone
    profiled at each share (:func:`valley_floor`): where the dead zone acts on v - ke w, a
    share moved with the fitted dead zone held can leave a model that fits nothing
    (guanlunlu-l298n's steps with a lag, session 33's trial in docs/identification.md: the fit
    at share 0 with a 5 V dead zone, moved to share 0.5, simulated its 6 V fit step at 0.74
    against 0.017)."""
    c = cost([point, {**point, **{k: e.value for k, e in moved.items()}}])
    return float(c[1]) - float(c[0]) <= valley_threshold(fit)


def _kept(point, est, found, rho) -> tuple[dict[str, Estimate], str]:
    """J, tau_e, ke_share at the fit's own point (where the interval's middle does not fit,
    :func:`_fits`), each standard error at least half its farther reach over the share
    interval ``found``, so that two reach both its ends."""
    ends = valley_points(point, found)
    if len(ends) < 2:
        return {}, ""
    out = {}
    for k in NAMES:
        e = est[k]
        reach = max(abs(x[k] - e.value) for x in ends)
        se = max(at_share(e.stderr, rho.get(k, math.nan)), 0.5 * reach)
        out[k] = Estimate(k, e.value, se, e.unit, caveat=e.caveat)
    why = (f"ke_share between {found[0]:.2g} and {found[1]:.2g} fits as well (the back-EMF's "
           "share of bv trades with J and tau_e at equal linear response, only the friction "
           "and the dead zone tell them apart), but the interval's middle with the dead zone "
           "as fitted does not: J, tau_e and ke_share kept where the fit put them, their "
           "standard errors reaching the interval's ends")
    return out, why


def at_share(se: float, rho: float) -> float:
    """A standard error with the share held: ``se sqrt(1 - rho^2)``, ``rho`` the local
    correlation with the share (``se`` itself where that is not a number)."""
    return se * math.sqrt(max(1.0 - rho * rho, 0.0)) if math.isfinite(rho) else se


def pm(e: Estimate, fmt: str = ".3g") -> str:
    """``value ± stderr`` of ``e`` for a note as it is shown (:func:`pmdcid.fit.results.shown`:
    no standard error where it spans the whole range; :func:`~pmdcid.fit.results.plus_minus`)."""
    s = shown(e)
    return plus_minus(s.value, s.stderr, fmt)


def _moved(point, est, found, rho) -> tuple[dict[str, Estimate], str]:
    """J, tau_e, ke_share at the middle of the share interval ``found``, their standard
    errors the local ones with the share held (:func:`at_share`; ``rho``: each one's local
    correlation with the share) and a share uniform over the interval combined.

    The local covariance's own part along the valley is the linearisation of a cost that is
    flat there and bounded by the share's range, 0 to 1: where the share is poorly determined
    it claims more than the whole valley spans (``bench/lawlag.py --family share03``, the
    dead zone masked, shares 0-0.95 fitting as well: J' ± 0.032 V s^2/rad, 430 %, where the
    valley's J' spans 0.0068-0.0077). The valley's reading replaces that part, the rest (the
    error with the share held) kept."""
    ends = valley_points(point, found)
    middle = valley_points(point, [0.5 * (found[0] + found[1])])
    if len(ends) < 2 or not middle:  # a share no (J, tau_e) of equal response reaches: the
        return {}, ""  # local covariance stands (bench/fuzz_cli.py negative-only: IndexError)
    lo, hi, mid = ends[0], ends[-1], middle[0]
    out = {}
    for k in NAMES:
        e = est[k]
        spread = abs(hi[k] - lo[k]) / math.sqrt(12.0)  # uniform over the interval
        local = at_share(e.stderr, rho.get(k, math.nan))
        out[k] = Estimate(k, mid[k], math.hypot(local, spread), e.unit, caveat=e.caveat)
    where = (f"ke_share between {found[0]:.2g} and {found[1]:.2g}" if found[1] - found[0] > 0.01
             else f"only ke_share = {mid['ke_share']:.2g} (the valley's cost rises by two standard "
             "errors within a grid step of it)")
    why = (f"{where} fits as well (the back-EMF's "
           "share of bv trades with J and tau_e at equal linear response, only the friction "
           "and the dead zone tell them apart): J, tau_e and ke_share at that interval's "
           "middle, their standard errors the local fit's with the share held and a share "
           f"uniform over the interval combined (the local fit gave J = {pm(est['J'], '.5g')}, "
           f"ke_share = {pm(est['ke_share'])})")
    return out, why


__all__ = ["DIP_SHARES", "FINE_N", "GRID_STARTS", "NAMES", "PROBE_NFEV", "SHARES",
           "VALLEY_STARTS", "at_share", "dips", "grid_starts", "lower_hull", "probed",
           "refined_dip", "restart_from_dips", "share_interval", "share_range", "valley_floor",
           "valley_points", "valley_threshold"]
