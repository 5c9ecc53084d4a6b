"""What a plan would tell about each catalogue effect the model does not have yet.

For each effect of :data:`pmdcid.model.effects.EFFECTS`, its main parameter is switched on at a
small stated size (the size diagnose probes it with: a few percent of the typical friction
torque, speed or voltage, one sample of delay) and its predicted standard error computed jointly
with the identified parameters, from the same sensitivities (the base parameters' columns are
taken at the model, the effect being small).
"""

from __future__ import annotations

import math

import numpy as np

from pmdcid.model import EFFECTS, Model
from pmdcid.model.effects.probes import PROBE
from pmdcid.model.residual import LogResidual, Probe, ResidualContext
from pmdcid.plan import fisher as fi

#: cogging order assumed when no residual gives one [periods per revolution]
COGGING_ORDER = 8.0


def plan_context(profiles, vals, drive: fi.Drive) -> ResidualContext:
    """The scales diagnose would see on the plan's simulated profiles (no residual)."""
    logs, speeds = [], []
    for p in profiles:
        sim = fi.simulate_profile(p.t, p.u, vals, drive, p.blocked)
        logs.append(LogResidual(p.t, p.u, drive.torque_path, p.blocked,
                                None if p.blocked else sim.omega,
                                None if p.blocked else sim.theta, sim.omega_true, {}))
        if not p.blocked:
            speeds.append(np.abs(sim.omega))
    speed = float(np.percentile(np.concatenate(speeds), 95)) if speeds else 1.0
    speed = speed if speed > 0 else 1.0
    bv, bc, dz = (max(vals.get(n, 0.0), 0.0) for n in ("bv", "bc", "dz"))
    torque = max(bc + bv * speed, dz, 1e-12)
    volts = max(float(np.max(np.abs(p.u))) for p in profiles)
    return ResidualContext(dict(vals), logs, torque, speed, volts if drive.column == "v" else 0.0,
                           min(float(p.t[1] - p.t[0]) for p in profiles))


def probe_of(effect, ctx: ResidualContext) -> dict[str, float] | None:
    """The effect's first probe column (its parameters at a small size), or a fallback."""
    probes: list[Probe] = effect.signature(ctx) if effect.signature else []
    if probes:
        return dict(probes[0].columns[0])
    if effect.name == "cogging":
        return {"ca": PROBE * ctx.torque_scale, "cn": COGGING_ORDER, "cphi": 0.0}
    return None


def extra_column(profiles, vals, name, drive, scales, sigs) -> list[dict[str, np.ndarray]]:
    """Sensitivity of each profile's signals to one more parameter."""
    out = []
    for p, s in zip(profiles, sigs, strict=True):
        out.append(fi.sensitivities(p.t, p.u, vals, [name], drive, p.blocked, scales,
                                    tuple(s)))
    return out


def joint_stderr(F, sens, extra, noise) -> float:
    """Standard error of the extra parameter with the base information ``F`` bordered."""
    p = F.shape[0]
    G = np.zeros((p + 1, p + 1))
    G[:p, :p] = F
    for S, d in zip(sens, extra, strict=True):
        for s, col in d.items():
            w = 1.0 / noise[s] ** 2
            G[:p, p] += S[s].T @ col[:, 0] * w
            G[p, p] += float(col[:, 0] @ col[:, 0]) * w
    G[p, :p] = G[:p, p]
    return float(fi.stderr(G)[-1])


def effect_table(profiles, sens, F, vals, names, drive: fi.Drive, noise, scales,
                 model: Model) -> list[dict]:
    """One row per catalogue effect: parameter, size, predicted stderr, and a note."""
    ctx = plan_context(profiles, vals, drive)
    rows = []
    for eff in EFFECTS.values():
        main = eff.params[0]
        row = {"effect": eff.name, "parameter": main.name, "unit": main.unit,
               "size": math.nan, "stderr": math.nan, "note": ""}
        rows.append(row)
        if eff.name in model.effects:
            row.update(size=vals[main.name], note="in the model")
            if main.name in names:
                row["stderr"] = float(fi.stderr(F)[names.index(main.name)])
            continue
        if drive.torque_path and eff.acts_on in ("electrical", "input"):
            row["note"] = "not applicable: the input is a torque (or a lumped per-volt model)"
            continue
        col = probe_of(eff, ctx)
        if col is None:
            row["note"] = "no probe at this plan's scales"
            continue
        v2 = {**vals, **col}
        extra = extra_column(profiles, v2, main.name, drive, scales, [s.keys() for s in sens])
        row.update(size=col[main.name], stderr=joint_stderr(F, sens, extra, noise))
        held = {k: v for k, v in col.items() if k != main.name}
        if held:
            row["note"] = "with " + ", ".join(f"{k} = {v:.3g}" for k, v in held.items())
    return rows


__all__ = ["effect_table", "joint_stderr", "plan_context", "probe_of"]
