"""The paper's protocol through the same Fisher machinery as a plan, for comparison.

The protocol of Pérez-Gómez et al. (the bundled ``fixtures/paper`` logs, :func:`pmdcid.synth.
paper_protocols`): five blocked-rotor current steps 0.5..2.5 V (0.3 s at 5 kHz), five free
speed steps 0.5..2.5 V (3 s at 1 kHz) and a +-2 V triangle of period 40 s for 120 s; 136.5 s in
all.
"""

from __future__ import annotations

import numpy as np

from pmdcid.model import Model
from pmdcid.plan import fisher as fi
from pmdcid.plan.design import parameter_scales

AMPLITUDES = (0.5, 1.0, 1.5, 2.0, 2.5)


def paper_profiles() -> list[tuple[np.ndarray, np.ndarray, bool]]:
    """(t [s], v [V], blocked) of each log of the paper's protocol."""
    from pmdcid.synth import step, triangle

    out = []
    tb = np.arange(1500) / 5000.0
    out += [(tb, step(tb, a, 0.05), True) for a in AMPLITUDES]
    ts = np.arange(3000) / 1000.0
    out += [(ts, step(ts, a, 0.5), False) for a in AMPLITUDES]
    tt = np.arange(120000) / 1000.0
    out.append((tt, triangle(tt, 2.0, 40.0), False))
    return out


def protocol_seconds(profiles) -> float:
    return float(sum(len(t) * (t[1] - t[0]) for t, _, _ in profiles))


def protocol_stderr(model: Model, profiles, noise: dict[str, float]) -> dict[str, float]:
    """Predicted standard errors [SI] of the identified parameters from logs of ``profiles``,
    stage by stage as identify fits them (:func:`~pmdcid.plan.fisher.staged_stderr`)."""
    drive = fi.drive_of(model)
    vals = fi.model_values(model, drive)
    names = fi.identified(model, drive)
    scales = parameter_scales(vals, drive, 1.0)
    sens = [fi.sensitivities(t, u, vals, names, drive, blocked, scales)
            for t, u, blocked in profiles]
    se = fi.staged_stderr(sens, [b for _, _, b in profiles], names, noise)
    return dict(zip(names, se.tolist(), strict=True))


__all__ = ["paper_profiles", "protocol_seconds", "protocol_stderr"]
