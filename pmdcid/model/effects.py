"""The effect catalogue: named, composable physical effects the paper's model lacks.

Each :class:`Effect` declares its parameters (name, unit, neutral value, bounds), where it acts
(``electrical``, ``mechanical`` or ``sensor``), the base parameters it interacts with (refitted
together when diagnose adds it), and a docstring with its physics and its residual signature.
The simulation kernel evaluates every effect's term from the flat parameter vector; an effect that
is not listed in a model's ``effects`` has its parameters held at their neutral values, so it is
exactly off.

Each effect also carries its ``signature`` and ``guess`` functions (:mod:`pmdcid.model.signatures`)
used by diagnose to screen the residual and start the refit.

Adding an effect: add its :class:`Effect` entry below and its term in
:mod:`pmdcid.simulate.terms` (electrical or mechanical), or in
:func:`pmdcid.simulate.sensors.apply_sensors` for a sensor effect. See docs/effects.md.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

from pmdcid.errors import ModelError
from pmdcid.model import signatures as sg
from pmdcid.model import sizes
from pmdcid.model.spec import BASE_PARAMS, ParamSpec


@dataclass(frozen=True)
class Effect:
    """One catalogue effect."""

    name: str
    doc: str
    params: tuple[ParamSpec, ...]
    acts_on: str  # "electrical" | "mechanical" | "sensor" | "input"
    #: the base parameters it interacts with: refitted with it, and those that can stand in
    #: for it where the data hold only part of what it acts on (one speed level cannot tell a
    #: drag law from bv): :mod:`pmdcid.diagnose.testable` projects them out of its held-out
    #: signature
    interacts: tuple[str, ...] = ()
    #: optional hooks filled in by the diagnose stage: residual signature and starting guess
    hooks: dict[str, Callable] = field(default_factory=dict, compare=False, hash=False)
    #: ``signature(ctx) -> list[Probe]``: small parameter settings switching the effect on, whose
    #: simulated change is the effect's signature in the residual (see model/signatures.py)
    signature: Callable | None = field(default=None, compare=False, hash=False)
    #: ``guess(probe, coefs, ctx) -> dict | None``: starting values from the residual's regression
    #: coefficients on the probe's columns (None: the residual does not point at this effect)
    guess: Callable | None = field(default=None, compare=False, hash=False)
    #: parameters set by the guess and held when refitting (integers such as a cogging order)
    held: tuple[str, ...] = ()
    #: optional ``limits(ctx) -> {param: (lower, upper)}``: tighter refit bounds from the data's
    #: scales, where a parameter outside them makes the effect indistinguishable from another
    limits: Callable | None = field(default=None, compare=False, hash=False)
    #: signals some log must measure by its own sensor (not derived from another) for the
    #: effect to mean anything (a speed-sensor bias needs a speed sensor)
    requires: tuple[str, ...] = ()
    #: parameters whose largest distance from neutral, in standard errors, is the effect's size
    #: (default: its first parameter)
    size_params: tuple[str, ...] = ()
    #: kernel states the effect owns (:data:`pmdcid.simulate.layout.STATE_OWNERS`), integrated
    #: only while it is on
    states: tuple[str, ...] = ()
    #: screened by ``pmdcid diagnose`` unless ``--effect`` names the effects to search
    screened: bool = True
    #: what to record so that held-out data can test the effect (said when the logs given
    #: cannot: :mod:`pmdcid.diagnose.testable`)
    record: str = ""
    #: optional ``implausible(values, ctx, start) -> str | None``: why a refitted size is not
    #: physical for these logs (a delay of many samples, a sensor bias the size of the speed)
    implausible: Callable | None = field(default=None, compare=False, hash=False)

    @property
    def param_names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.params)


EFFECTS: dict[str, Effect] = {}


def register(effect: Effect) -> Effect:
    """Add an effect to the catalogue (names are unique)."""
    if effect.name in EFFECTS:
        raise ValueError(f"effect {effect.name!r} registered twice")
    EFFECTS[effect.name] = effect
    return effect


def get_effect(name: str) -> Effect:
    try:
        return EFFECTS[name]
    except KeyError:
        raise ModelError(f"unknown effect '{name}' (known: {', '.join(EFFECTS)})") from None


def effect_param_specs() -> dict[str, ParamSpec]:
    """Every effect parameter by name."""
    return {p.name: p for e in EFFECTS.values() for p in e.params}


def param_spec(name: str) -> ParamSpec | None:
    """The declaration of any parameter, base or effect (None for an unknown name): the one
    look-up of units, bounds and neutral values."""
    return BASE_PARAMS.get(name) or effect_param_specs().get(name)


def unit_of(name: str) -> str:
    """The unit of any parameter ('' for an unknown name)."""
    spec = param_spec(name)
    return spec.unit if spec else ""


def bounds_of(name: str) -> tuple[float, float]:
    """(lower, upper) bounds of any parameter (unbounded for an unknown name)."""
    spec = param_spec(name)
    return (spec.lower, spec.upper) if spec else (-math.inf, math.inf)


register(Effect(
    "back_emf",
    "Counter-EMF: the armature equation gains -ke*omega, L di/dt = v - R i - ke omega. "
    "In SI units ke = km. Signature: under load the current falls as the speed rises; "
    "steady-state speed saturates below v*km/(R*bv); current residual correlates with -omega.",
    (ParamSpec("ke", "V s/rad", "back-EMF constant", 0.0, 0.0, 1e3),),
    "electrical",
    ("bv", "J"),
    **sg.linear("ke", sg.back_emf_probe),
    record='currents logged at several speeds (steps to different voltages)',
))
register(Effect(
    "stribeck",
    "Static friction above the Coulomb level that falls off with speed: friction gains "
    "fs*exp(-(omega/ws)^2)*sign(omega); breakaway torque bc + fs. Signature: late breakaway and "
    "a speed deficit concentrated at low |omega|, vanishing at high speed.",
    (ParamSpec("fs", "N m", "static friction above Coulomb", 0.0, 0.0, 1e6),
     ParamSpec("ws", "rad/s", "Stribeck speed", 1.0, 1e-6, 1e6)),
    "mechanical",
    ("bc", "dz"),
    signature=sg.stribeck_signature,
    guess=sg.stribeck_guess,
    limits=sg.stribeck_limits,
    record='slow reversals or breakaways from rest in a log of their own (a slow triangle)',
))
register(Effect(
    "quadratic_drag",
    "Friction growing with speed squared: friction gains bq*omega*|omega| (windage, lubricant); "
    "bq < 0 is friction flattening with speed, bounded so that the total friction stays "
    "positive over the logged speeds. Signature: speed residual proportional to "
    "-omega*|omega|; high speeds over-predicted (bq > 0) or under-predicted (bq < 0).",
    (ParamSpec("bq", "N m s^2/rad^2", "quadratic drag coefficient (negative: friction "
               "flattening with speed)", 0.0, -1e6, 1e6),),
    "mechanical",
    ("bv",),
    **sg.linear("bq", sg.quadratic_probe, positive=False),
    limits=sg.quadratic_drag_limits,
    record=('steady speeds spanning the range, in logs of their own (a staircase of levels or '
            'steps to several voltages)'),
))
register(Effect(
    "torque_offset",
    "Constant load torque tau0 opposing positive motion (gravity, spring preload) - equivalent to "
    "direction-asymmetric Coulomb friction bc+tau0 forward, bc-tau0 backward. Signature: "
    "speed residual of one sign in both directions; drift at rest if |tau0| > bc.",
    (ParamSpec("tau0", "N m", "constant load torque", 0.0, -1e6, 1e6),),
    "mechanical",
    ("bc",),
    **sg.linear("tau0", sg.torque_probe, positive=False),
    record='motion in both directions (steps of both signs, a triangle through zero)',
))
register(Effect(
    "cogging",
    "Cogging torque periodic in rotor angle: -ca*sin(cn*theta + cphi), cn periods per revolution "
    "(an integer, slots x poles). Signature: residual periodic in theta, line at cn in the angle "
    "spectrum; speed ripple at cn*omega/(2 pi) Hz.",
    (ParamSpec("ca", "N m", "cogging torque amplitude", 0.0, 0.0, 1e6),
     ParamSpec("cn", "1/rev", "cogging periods per revolution", 0.0, 0.0, 1000.0),
     ParamSpec("cphi", "rad", "cogging phase", 0.0, -2 * math.pi, 2 * math.pi)),
    "mechanical",
    (),
    signature=sg.cogging_signature,
    guess=sg.cogging_guess,
    held=("cn",),
    record='slow, steady runs over several revolutions',
))
register(Effect(
    "sensor_delay",
    "Speed and angle measured late by delay seconds (filtering, communication). Signature: "
    "residual is the derivative of the signal times -delay; cross-correlation peak at a lag > 0.",
    (ParamSpec("delay", "s", "measurement delay of speed and angle", 0.0, 0.0, 10.0),),
    "sensor",
    (),
    **sg.linear("delay", sg.delay_probe),
    record='input edges or reversals in logs of their own (steps at other levels, a square wave)',
    implausible=sizes.delay_too_long,
))
register(Effect(
    "speed_offset",
    "Constant bias on the speed sensor: omega_meas = omega + omega0. Signature: constant speed "
    "residual, visible at rest; angle unaffected.",
    (ParamSpec("omega0", "rad/s", "speed sensor bias", 0.0, -1e6, 1e6),),
    "sensor",
    ("bc", "bv"),
    **sg.linear("omega0", sg.speed_probe, positive=False),
    requires=("omega",),
    record='rest and motion in both directions (steps of both signs, rest recorded before each)',
    implausible=sizes.speed_bias_too_large,
))
register(Effect(
    "voltage_saturation",
    "The drive clips the applied voltage to +-vmax. Signature: speed residual only where |v| is "
    "large, flat-topped speed peaks.",
    (ParamSpec("vmax", "V", "drive voltage limit", math.inf, 1e-6, math.inf),),
    "input",
    (),
    signature=sg.saturation_signature,
    guess=sg.saturation_guess,
    record="inputs near and below the drive's limit in separate logs",
))
register(Effect(
    "brush_drop",
    "Constant voltage drop vb across the brushes, opposing the driving voltage: no current "
    "flows until |v - ke omega| exceeds vb. Signature: steady current vs voltage is affine with "
    "a dead band; later breakaway at small voltages.",
    (ParamSpec("vb", "V", "brush voltage drop", 0.0, 0.0, 1e3),),
    "electrical",
    ("R",),
    **sg.linear("vb", sg.voltage_probe),
    record='currents at several small voltages (blocked-rotor steps at several levels)',
    implausible=sizes.moves_resistance,
))


register(Effect(
    "viscous_asymmetry",
    "Viscous friction that depends on the direction of motion: friction gains dbv*|omega|, i.e. "
    "bv + dbv moving forward and bv - dbv backward (a worn or unevenly preloaded screw, seals "
    "that drag more one way). Signature: speed residual of one sign in both directions that "
    "grows with |omega| (a torque offset's residual does not grow with speed); plateau speeds "
    "differ between directions by more than Coulomb friction explains.",
    (ParamSpec("dbv", "N m s/rad", "direction-dependent part of the viscous friction", 0.0,
               -1e6, 1e6),),
    "mechanical",
    ("bv", "tau0"),
    **sg.linear("dbv", sg.viscous_probe, positive=False),
    limits=sg.viscous_asymmetry_limits,
    record='steady speeds in both directions at several levels',
))


#: friction_curve's parameters: knot speeds fcw1..fcw4 [rad/s] (placed by the logged speeds and
#: held) and the friction added at the first three fc1..fc3 [N m] (0 at the last)
CURVE_SPEEDS = tuple(f"fcw{k}" for k in range(1, 5))
CURVE_VALUES = tuple(f"fc{k}" for k in range(1, 4))

register(Effect(
    "friction_curve",
    "Speed-dependent friction that follows no named law: friction gains sign(omega)*c(|omega|), "
    "c piecewise linear through (0, 0), (fcw_k, fc_k) for k = 1..3 and (fcw4, 0), zero beyond "
    "fcw4 (the paper's bc + bv*|omega| continues past the logged speeds). The knot speeds are "
    "0.15, 0.4, 0.7 and 1 times the top logged |omega| (its 99.9 % quantile while moving), "
    "written in the model file and held; the knot values are fitted, each at least -0.9 times "
    "bc + bv*fcw_k so the total friction stays positive over the logged speeds. Zero at "
    "omega = 0 (breakaway unchanged), the same in both directions. Signature: a speed residual "
    "that is a smooth function of |omega| (e.g. friction rising then flattening: the speed per "
    "unit torque grows with speed) which quadratic drag, Stribeck or viscous asymmetry do not "
    "follow. diagnose prefers those named laws when they explain the residual about as well.",
    tuple(ParamSpec(n, "rad/s", f"friction curve knot speed {n[-1]} (from the logged speeds)",
                    0.0, 0.0, 1e6) for n in CURVE_SPEEDS)
    + tuple(ParamSpec(n, "N m", f"friction added at knot speed fcw{n[-1]}", 0.0, -1e6, 1e6)
            for n in CURVE_VALUES),
    "mechanical",
    ("bv", "bc"),
    signature=sg.friction_curve_signature,
    guess=sg.friction_curve_guess,
    held=CURVE_SPEEDS,
    limits=sg.friction_curve_limits,
    size_params=CURVE_VALUES,
    record='steady speeds spanning the range, in logs of their own (a staircase of levels)',
))

register(Effect(
    "input_delay",
    "The drive applies the command latency seconds late (a host-paced loop: the USB or serial "
    "round trip, a PWM duty taken at the next period): every state, the current included, "
    "follows the input late (sensor_delay: the outputs read late, the current on time). "
    "Signature: current and speed residuals = -latency x their derivatives after every input "
    "change. Only searched when some log measures the current: on voltage and speed alone a "
    "system started at rest cannot tell an input applied late from outputs read late, and "
    "sensor_delay stands for both.",
    (ParamSpec("latency", "s", "delay between the logged command and the applied input", 0.0,
               0.0, 10.0),),
    "input",
    (),
    **sg.linear("latency", sg.delay_probe),
    requires=("i",),
    record='input edges in logs of their own, with the current logged',
))

register(Effect(
    "lugre",
    "LuGre dynamic friction: bristles of deflection z (a kernel state) replace the stick-slip "
    "logic. dz/dt = omega - sigma0*|omega|*z/g(omega), g = bc + fs*exp(-(omega/ws)^2) (the "
    "Coulomb/Stribeck level, from the model's bc and stribeck); friction sigma0*z + sigma1*dz/dt "
    "+ bv*omega (+ quadratic drag, viscous asymmetry). Below breakaway the rotor springs back: "
    "a presliding angle of about torque/sigma0, with hysteresis on a reversal; at constant speed "
    "the static curve g(omega) sign(omega) + bv*omega. Signature: angle creeping under torques "
    "below breakaway (needs an angle sampled well above sqrt(sigma0/J)/(2 pi) Hz and resolved "
    "below bc/sigma0); smooth, not stepped, breakaway. Not screened by default (--effect lugre).",
    (ParamSpec("sigma0", "N m/rad", "bristle stiffness (presliding spring)", 0.0, 0.0, 1e12),
     ParamSpec("sigma1", "N m s/rad", "bristle micro-damping", 0.0, 0.0, 1e9)),
    "mechanical",
    ("bc",),
    signature=sg.lugre_signature,
    guess=sg.lugre_guess,
    states=("z",),
    screened=False,
    record='slow reversals with the angle resolved well below bc/sigma0',
))
