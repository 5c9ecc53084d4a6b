"""The report's figures (matplotlib, Agg canvas, no pyplot state): each returns PNG bytes.

Speed (issue #16): long lines are drawn as their min/max envelope per pixel column
(:mod:`pmdcid.report.decimate`; every number on the page is computed from the full data), and a
:class:`FigurePool` lets the per-log figures of one report reuse one figure per layout, so that
matplotlib builds its axes and ticks once rather than once per log. PNGs are written from the
Agg buffer as RGB (the figures are opaque) at zlib level 3: the same pixels as ``savefig``.
"""

from __future__ import annotations

import io

import numpy as np

from pmdcid.io.escape import mpl_text
from pmdcid.report.decimate import envelope_indices, scatter_indices

DPI = 100
#: zlib level of the PNGs: 3 is ~2x faster to encode than PIL's 6 for files ~5 % larger
PNG_LEVEL = 3
#: measured: a wide light-grey band; the model: a thin saturated line on top. Told apart by
#: weight and lightness in grey print, by colour on screen, whatever the zoom (issue #26)
MEAS = dict(color="0.62", lw=2.6, solid_capstyle="butt", label="measured")
SIM = dict(color="#c4001a", lw=1.0, label="model")
INPUT = dict(color="#1f4e9c", lw=1.0)
LABELS = {"omega": "speed [rad/s]", "theta": "angle [rad]", "i": "current [A]",
          "v": "input voltage [V]", "tau": "input torque [N m]"}
#: right margin [in] of a figure with axes in the log's own units
RIGHT_UNITS = 0.95


class FigurePool:
    """Figures kept for reuse within one report, one per layout (see :func:`_new`).

    A reused figure is emptied of everything the figure functions add (lines, collections,
    patches, texts, legends, titles, labels, scales, limits) but keeps its axes and their tick
    objects, which are most of a figure's build cost. It draws the same pixels as a new one
    (``tests/report/test_decimate.py``).
    """

    def __init__(self):
        self._figs: dict[tuple, tuple] = {}

    def get(self, key: tuple):
        got = self._figs.get(key)
        if got is None:
            got = self._figs[key] = _build(*key)
        else:
            _empty(*got)
        return got


def _new(nrows: int, ncols: int, height: float, left: float = 0.85, wspace: float = 0.22,
         top: float = 0.45, pool: FigurePool | None = None, right: float = 0.165):
    """A figure 11 in wide with fixed margins (``left``, ``right`` in inches); from ``pool``
    if given."""
    key = (nrows, ncols, height, left, wspace, top, right)
    return pool.get(key) if pool is not None else _build(*key)


def _build(nrows, ncols, height, left, wspace, top, right=0.165):
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(figsize=(11, height), dpi=DPI)
    FigureCanvasAgg(fig)
    axes = fig.subplots(nrows, ncols, squeeze=False)
    # fixed margins (in inches): constrained layout doubles the drawing time
    fig.subplots_adjust(left=left / 11, right=1 - right / 11, top=1 - top / height,
                        bottom=0.55 / height, hspace=0.55 * 2.3 / max(height / nrows, 1.0),
                        wspace=wspace)
    return fig, axes


def _empty(fig, axes) -> None:
    """Back to the state :func:`_build` leaves, except the axes' tick objects."""
    from matplotlib.transforms import Bbox

    if fig._suptitle is not None:
        fig._suptitle.remove()
        fig._suptitle = None
    for ax in axes.flat:
        for a in [*ax.lines, *ax.collections, *ax.patches, *ax.texts, *ax.child_axes]:
            a.remove()
        if ax.legend_ is not None:
            ax.legend_.remove()
        ax.set_title("")  # and the title's default font
        ax.set_xlabel("")
        ax.set_ylabel("")
        ax.set_xscale("linear")  # and the default tick locators and formatters
        ax.set_yscale("linear")
        ax.dataLim = Bbox.null()  # the next plots set the limits as on new axes
        ax.ignore_existing_data_limits = True
        ax.set_xlim(0, 1)
        ax.set_ylim(0, 1)
        ax.set_autoscale_on(True)


