"""The population of a fleet: robust statistics, outliers and population priors.

Every statistic reads each unit once, at its latest measurement (a unit measured weekly
counts once, as it is now). Per parameter [its own unit]:

- the median and the robust sigma ``1.4826 MAD``, at least the median of the units' own
  standard errors (a spread smaller than the measurements' own errors is a small sample's
  accident: six repeats of one real motor had a MAD spread of bc below its stderr)
  (:class:`ParamStats`); rank (Spearman) correlations between parameters (:func:`correlations`);
- an **outlier** (:func:`outliers`) is a unit whose value lies at least :data:`Z_POP` robust
  sigmas from the median AND at least :data:`Z_OWN` of its own standard errors from it: a unit
  whose own uncertainty is too large to tell is never called an outlier;
- a **population prior** (empirical Bayes, :func:`pool`): the units' true values spread as
  N(median, tau^2), tau^2 = sigma^2 - median(stderr^2) (the measured spread less the part the
  measurements' own errors explain; at least sigma^2/10), and a unit's estimate x +- s combines
  with it by precision: pooled = w x + (1 - w) median, w = (1/s^2) / (1/s^2 + 1/tau^2),
  stderr (1/s^2 + 1/tau^2)^-1/2. A unit *borrows* a parameter where the prior's weight
  1 - w is at least :data:`BORROW`. A parameter a unit's logs only bound (an interval, no
  standard error) enters no statistic; its pooled value is the prior restricted to the
  interval (:func:`pool_bounded`). Needs :data:`MIN_UNITS` units.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: robust sigmas from the median, and own standard errors from it, that make an outlier
Z_POP = 4.0
Z_OWN = 3.0
#: prior weight above which a unit is said to borrow a parameter from the fleet
BORROW = 0.1
#: units needed for statistics, priors and outliers
MIN_UNITS = 5
#: robust sigma of a normal sample per MAD
MAD_SIGMA = 1.4826


@dataclass
class ParamStats:
    """One parameter over the fleet (values in the parameter's unit)."""

    name: str
    unit: str
    n: int
    median: float
    sigma: float  # 1.4826 MAD
    stderr: float  # median of the units' own standard errors (nan: none given)
    tau: float  # spread of the true values (nan: no prior)

    @property
    def rel_sigma(self) -> float:
        return self.sigma / abs(self.median) if self.median else math.nan


@dataclass
class Outlier:
    """One unit far from the fleet on one parameter, and why (``reason``, in words)."""

    unit: str
    parameter: str
    value: float
    z: float  # robust sigmas from the median (signed)
    z_own: float  # own standard errors from the median
    reason: str


def _num(x) -> float:
    try:
        v = float(x)
    except (TypeError, ValueError):
        return math.nan
    return v if math.isfinite(v) else math.nan


def latest(rows: list[dict]) -> list[dict]:
    """Each unit's latest ok row (a row without a time counts as the earliest)."""
    best: dict[str, dict] = {}
    for r in rows:
        if r.get("status") != "ok":
            continue
        cur = best.get(r["unit"])
        if cur is None or (r.get("time") or "") >= (cur.get("time") or ""):
            best[r["unit"]] = r
    return list(best.values())


def values(rows: list[dict], name: str) -> tuple[np.ndarray, np.ndarray]:
    """(values, stderrs) of ``name`` over ``rows`` (nan where a row lacks it, or where its logs
    only bound it: the point inside an interval is no estimate to pool)."""
    got = [r["params"].get(name, [math.nan, math.nan]) for r in rows]
    got = [[math.nan, math.nan] if len(g) > 3 else g for g in got]
    return (np.array([_num(g[0]) for g in got]), np.array([_num(g[1]) for g in got]))


def param_names(rows: list[dict]) -> list[str]:
    """Every parameter any row holds: the base parameters first, in their declared order."""
    from pmdcid.model.spec import BASE_PARAMS

    seen = {n for r in rows for n in r.get("params", {})}
    return [n for n in BASE_PARAMS if n in seen] + sorted(seen - set(BASE_PARAMS))


def unit_of(rows: list[dict], name: str) -> str:
    for r in rows:
        if name in r.get("params", {}):
            return str(r["params"][name][2] or "")
    return ""


def stats(rows: list[dict]) -> dict[str, ParamStats]:
    """:class:`ParamStats` of every parameter held by at least :data:`MIN_UNITS` units."""
    pop = latest(rows)
    out = {}
    for name in param_names(pop):
        x, s = values(pop, name)
        ok = np.isfinite(x)
        if ok.sum() < MIN_UNITS:
            continue
        med = float(np.median(x[ok]))
        sigma = MAD_SIGMA * float(np.median(np.abs(x[ok] - med)))
        se = s[ok & np.isfinite(s)]
        med_se = float(np.median(se)) if se.size else math.nan
        if math.isfinite(med_se) and sigma > 0:
            sigma = max(sigma, med_se)  # a spread below the units' own errors: a small sample
        tau = math.nan
        if se.size >= MIN_UNITS and sigma > 0:
            tau = math.sqrt(max(sigma ** 2 - float(np.median(se ** 2)), sigma ** 2 / 10.0))
        out[name] = ParamStats(name, unit_of(pop, name), int(ok.sum()), med, sigma, med_se, tau)
    return out


def correlations(rows: list[dict], names: list[str]) -> np.ndarray:
    """Spearman rank correlations between ``names`` over the units (latest rows; units
    lacking either parameter left out of that pair); nan where fewer than MIN_UNITS pairs."""
    from scipy.stats import rankdata

    pop = latest(rows)
    cols = [values(pop, n)[0] for n in names]
    k = len(names)
    out = np.full((k, k), math.nan)
    for a in range(k):
        for b in range(k):
            ok = np.isfinite(cols[a]) & np.isfinite(cols[b])
            if ok.sum() < MIN_UNITS:
                continue
            ra, rb = rankdata(cols[a][ok]), rankdata(cols[b][ok])
            if np.std(ra) > 0 and np.std(rb) > 0:
                out[a, b] = float(np.corrcoef(ra, rb)[0, 1])
    return out


def _reason(st: ParamStats, x: float, s: float, z: float, z_own: float) -> str:
    side = "above" if x > st.median else "below"
    unit = f" {st.unit}" if st.unit else ""
    return (f"{st.name} = {x:.4g}{unit} is {abs(z):.1f} robust sigma {side} the fleet median "
            f"{st.median:.4g} (sigma {st.sigma:.3g}, {100 * st.rel_sigma:.2g} %); its own "
            f"stderr {s:.2g} puts it {z_own:.0f} stderr away")


def outliers(rows: list[dict], table: dict[str, ParamStats]) -> list[Outlier]:
    """The outlier (unit, parameter) pairs of the units' latest measurements (module doc)."""
    pop = latest(rows)
    out = []
    for name, st in table.items():
        if not st.sigma > 0:
            continue
        x, s = values(pop, name)
        for r, xi, si in zip(pop, x, s, strict=True):
            if not (np.isfinite(xi) and np.isfinite(si) and si > 0):
                continue
            z, z_own = (xi - st.median) / st.sigma, abs(xi - st.median) / si
            if abs(z) >= Z_POP and z_own >= Z_OWN:
                out.append(Outlier(r["unit"], name, float(xi), float(z), float(z_own),
                                   _reason(st, xi, si, z, z_own)))
    return out


def pool(x: float, s: float, st: ParamStats) -> tuple[float, float, float]:
    """(pooled value, its stderr, prior weight 1 - w) of one estimate ``x +- s`` (module doc);
    the estimate itself (weight 0) when there is no prior or no stderr."""
    if not (math.isfinite(x) and math.isfinite(s) and s > 0 and math.isfinite(st.tau)):
        return x, s, 0.0
    a, b = 1.0 / s ** 2, 1.0 / st.tau ** 2
    w = a / (a + b)
    return w * x + (1.0 - w) * st.median, 1.0 / math.sqrt(a + b), 1.0 - w


def pool_bounded(low: float, high: float, st: ParamStats) -> tuple[float, float, float]:
    """(pooled value, its stderr, prior weight) of a parameter a unit's logs only bound to
    [low, high]: the population prior N(median, tau^2) restricted to the interval (its mean and
    standard deviation; all of it from the prior, weight 1); the interval's midpoint (no
    stderr, weight 0) when there is no prior."""
    if not (math.isfinite(st.tau) and st.tau > 0 and math.isfinite(st.median)):
        return 0.5 * (low + high), math.nan, 0.0
    from scipy.stats import truncnorm

    got = truncnorm((low - st.median) / st.tau, (high - st.median) / st.tau, loc=st.median,
                    scale=st.tau)
    mean, sd = float(got.mean()), float(got.std())
    if not (math.isfinite(mean) and math.isfinite(sd)):  # the interval far in a tail
        return 0.5 * (low + high), math.nan, 0.0
    return mean, sd, 1.0


__all__ = ["BORROW", "MIN_UNITS", "Outlier", "ParamStats", "Z_OWN", "Z_POP", "correlations",
           "latest", "outliers", "param_names", "pool", "pool_bounded", "stats", "values"]
