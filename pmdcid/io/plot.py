"""Quick looks for a notebook: ``Log.plot()``, ``SimResult.plot()`` and a fit result's
``plot()`` (matplotlib).

One panel per signal sharing the time axis, the input (``v`` or ``tau``) on top; each returns
the matplotlib Figure (drawn with pyplot, so a notebook shows it and a script can ``show()``
or ``savefig`` it). The report's figures (pmdcid/report/figures.py) are the careful ones.
"""

from __future__ import annotations

import numpy as np

#: canonical column -> axis label (SI)
LABELS = {"v": "voltage [V]", "tau": "torque [N m]", "i": "current [A]",
          "omega": "speed [rad/s]", "theta": "angle [rad]"}
#: panel order: the input first, then what it drives
ORDER = ("v", "tau", "i", "omega", "theta")


def plot_columns(t, columns: dict[str, np.ndarray], title: str, styles: dict | None = None,
                 units: dict[str, str] | None = None):
    """One panel per column of ``columns`` (canonical names, :data:`ORDER`), against ``t`` [s].

    ``styles``: label -> ``{name: array}`` of further lines drawn on the same panels (e.g. the
    measurement beside a simulation); ``units``: column -> a note for its axis label."""
    import matplotlib.pyplot as plt

    names = [c for c in ORDER if c in columns]
    fig, axes = plt.subplots(len(names), 1, sharex=True, squeeze=False,
                             figsize=(9, 1.8 * len(names) + 0.6))
    for ax, name in zip(axes[:, 0], names, strict=True):
        main = dict(color="tab:blue", lw=1.0) if name in ("v", "tau") else dict(color="k", lw=1.0)
        ax.plot(t, columns[name], label=title if styles else None, **main)
        for k, (label, other) in enumerate((styles or {}).items()):
            if name in other:
                ax.plot(t, other[name], color=("tab:red", "tab:green")[k % 2], lw=1.4, alpha=0.8,
                        label=label)
        ax.set_ylabel(LABELS.get(name, name) + (units or {}).get(name, ""))
        ax.grid(alpha=0.3)
        if len(ax.lines) > 1:
            ax.legend(loc="upper right", fontsize=8)
    axes[-1, 0].set_xlabel("time [s]")
    axes[0, 0].set_title(title, fontsize=10)
    fig.tight_layout()
    return fig


#: at most this many logs drawn by :func:`plot_fit` (the report draws every log)
MAX_FIT_PANELS = 8


def plot_fit(rows: list[tuple], title: str, left: list[str] | None = None):
    """A fit at a glance, one panel per log: ``rows`` of (label, t [s], signal, measured,
    simulated), the measurement in black and the model in red, each panel titled by its label;
    logs beyond :data:`MAX_FIT_PANELS` and ``left`` (logs not drawn, with why) are named under
    the figure."""
    import matplotlib.pyplot as plt

    shown = rows[:MAX_FIT_PANELS]
    fig, axes = plt.subplots(max(len(shown), 1), 1, squeeze=False,
                             figsize=(9, 1.9 * max(len(shown), 1) + 0.8))
    for ax, (label, t, signal, meas, sim) in zip(axes[:, 0], shown, strict=False):
        ax.plot(t, meas, color="k", lw=1.0, label="measured")
        ax.plot(t, sim, color="tab:red", lw=1.2, alpha=0.85, label="model")
        ax.set_ylabel(LABELS.get(signal, signal))
        ax.set_title(label, fontsize=9)
        ax.grid(alpha=0.3)
        ax.legend(loc="upper right", fontsize=8)
    axes[-1, 0].set_xlabel("time [s]")
    fig.suptitle(title, fontsize=10)
    unshown = [r[0] for r in rows[MAX_FIT_PANELS:]] + list(left or [])
    if unshown:
        fig.text(0.01, 0.005, "not drawn: " + ", ".join(unshown)[:300], fontsize=7)
    fig.tight_layout()
    return fig


def describe(t: np.ndarray) -> str:
    """``12000 samples, 0-12 s at 1000 Hz`` for a repr."""
    n = len(t)
    if n < 2:
        return f"{n} sample(s)"
    dt = (t[-1] - t[0]) / (n - 1)
    rate = f" at {1.0 / dt:.4g} Hz" if dt > 0 else ""
    return f"{n} samples, {t[0]:.4g}-{t[-1]:.4g} s{rate}"


__all__ = ["LABELS", "MAX_FIT_PANELS", "ORDER", "describe", "plot_columns", "plot_fit"]
