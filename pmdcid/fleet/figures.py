"""The fleet page's figures (matplotlib, Agg canvas, no pyplot state): each returns PNG bytes.

- :func:`distributions`: one panel per parameter, each unit's latest value with its standard
  error, the median and the outlier band (``Z_POP`` robust sigmas), outliers in red;
- :func:`drift_figure`: the parameters that drift, value against time for every unit measured
  more than once, the drifting units' lines drawn solid.
"""

from __future__ import annotations

import io
import math

import numpy as np

from pmdcid.fleet.population import Z_POP, latest, values

DPI = 90


def _figure(n: int, ncols: int = 3, height: float = 2.4):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    nrows = max(1, math.ceil(n / ncols))
    fig = Figure(figsize=(11, height * nrows), dpi=DPI, layout="constrained")
    FigureCanvasAgg(fig)
    axes = fig.subplots(nrows, ncols, squeeze=False).ravel()
    for ax in axes[n:]:
        ax.set_visible(False)
    return fig, axes


def plain(text: str) -> str:
    """``text`` shown as written by matplotlib (no mathtext: a ``$`` is a dollar sign)."""
    return str(text).replace("$", r"\$")


def _png(fig) -> bytes:
    buf = io.BytesIO()
    fig.savefig(buf, format="png", dpi=DPI)
    return buf.getvalue()


def _panel(ax, rows, st, flagged: set[str]) -> None:
    x, s = values(rows, st.name)
    ok = np.isfinite(x)
    y = np.arange(len(rows))[ok]
    red = np.array([r["unit"] in flagged for r in rows])[ok]
    err = np.where(np.isfinite(s[ok]), s[ok], 0.0)
    ax.axvspan(st.median - Z_POP * st.sigma, st.median + Z_POP * st.sigma, color="#e8f0fa")
    ax.axvline(st.median, color="#1f4e9c", lw=1)
    for mask, colour in ((~red, "#333333"), (red, "#c62828")):
        if mask.any():
            ax.errorbar(x[ok][mask], y[mask], xerr=err[mask], fmt="o", ms=3, color=colour,
                        lw=0.8)
    ax.set_title(f"{st.name} [{st.unit}]" if st.unit else st.name, fontsize=9)
    ax.set_yticks([])
    ax.tick_params(labelsize=7)


def distributions(rows: list[dict], table: dict, outliers) -> bytes | None:
    """Each parameter's spread over the units (module doc); None without parameters."""
    names = [n for n, st in table.items() if st.sigma > 0]
    if not names:
        return None
    pop = latest(rows)
    fig, axes = _figure(len(names))
    for ax, name in zip(axes, names, strict=False):
        _panel(ax, pop, table[name], {o.unit for o in outliers if o.parameter == name})
    return _png(fig)


def drift_figure(rows: list[dict], drifts) -> bytes | None:
    """Value against time of the drifting parameters (module doc); None when none drifts."""
    from datetime import datetime

    from matplotlib.dates import AutoDateLocator, ConciseDateFormatter

    names = sorted({d.parameter for d in drifts if d.significant})
    if not names:
        return None
    moving = {(d.unit, d.parameter) for d in drifts if d.significant}
    repeated = sorted({d.unit for d in drifts})
    fig, axes = _figure(len(names), ncols=2, height=2.8)
    for ax, name in zip(axes, names, strict=False):
        for unit in repeated:
            rs = sorted((r for r in rows if r["unit"] == unit and r.get("status") == "ok"
                         and r.get("time") and name in r["params"]), key=lambda r: r["time"])
            if len(rs) < 2:
                continue
            t = [datetime.fromisoformat(r["time"]) for r in rs]
            x, s = values(rs, name)
            solid = (unit, name) in moving
            ax.errorbar(t, x, yerr=np.where(np.isfinite(s), s, 0.0), fmt="o-" if solid else "o:",
                        ms=3, lw=1.2 if solid else 0.6, color=None if solid else "#999999",
                        label=plain(unit) if solid else None)
        loc = AutoDateLocator(maxticks=6)
        ax.xaxis.set_major_locator(loc)
        ax.xaxis.set_major_formatter(ConciseDateFormatter(loc))
        ax.set_title(name, fontsize=9)
        ax.tick_params(labelsize=7)
        ax.legend(fontsize=7)
    return _png(fig)


__all__ = ["distributions", "drift_figure"]
