"""Drift: how the parameters of units measured more than once move with time.

For each unit with at least two ok measurements at known times, and each parameter with
standard errors, a straight line value = a + slope t is fitted by weighted least squares
(weights 1/stderr^2, t in days). The slope's standard error comes from the measurements' own
standard errors, scaled up by sqrt(chi^2/dof) when three or more measurements scatter more than
those errors say. A drift is *significant* when the slope is at least :data:`Z_DRIFT` standard
errors from zero AND the change over the measured span is at least :data:`MIN_CHANGE` of the
value (a real, not just a resolvable, change: a bench's stderr of 0.02 % on R would otherwise
call a 0.1 % warm-up a drift).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from datetime import datetime

import numpy as np

from pmdcid.fleet.population import param_names, values

#: standard errors of the slope that make a drift significant
Z_DRIFT = 5.0
#: smallest relative change over the span called a drift
MIN_CHANGE = 0.01
#: seconds per day
DAY = 86400.0


@dataclass
class Drift:
    """One parameter of one unit over time."""

    unit: str
    parameter: str
    n: int
    first: float  # the fitted line at the first measurement
    last: float  # ... and at the last
    slope: float  # [parameter unit / day]
    z: float  # slope / its standard error
    days: float  # span of the measurements [days]
    significant: bool

    @property
    def change(self) -> float:
        """Relative change over the span (last / first - 1)."""
        return self.last / self.first - 1.0 if self.first else math.nan

    def describe(self) -> str:
        return (f"{self.parameter} {100 * self.change:+.2f} % over {self.days:.3g} days "
                f"({self.n} measurements, slope {self.z:+.1f} stderr)")


def _days(rows: list[dict]) -> np.ndarray:
    t = [datetime.fromisoformat(r["time"]).timestamp() for r in rows]
    return (np.array(t) - min(t)) / DAY


def line(t: np.ndarray, x: np.ndarray, s: np.ndarray) -> tuple[float, float, float]:
    """(intercept, slope, slope's stderr) of the weighted straight line (module doc)."""
    w = 1.0 / s ** 2
    tm = float(np.sum(w * t) / np.sum(w))
    sxx = float(np.sum(w * (t - tm) ** 2))
    slope = float(np.sum(w * (t - tm) * x) / sxx)
    a = float(np.sum(w * x) / np.sum(w)) - slope * tm
    se = 1.0 / math.sqrt(sxx)
    dof = len(t) - 2
    if dof > 0:
        chi2 = float(np.sum(w * (x - a - slope * t) ** 2))
        se *= math.sqrt(max(1.0, chi2 / dof))
    return a, slope, se


def _unit_drifts(unit: str, rows: list[dict]) -> list[Drift]:
    rows = sorted(rows, key=lambda r: r["time"])
    t = _days(rows)
    if not t[-1] > 0:
        return []
    out = []
    for name in param_names(rows):
        x, s = values(rows, name)
        ok = np.isfinite(x) & np.isfinite(s) & (s > 0)
        if ok.sum() < 2 or np.ptp(t[ok]) <= 0:
            continue
        a, slope, se = line(t[ok], x[ok], s[ok])
        first, last = a + slope * t[ok][0], a + slope * t[ok][-1]
        z = slope / se if se > 0 else math.inf * np.sign(slope)
        rel = abs(last - first) / abs(first) if first else math.inf
        out.append(Drift(unit, name, int(ok.sum()), first, last, slope, float(z),
                         float(np.ptp(t[ok])), bool(abs(z) >= Z_DRIFT and rel >= MIN_CHANGE)))
    return out


def drifts(rows: list[dict]) -> list[Drift]:
    """Every (unit, parameter) line of the units with two or more timed ok measurements."""
    by_unit: dict[str, list[dict]] = {}
    for r in rows:
        if r.get("status") == "ok" and r.get("time"):
            by_unit.setdefault(r["unit"], []).append(r)
    out = []
    for unit, rs in by_unit.items():
        if len(rs) >= 2:
            out += _unit_drifts(unit, rs)
    return out


__all__ = ["MIN_CHANGE", "Z_DRIFT", "Drift", "drifts", "line"]
