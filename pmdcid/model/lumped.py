"""Lumped (per-volt) models: voltage and speed logged, no current sensor and no datasheet.

From v -> omega alone only ratios are identifiable. Divided by km/R, the motor
``L i' = v - R i - ke w``, ``J w' = DZ(km i) - bv w - f(w)`` becomes, with ``x = R i`` [V]:

    tau_e x' = v - x - ke w,     J' w' = DZ'(x) - bv'' w - f'(w)
    tau_e = L/R [s], J' = J R/km [V s^2/rad], bv'' = bv R/km, ke [V s/rad],
    bc', dz', tau0' = (R/km) x torque [V]

which is the kernel's own voltage-driven structure with R = km = 1 and L = tau_e
(:func:`kernel_values`): the dead zone acts on the torque, per volt on v - ke w lagged by
tau_e, where the physics puts it. The model file keeps the per-volt damping as one number,
``bv = bv'' + ke`` [V s/rad] (the steady state sees only the sum), and the back-EMF's share of
it, ``ke_share = ke/bv`` (the split is weak in the dynamics: the characteristic polynomial is
``tau_e J' s^2 + (J' + tau_e bv'') s + bv``; where the dead zone acts pins it, docs/model.md).
A lumped model file says ``"lumped": true`` and carries these parameters with their per-volt
units; every command that reads a model accepts it. :func:`to_si` converts it when km and R are
known.

A lumped model without tau_e (older files, or logs whose sampling does not resolve the lag) is
``tau_e = 0``: the kernel's torque-driven equation ``J' w' = DZ(v) - bv w - f'(w)`` with the
voltage as input, the dead zone on the applied voltage and the lag folded into J (J' about
J R/km + (L/R) bv: 7.7 % on the paper's motor).
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from pmdcid.errors import ModelError
from pmdcid.model.effects import unit_of, within_range

if TYPE_CHECKING:  # annotations only: Model.to_si calls to_si here
    from pmdcid.model.params import Model

KEY = "lumped"
NOTE = ("per-volt parameters (voltage and speed only: no current, no datasheet): "
        "J = J_SI R/km [V s^2/rad], bv = bv_SI R/km + ke [V s/rad], bc, dz, tau0 = R/km x "
        "torque [V]; tau_e = L/R [s], the electrical lag (without it, folded into J: about "
        "(L/R) bv more), ke_share = ke/bv (the back-EMF's share of bv; the dead zone acts on "
        "the torque, per volt on v - ke omega lagged by tau_e); give km and R "
        "(fit-electrical, --km) to convert to SI")
#: parameters that have no meaning in a lumped model (the electrical side is folded in)
ELECTRICAL = ("R", "L", "km", "ke")
#: a lumped model's own electrical side: the time constant L/R [s] and the back-EMF's share of
#: bv; mapped onto the kernel's R, L, km, ke, bv by :func:`kernel_values` (no kernel slots)
LUMPED_ONLY = ("tau_e", "ke_share")


#: internal steps per electrical time constant of a lumped model (:func:`lag_substeps`)
LAG_STEPS = 32.0
#: at most this many per sample: a lag far below the sample period hardly shows in the speed
MAX_LAG_SUBSTEPS = 64


def lag_substeps(dt: float, tau_e: float) -> int:
    """Internal steps per sample for a lumped model with lag ``tau_e`` [s]: h <= tau_e /
    :data:`LAG_STEPS`. The linear dynamics are exact at any step, but the dead zone's mode is
    taken at each step's start while the torque (per volt, the lagged v - ke w) moves on the
    scale of tau_e: a coarser step puts its events (and the fit's cost) on a staircase (measured
    on bench/lumped_coverage.py's seed 4: bumps of 5 chi-square units at tau_e/8, of about 1 at
    tau_e/32), which stops the local fits and makes their Jacobian claim more than the cost's
    rise. At most :data:`MAX_LAG_SUBSTEPS` a sample."""
    if not tau_e > 0.0:  # no lag (an instant current): the mechanics' own steps suffice
        return 1
    return max(1, min(int(math.ceil(dt * LAG_STEPS / tau_e - 1e-9)), MAX_LAG_SUBSTEPS))


def kernel_values(vals: dict[str, float], torque_driven: bool) -> tuple[dict[str, float], bool]:
    """The kernel's view of a lumped model's values: (values, torque_driven).

    A lumped model with an electrical time constant ``tau_e`` > 0, simulated on a voltage log
    (the log's view is torque-driven, :func:`pmdcid.simulate.logs_for`), runs the kernel's own
    voltage-driven structure scaled per volt: R = 1 and km = 1 (the "current" is R i, in V),
    L = tau_e (0 where the model has a back-EMF share but no lag: the current follows
    v - ke w at once, :func:`pmdcid.simulate.terms.instant_current`; a lumped model without
    a share has ``ke_share`` NaN here, :func:`pmdcid.simulate.param_values`), the back-EMF
    ke = ke_share bv and the mechanical viscous friction
    (1 - ke_share) bv, so that ``tau_e (R i)' = v - R i - ke w`` and
    ``J' w' = DZ(R i) - (1 - ke_share) bv w - f'(w)``: the dead zone acts on the torque, per
    volt on ``v - ke w`` lagged by tau_e, where the physics puts it. Anything else (SI models,
    torque logs, a lumped model with neither a lag nor a share: tau_e = 0, the dead zone on
    v) is returned as it is.
    """
    tau_e = float(vals.get("tau_e", 0.0) or 0.0)
    share = float(vals.get("ke_share", math.nan))
    if not (torque_driven and (tau_e > 0.0 or math.isfinite(share))):
        return vals, torque_driven
    share = min(max(share, 0.0), 1.0) if math.isfinite(share) else 1.0
    bv = float(vals["bv"])
    out = dict(vals)
    out.update(R=1.0, km=1.0, L=max(tau_e, 0.0), ke=share * bv, bv=(1.0 - share) * bv)
    return out, False


def same_response(J: float, tau_e: float, bv: float, share: float,
                  new_share: float) -> tuple[float, float] | None:
    """(J [V s^2/rad], tau_e [s]) with which a lumped model of back-EMF share ``new_share``
    answers the voltage exactly as one with ``J``, ``tau_e``, ``bv`` [V s/rad] and ``share``
    does, while the rotor moves freely: None when no such pair exists.

    Linear, v -> omega is ``1 / (tau_e J s^2 + (J + tau_e (1 - share) bv) s + bv)``: three
    coefficients for four parameters, so the share moves along a valley of equal linear
    response, only the friction and the dead zone (on the lagged torque) telling its points
    apart. Keeping ``a1 = tau_e J`` and ``a2 = J + tau_e (1 - share) bv``, J is the mechanical
    (larger) root of ``J^2 - a2 J + a1 (1 - new_share) bv = 0`` and tau_e = a1 / J. Without a
    lag (tau_e = 0, the current instant) the response ``1 / (J s + bv)`` holds no share: J
    stays, tau_e stays 0."""
    a1 = tau_e * J
    a2 = J + tau_e * (1.0 - share) * bv
    disc = a2 * a2 - 4.0 * a1 * (1.0 - new_share) * bv
    if not (a1 >= 0 and J > 0 and disc >= 0):
        return None
    j = 0.5 * (a2 + math.sqrt(disc))
    return j, a1 / j


def is_lumped(model: Model) -> bool:
    """True for a per-volt model (``"lumped": true`` in the model file)."""
    return bool(model.extra.get(KEY, False))


def lumped_unit(si_unit: str) -> str:
    """The per-volt unit of a parameter whose SI unit is ``si_unit`` (torque -> V,
    inertia -> V s^2/rad)."""
    return si_unit.replace("kg m^2", "V s^2/rad").replace("N m", "V")


def mark_lumped(model: Model) -> None:
    """Make ``model`` a lumped model: flag, note, and per-volt units on its parameters."""
    model.extra[KEY] = True
    model.extra["lumped_note"] = NOTE
    for name, par in model.parameters.items():
        if name not in ELECTRICAL:  # R, L, km, ke (a datasheet km) keep their SI units
            par.unit = lumped_unit(unit_of(name) or par.unit)


def wants_lumped(logs, model: Model) -> bool:
    """Whether a stage on ``logs`` must work per volt: the model is lumped already, or the logs
    are voltage logs with no current anywhere and the model has no R (a datasheet km alone
    does not give SI units: the torque per volt is km/R)."""
    if is_lumped(model):
        return True
    volt = [lg for lg in logs if "v" in lg.data]
    if not volt or any("i" in lg.data for lg in logs):
        return False
    return not model.has("R")


def to_si(model: Model, km: float, R: float) -> Model:
    """An SI copy of a lumped model, given km [N m/A] and R [ohm].

    Torque-like parameters scale by km/R; J too; ``bv' = bv R/km + ke`` with ke = km (SI)
    gives ``bv = (bv' - km) km/R``, and the back-EMF becomes an explicit effect. A bv' smaller
    than km is impossible for that km and R (the motor would be faster than unloaded): refused.
    The lag tau_e becomes L = tau_e R (an L already in the model is kept; an instant current's
    tau_e = 0 in [0, bound] becomes L = 0 in [0, bound R], which SI simulates as instant too);
    ke_share is dropped (its back-EMF, ke_share bv', is the ideal motor's km: compare it with
    the km given).
    """
    if not (math.isfinite(km) and km > 0 and math.isfinite(R) and R > 0):
        raise ModelError("converting a lumped model needs positive km and R", model.path)
    g = km / R
    out = model.copy()
    out.extra.pop(KEY, None)
    out.extra.pop("lumped_note", None)
    for name, par in list(out.parameters.items()):
        if name in ELECTRICAL:
            continue
        unit = unit_of(name)
        if "N m" in unit or "kg m^2" in unit:
            par.value *= g
            par.stderr *= g
            if par.interval is not None:
                par.interval = within_range(name, par.interval[0] * g, par.interval[1] * g)
        par.unit = unit
    bv_name = "bv" if out.has("bv") else "b"
    if out.has(bv_name):
        par = out.parameters[bv_name]
        raw = model.parameters[bv_name].value
        if raw <= km:
            raise ModelError(f"the lumped {bv_name} = {raw:.4g} V s/rad is below km = {km:.4g}: "
                             "this km and R cannot produce the logged speeds", model.path)
        par.value = (raw - km) * g
    tau_e = out.parameters.pop("tau_e", None)  # the lag L/R: L = tau_e R
    out.parameters.pop("ke_share", None)  # the back-EMF's share: ke = km of an ideal motor here
    if tau_e is not None and tau_e.value > 0 and not out.has("L"):
        out.set("L", tau_e.value * R, tau_e.stderr * R, "H", stage="lumped->SI (L = tau_e R)",
                caveat=tau_e.caveat)
        if tau_e.interval is not None:
            out.parameters["L"].interval = within_range("L", tau_e.interval[0] * R,
                                                        tau_e.interval[1] * R)
    elif tau_e is not None and tau_e.interval is not None and not out.has("L"):
        # an instant current (identify/instant.py): L = 0, inside the bound the steps left
        out.set_bounded("L", 0.0, tau_e.interval[1] * R, 0.0, unit="H",
                        stage="lumped->SI (L = tau_e R)", caveat=tau_e.caveat)
    out.set("ke", km, stage="lumped->SI (ke = km)")
    out.add_effect("back_emf")
    out.set("km", km, stage="datasheet")
    if not out.has("R"):
        out.set("R", R, stage="given")
    return out