def _freeze_ticks(fig) -> None:
    """Fix each linear axis' ticks and labels at what its locator and formatter give now.

    Drawing asks an axis for its ticks several times (the axis, its label's position, the
    title's); once fixed, each asks a list instead of rerunning the locator and formatter.
    The same ticks and labels (and offset text) are drawn. Call when the figure is complete.
    """
    from matplotlib.ticker import FixedFormatter, FixedLocator

    for ax in fig.axes:
        for axis in (ax.xaxis, ax.yaxis):
            if axis.get_scale() != "linear":
                continue
            locs = axis.get_majorticklocs()
            fmt = axis.get_major_formatter()
            fixed = FixedFormatter(fmt.format_ticks(locs))
            fixed.set_offset_string(fmt.get_offset())
            axis.set_major_locator(FixedLocator(locs))
            axis.set_major_formatter(fixed)


def _png(fig) -> bytes:
    """The figure as PNG: Agg's pixels as RGB, zlib level :data:`PNG_LEVEL`."""
    from PIL import Image

    _freeze_ticks(fig)
    fig.canvas.draw()
    img = Image.frombuffer("RGBA", fig.canvas.get_width_height(),
                           fig.canvas.buffer_rgba(), "raw", "RGBA", 0, 1).convert("RGB")
    buf = io.BytesIO()
    img.save(buf, format="png", compress_level=PNG_LEVEL, dpi=(DPI, DPI))
    return buf.getvalue()


def _columns(ax) -> int:
    """Pixel columns of an axes (its width at the figure's dpi)."""
    return max(int(ax.bbox.width), 1)


def _line(ax, t, y, **kw) -> None:
    """``ax.plot(t, y)`` drawing only the min/max envelope per pixel column of a long line."""
    k = envelope_indices(t, y, _columns(ax))
    ax.plot(np.asarray(t)[k], np.asarray(y)[k], **kw)


def _maybe_log(ax, values, label: str) -> None:
    """Log x-scale when the positive values span more than two decades."""
    v = np.asarray([x for x in values if x is not None and x > 0], float)
    if len(v) and v.max() / v.min() > 100:
        ax.set_xscale("log")
        label += " (log scale)"
    ax.set_xlabel(label)


def zoom_window(t: np.ndarray, omega: np.ndarray, threshold: float) -> tuple[int, int, str]:
    """Sample range around the first zero-speed crossing (or the first breakaway from rest).

    A crossing is where the measured speed goes from below -threshold to above +threshold (or the
    reverse); the window shows the dwell near zero plus as much again on each side. The threshold
    is raised to 5 noise standard deviations so that sensor noise at rest is no crossing.
    """
    from pmdcid.io.derive import noise_std

    n = len(omega)
    threshold = max(threshold, 5.0 * noise_std(omega))
    big = np.flatnonzero(np.abs(omega) >= threshold) if threshold > 0 else np.array([], int)
    if len(big) >= 2:
        sgn = np.sign(omega[big])
        flips = np.flatnonzero(sgn[1:] != sgn[:-1])
        if len(flips):
            a, b = int(big[flips[0]]), int(big[flips[0] + 1])
            w = max(b - a, 20)
            return max(0, a - w), min(n, b + w + 1), "zero-speed crossing"
    if len(big):
        a = int(big[0])
        w = max(a // 4, 20, n // 40)
        return max(0, a - w), min(n, a + 3 * w), "breakaway from rest"
    return 0, min(n, max(n // 10, 2)), "start"


def _logged_axis(ax, lu: dict | None) -> None:
    """A right-hand axis in the log's own unit (``lu``: source, scale, offset; SI = logged x
    scale + offset), e.g. rpm beside rad/s, PWM counts beside volts."""
    if not lu:
        return
    k, b = float(lu["scale"]), float(lu["offset"])
    sec = ax.secondary_yaxis("right", functions=(lambda y: (y - b) / k, lambda r: r * k + b))
    sec.set_ylabel(f"{lu['source']} (as logged)", fontsize=8)
    sec.tick_params(labelsize=8)


def _fit_label(metrics: dict, s: str) -> str:
    fit = metrics["signals"][s].get("fit_percent")
    return f"model (fit {fit:.1f} %)" if fit is not None else "model"


def _input_panel(ax, cmp) -> None:
    log = cmp.log
    _line(ax, log.t, log.u, **INPUT)
    ax.set_ylabel(LABELS[log.drive])
    _logged_axis(ax, cmp.metrics.get("logged_units", {}).get(log.drive))
    ax.grid(alpha=0.3)


def _pair(ax, cmp, s: str, a: int = 0, b: int | None = None) -> None:
    """Measured and model of signal ``s`` over samples a..b; above the panel, the legend with
    the whole log's fit (not on the zoom: its fit would be the whole log's, not the zoom's)."""
    log = cmp.log
    label = _fit_label(cmp.metrics, s) if a == 0 and b is None else "model"
    _line(ax, log.t[a:b], log[s][a:b], **MEAS)
    _line(ax, log.t[a:b], cmp.sim.get(s)[a:b], **{**SIM, "label": label})
    ax.legend(loc="lower right", bbox_to_anchor=(1.0, 1.0), ncol=2, fontsize=8, frameon=False,
              borderaxespad=0.1)
    ax.grid(alpha=0.3)


def overlay_figure(cmp, pool: FigurePool | None = None) -> bytes:
    """The input on top, then measured against model for each compared signal (the legend
    gives the fit), and a zoom near zero speed; axes in the log's own units on the right."""
    log = cmp.log
    zoom = "omega" in cmp.signals and cmp.threshold is not None
    rows = 1 + len(cmp.signals) + (1 if zoom else 0)
    units = cmp.metrics.get("logged_units", {})
    fig, axes = _new(rows, 1, 2.1 * rows + 0.4, pool=pool,
                     right=RIGHT_UNITS if units else 0.165)
    _input_panel(axes[0, 0], cmp)
    for ax, s in zip(axes[1:, 0], cmp.signals, strict=False):
        _pair(ax, cmp, s)
        ax.set_ylabel(LABELS[s] + (" (derived)" if s in getattr(log, "derived", ()) else ""))
        _logged_axis(ax, units.get(s))
    if zoom:
        a, b, what = zoom_window(log.t, log["omega"], cmp.threshold)
        ax = axes[-1, 0]
        _pair(ax, cmp, "omega", a, b)
        for sgn in (-1, 1):
            ax.axhline(sgn * cmp.threshold, color="tab:blue", lw=0.6, ls=":")
        ax.set_ylabel(LABELS["omega"])
        _logged_axis(ax, units.get("omega"))
        ax.set_title(f"zoom: {what} (dotted: near-zero band ±{cmp.threshold:.3g} rad/s)",
                     fontsize=9, loc="left")
    axes[-1, 0].set_xlabel("time [s]")
    fig.suptitle(f"{mpl_text(cmp.name)}: input, then measured (grey band) and model (red line)",
                 fontsize=11)
    return _png(fig)


def residual_figure(cmp, pool: FigurePool | None = None) -> bytes:
    """Residual of the first signal vs time and vs speed; its autocorrelation and its
    cross-correlation with the input, with the 99 % bands."""
    log, sim = cmp.log, cmp.sim
    s = cmp.signals[0]
    m = cmp.metrics["signals"][s]
    e = sim.get(s) - log[s]
    fig, axes = _new(2, 2, 6.3, top=0.7, pool=pool)
    ax = axes[0, 0]
    _line(ax, log.t, e, color="tab:purple", lw=0.7)
    st = scatter_indices(e)  # the scatters: a uniform sample plus every outlier beyond it
    ax.set_xlabel("time [s]")
    ax.set_ylabel(f"residual sim-meas [{m['unit']}]")
    ax.set_title(f"{s} residual against time", fontsize=9)
    ax.grid(alpha=0.3)
    ax = axes[0, 1]
    if log.has("omega") and not cmp.blocked:
        ax.plot(log["omega"][st], e[st], ".", ms=1.5, color="tab:purple", alpha=0.5)
        if cmp.threshold:
            for sgn in (-1, 1):
                ax.axvline(sgn * cmp.threshold, color="tab:blue", lw=0.6, ls=":")
        ax.set_xlabel("measured speed [rad/s]")
        ax.set_title(f"{s} residual against speed (dotted: near-zero band)", fontsize=9)
    else:
        ax.plot(log.u[st], e[st], ".", ms=1.5, color="tab:purple", alpha=0.5)
        ax.set_xlabel(f"input {log.drive}")
        ax.set_title(f"{s} residual against the input (rotor blocked)", fontsize=9)
    ax.set_ylabel(f"residual [{m['unit']}]")
    ax.grid(alpha=0.3)
    r = m["resid"]
    dt = log.dt
    for ax, key, title in ((axes[1, 0], "auto", "autocorrelation of the residual"),
                           (axes[1, 1], "cross", f"cross-correlation input {log.drive} -> "
                                                  "residual")):
        lags = np.asarray(r[key]["lags"]) * dt
        vals = np.array([np.nan if v is None else v for v in r[key]["r"]])
        ax.vlines(lags, 0, vals, color="tab:purple", lw=1.5)
        ax.plot(lags, vals, "o", ms=3, color="tab:purple")
        band = r[key]["band"]
        if band is not None:
            ax.axhspan(-band, band, color="tab:blue", alpha=0.15, label="99 % band")
            ax.legend(loc="upper right", fontsize=8)
        ax.axhline(0, color="0.4", lw=0.5)
        ax.set_xlabel("lag [s]")
        ax.set_title(title, fontsize=9)
        ax.grid(alpha=0.3)
    fig.suptitle(f"{mpl_text(cmp.name)}: {s} residual", fontsize=11)
    return _png(fig)


def fit_figure(rows: list[tuple[str, dict]]) -> bytes:
    """Fit % per log and signal (MATLAB compare's figure of merit), near-zero speed vs rest."""
    labels = [f"{mpl_text(name)} {s}" for name, sig in rows for s in sig]
    left = 0.3 + 0.065 * max(len(x) for x in labels)
    fig, axes = _new(1, 2, 1.6 + 0.3 * len(labels), left=left, wspace=left / 4.5)
    fits = [sig[s]["fit_percent"] for _, sig in rows for s in sig]
    y = np.arange(len(labels))
    ax = axes[0, 0]
    ax.barh(y, [f if f is not None else 0 for f in fits], color="tab:green")
    ax.set_yticks(y, labels, fontsize=8)
    ax.invert_yaxis()
    ax.set_xlabel("fit [%] = 100 (1 - NRMSE)")
    ax.set_xlim(min(0, *[f for f in fits if f is not None], 0), 100)
    ax.grid(alpha=0.3, axis="x")
    ax = axes[0, 1]
    lo = [sig[s].get("low_speed", {}).get("nrmse") or 0 for _, sig in rows for s in sig]
    hi = [sig[s].get("high_speed", {}).get("nrmse") or 0 for _, sig in rows for s in sig]
    ax.barh(y - 0.2, lo, height=0.4, color="tab:orange", label="near zero speed")
    ax.barh(y + 0.2, hi, height=0.4, color="tab:blue", label="rest")
    ax.set_yticks(y, labels, fontsize=8)
    ax.invert_yaxis()
    _maybe_log(ax, lo + hi, "regime RMS error / std(measurement)")
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, axis="x")
    fig.suptitle("fit per log and signal; error near zero speed and elsewhere", fontsize=11)
    return _png(fig)


def before_after_figure(names: list[str], before: list[dict], after: list[dict]) -> bytes:
    """NRMSE per log and signal of the model without and with its added effects."""
    labels, b, a = [], [], []
    for name, rb, ra in zip(names, before, after, strict=True):
        for s in ra:
            labels.append(f"{mpl_text(name)} {s}")
            b.append(rb.get(s) or 0.0)
            a.append(ra.get(s) or 0.0)
    left = 0.3 + 0.065 * max((len(x) for x in labels), default=4)
    fig, axes = _new(1, 1, 1.6 + 0.3 * len(labels), left=left)
    ax = axes[0, 0]
    y = np.arange(len(labels))
    ax.barh(y - 0.2, b, height=0.4, color="0.6", label="before (no added effects)")
    ax.barh(y + 0.2, a, height=0.4, color="tab:green", label="after (with effects)")
    ax.set_yticks(y, labels, fontsize=8)
    ax.invert_yaxis()
    _maybe_log(ax, b + a, "NRMSE")
    ax.set_title("error without and with the added effects", fontsize=11)
    ax.legend(fontsize=8)
    ax.grid(alpha=0.3, axis="x")
    return _png(fig)
