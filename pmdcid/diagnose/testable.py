"""Can the held-out data test an effect at all, and do they confirm it?

A held-out gain is evidence for an effect only where the held-out data could have told the
effect from a change of the parameters the model already has. One step log split in time holds
out its steady tail: a sensor delay changes nothing there, and a quadratic drag or a friction
curve changes only the speed's level, which a new viscous or Coulomb friction changes as well.
Such a held-out "gain" says the effect re-balanced the base parameters, not that it exists.

The test, linearised at the candidate's refit (values ``fo``, effect switched on):

- ``d``: the effect's own change of the held-out residual (effect on minus effect off, the
  other parameters as refitted), weighted by the noise (each sample one unit of chi-square);
- ``B``: the held-out sensitivities of the free base parameters that can stand in for the
  effect (``Effect.interacts``: bv for a drag law, bc for a load torque, bc and bv for a speed
  bias; none for a delay, whose signature needs edges or reversals to show at all); for a
  direction asymmetry (``viscous_asymmetry``, ``torque_offset``) also the rest of the friction
  line, in the model or not (:func:`line_stand_ins`), unless the fit part tells the effect from
  it by the evidence any effect needs (:func:`fit_tells`);
- *distinct* = ``|P d|^2``, ``P`` projecting out the columns of ``B``: the chi-square by which
  the held-out data can tell the effect, at its fitted size, from any re-adjustment of the
  others. Below ``floor`` the effect is *not testable with these logs*.
- *confirmed* = ``|P r_off|^2 - |P r_on|^2`` (``r``: the held-out residuals with the effect off
  and on): how much of that distinct part the held-out data actually bear out. A real effect
  gives about *distinct*; a spurious one about zero or less. The rule asks for half.

Cost: one held-out simulation per free parameter and one with the effect off (for a direction
asymmetry, of the whole logs: the fit part's columns decide whether its twins stand in).

*Before any refit* (``pmdcid plan --check``: can these logs test the effect at all?),
:func:`logs_can_test` applies the same test at the model's values with the effect switched on
at its probe size: ``seen`` is the effect's change on the fit part that no free base parameter
absorbs (what a refit there could see), ``distinct`` the held-out part's that the parameters it
interacts with cannot. Both grow as the effect's size squared, and no effect can explain more
of the fit part than its whole chi-square (``room``): the largest effect these logs could
hold is told apart on the held-out data by ``distinct x room / seen``. Below the floor, no
effect diagnose could add on these logs could be tested. A necessary condition, linearised
at the model: whether the data bear a refitted effect out is diagnose's own test.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pmdcid.identify.nonlinear_setup import both_directions, rests_or_both_ways
from pmdcid.identify.offset import OFFSET_BIC
from pmdcid.model import EFFECTS
from pmdcid.runtime.cpus import pmap

#: relative step of a parameter's held-out sensitivity column
STEP = 0.05
#: share of the distinct part the held-out data must bear out
CONFIRM_SHARE = 0.5


@dataclass(frozen=True)
class HeldoutTest:
    """What the held-out data can say about one effect (chi-square units, noise-weighted)."""

    distinct: float  # chi-square that tells the effect from the other parameters
    confirmed: float  # part of it the held-out data bear out
    floor: float  # the least distinct chi-square that counts as a test
    one_way: bool = False  # a direction effect on logs that turn one way only (:func:`one_way`)

    @property
    def testable(self) -> bool:
        return self.distinct >= self.floor

    @property
    def confirms(self) -> bool:
        return self.confirmed >= max(CONFIRM_SHARE * self.distinct, self.floor)


@dataclass(frozen=True)
class LogsTest:
    """Whether logs could test an effect, before any refit (module doc; chi-square units at
    the probed size for ``seen`` and ``distinct``)."""

    seen: float  # fit part: the effect's change no free base parameter absorbs
    distinct: float  # held-out part: the change its interacting parameters cannot absorb
    room: float  # the fit part's chi-square: the most any effect could explain there
    floor: float  # the held-out distinct chi-square that counts as a test
    one_way: bool = False  # a direction effect on logs that turn one way only (:func:`one_way`)

    @property
    def largest(self) -> float:
        """The held-out distinct chi-square of the largest effect the fit part could hold (0
        when the fit part cannot see it at all)."""
        return self.distinct * self.room / self.seen if self.seen > 0 else 0.0

    @property
    def testable(self) -> bool:
        return self.largest >= self.floor


def heldout_floor(rules, n_held: int, chi2_held: float) -> float:
    """The least held-out distinct chi-square that counts as a test: ``min_z`` standard errors
    squared, or ``min_gain`` of the held-out chi-square (1 when nothing is held out)."""
    return max(rules.min_z ** 2, rules.min_gain * chi2_held) if n_held else 1.0


#: torques whose sensitivity step is at least a share of the torque scale
TORQUES = ("bc", "dz", "tau0", "fs")
#: that share: a friction fitted to its bound at 1e-17 would otherwise get a step of 5e-19,
#: a column of rounding that is dropped, and an effect it could absorb (a load torque beside
#: bc on a log turning one way) would look distinct from it
MIN_TORQUE = 0.01


def _step(name: str, values: dict[str, float], torque_scale: float) -> float:
    """The step of ``name``'s held-out sensitivity column: :data:`STEP` of its value, of at
    least :data:`MIN_TORQUE` of the torque scale for a torque and of the viscous friction for
    its direction-dependent part (0: no column)."""
    value = values.get(name, 0.0)
    if not math.isfinite(value):
        return 0.0
    if name in TORQUES:
        return STEP * max(abs(value), MIN_TORQUE * torque_scale)
    if name == "dbv" and math.isfinite(bv := values.get("bv", math.nan)):
        return STEP * max(abs(value), abs(bv))
    return STEP * abs(value)


def _steps(names, values: dict[str, float], torque_scale: float) -> list[tuple[str, float]]:
    """(name, step) of the parameters of ``names`` that get a column."""
    steps = [(p, _step(p, values, torque_scale)) for p in names]
    return [(p, h) for p, h in steps if h > 0]


#: the steady friction in each direction is a line in the speed: an intercept bc + tau0 and a
#: slope bv + dbv turning forward, bc - tau0 and bv - dbv backward (``torque_offset`` and
#: ``viscous_asymmetry`` are its two direction-dependent parts)
FRICTION_LINE = ("bc", "tau0", "bv", "dbv")
#: the parts of the line that differ by direction
DIRECTIONAL = ("tau0", "dbv")


def line_stand_ins(effect: str) -> list[str]:
    """The rest of the friction line, where ``effect`` sets a direction-dependent part of it
    (else none): what its change of the steady speeds must be told from, in the model or not.

    Per direction the line has an intercept and a slope. Where the data hold one steady speed
    per direction, an intercept of each direction (bc and tau0) takes up any change of the
    slopes there, and a slope of each (bv and dbv) any change of the intercepts: an offset is
    then not told from an asymmetric viscous friction, nor either of them from a drag law's
    curvature. Two speeds in one direction and one in the other leave the four still
    undetermined; a direction asymmetry is told apart only by two speeds in each direction, or
    by transients that sweep the speed (their time constants are the slopes)."""
    own = EFFECTS[effect].param_names
    if not set(own) & set(DIRECTIONAL):
        return []
    return [p for p in FRICTION_LINE if p not in own]


#: why a direction effect is not testable on logs that turn one way only (:func:`one_way`)
ONE_WAY = ("the logs turn one way only: there a direction-dependent friction is the friction "
           "line's own intercept and slope (bc, bv), and only motion in both directions tells "
           "it from them")


#: why a speed sensor's offset is not testable on logs that turn one way and never rest
ONE_WAY_UNRESTING = ("the logs turn one way only and never rest: there a speed sensor's offset "
                     "is a shift of the friction line (bc by bv' omega0 at a steady speed; "
                     "what is left of it lies in the transients), and only the rotor at rest "
                     "or turning the other way tells the two apart")
#: effects the friction line stands in for on logs that turn one way, unless they rest (a speed
#: sensor's offset is read as it is where the rotor stands still)
TOLD_AT_REST = ("speed_offset",)


def one_way(effect: str, logs) -> bool:
    """Whether ``effect`` sets a direction-dependent part of the friction line
    (:func:`line_stand_ins`: ``torque_offset``, ``viscous_asymmetry``) and ``logs`` never turn
    both ways (:func:`pmdcid.identify.nonlinear_setup.both_directions`: each direction at least
    1 % of the samples moving clearly, the rule fit-nonlinear fits tau0 by). Such logs cannot
    test it, held out or not: in one direction its change is exactly one of bc's or bv's, and
    what a linearised projection leaves of it is the two columns' curvature, not evidence
    (plan --check called viscous_asymmetry testable on a one-way staircase at 1684 chi-square
    against a floor of 81). A speed sensor's offset (:data:`TOLD_AT_REST`) likewise where the
    logs also never rest (:func:`~pmdcid.identify.nonlinear_setup.rests_or_both_ways`): at a
    steady speed it is bc's shift by bv' omega0, and what is left in the transients is what a
    lag or a delay the model folds leaves there too (bench/lawlag.py's hobby motor with a
    2-sample sensor delay, seed 2, 500 Hz, L/R 2 ms: an offset of 0.28 rad/s added on a step
    and a staircase that turn one way, the held-out step to negative speeds 0.0072 ->
    0.0111)."""
    if effect in TOLD_AT_REST:
        return not rests_or_both_ways(logs)
    return bool(line_stand_ins(effect)) and not both_directions(logs)


def why_one_way(effect: str) -> str:
    """The reason :func:`one_way` gives for ``effect``, in words."""
    return ONE_WAY_UNRESTING if effect in TOLD_AT_REST else ONE_WAY


def _project_out(b: np.ndarray | None, y: np.ndarray) -> np.ndarray:
    """``y`` minus its least-squares projection on the columns of ``b``."""
    if b is None or b.shape[1] == 0:
        return y
    coef, *_ = np.linalg.lstsq(b, y, rcond=None)
    return y - b @ coef


def heldout_test(problem, values: dict[str, float], effect: str, others: list[str],
                 torque_scale: float, floor: float, evidence: float = -OFFSET_BIC) -> HeldoutTest:
    """The held-out test of ``effect`` at ``values`` (its refit), the parameters ``others``
    free to re-adjust, and the rest of the friction line (:func:`line_stand_ins`) where the fit
    part cannot tell the effect from it by ``evidence`` (chi-square)."""
    if one_way(effect, problem.logs):
        return HeldoutTest(0.0, 0.0, floor, one_way=True)
    if problem.count("held") == 0:
        return HeldoutTest(0.0, 0.0, floor)
    off = {**values, **{p.name: p.neutral for p in EFFECTS[effect].params
                        if p.name not in EFFECTS[effect].held}}
    twins = [p for p in line_stand_ins(effect) if p not in others]
    parts = ("fit", "held") if twins else ("held",)

    def resid(v: dict[str, float]) -> dict[str, np.ndarray]:
        sims = problem.simulate_all(v, "all" if twins else "held")
        return {part: problem.weighted(sims, part) for part in parts}

    r_on, r_off = resid(values), resid(off)
    steps = _steps([*others, *twins], values, torque_scale)
    cols = dict(zip([p for p, _ in steps], pmap(
        lambda ph: resid({**values, ph[0]: values[ph[0]] + ph[1]}), steps), strict=True))
    if twins and fit_tells(r_on["fit"] - r_off["fit"], [c["fit"] - r_on["fit"]
                                                       for c in cols.values()], evidence):
        cols = {p: c for p, c in cols.items() if p not in twins}
    held = [c["held"] - r_on["held"] for c in cols.values()]
    held = [c for c in held if np.all(np.isfinite(c)) and np.any(c)]
    b = np.column_stack(held) if held else None
    d = r_on["held"] - r_off["held"]
    if not np.all(np.isfinite(d)):
        return HeldoutTest(0.0, 0.0, floor)
    pd = _project_out(b, d)
    distinct = float(pd @ pd)
    p_off, p_on = _project_out(b, r_off["held"]), _project_out(b, r_on["held"])
    confirmed = float(p_off @ p_off - p_on @ p_on)
    return HeldoutTest(distinct, confirmed, floor)


def fit_tells(d_fit: np.ndarray, cols: list[np.ndarray], evidence: float,
              scale: float = 1.0) -> bool:
    """Whether the fit part tells an effect (its change ``d_fit``, the chi-square times
    ``scale``) from the re-adjustments of ``cols`` by at least ``evidence`` chi-square: the
    evidence diagnose asks of any effect (:data:`~pmdcid.identify.offset.OFFSET_BIC`), here of
    the effect against its twins, which have as many parameters. Where it does, the fit part
    has chosen between them and the twins do not stand in on the held-out data; where it does
    not, neither part can tell them apart."""
    return len(d_fit) > 0 and _distinct(d_fit, cols) * scale >= evidence


#: a projected change below this share of the change is the projection's rounding: an effect
#: the columns absorb exactly (a load torque beside bc in one direction)
ROUNDING = 1e-8


def _distinct(d: np.ndarray, cols: list[np.ndarray]) -> float:
    """|P d|^2, ``P`` projecting out ``cols`` (0 where only rounding is left)."""
    cols = [c for c in cols if np.all(np.isfinite(c)) and np.any(c)]
    if not np.all(np.isfinite(d)):
        return 0.0
    pd = _project_out(np.column_stack(cols) if cols else None, d)
    left = float(pd @ pd)
    return left if left > ROUNDING * float(d @ d) else 0.0


def logs_can_test(problem, values: dict[str, float], probes: dict[str, dict[str, float]],
                  base_free: list[str], torque_scale: float, rules) -> dict[str, LogsTest]:
    """For each effect of ``probes`` (effect -> its parameters at a probe size), whether the
    held-out data of ``problem`` could test it before any refit (module doc), at the model's
    ``values`` with ``base_free`` the parameters every refit moves and ``rules`` diagnose's."""
    n_held = problem.count("held")
    sims = problem.simulate_all(values)
    r0 = {p: problem.weighted(sims, p) for p in ("fit", "held")}
    floor = heldout_floor(rules, n_held, float(r0["held"] @ r0["held"]))
    chi2_fit = float(r0["fit"] @ r0["fit"])

    def change(v: dict[str, float]) -> dict[str, np.ndarray]:
        s = problem.simulate_all(v)
        return {p: problem.weighted(s, p) - r0[p] for p in ("fit", "held")}

    single = {e for e in probes if one_way(e, problem.logs)}
    lines = [p for e in probes if e not in single for p in line_stand_ins(e)]
    steps = _steps(dict.fromkeys([*base_free, *lines]), values, torque_scale)
    cols = dict(zip([p for p, _ in steps], pmap(
        lambda ph: change({**values, ph[0]: values[ph[0]] + ph[1]}), steps), strict=True))
    out = {}
    for effect, col in probes.items():
        if effect in single:
            out[effect] = LogsTest(0.0, 0.0, chi2_fit, floor, one_way=True)
            continue
        d = change({**values, **col})
        seen = _distinct(d["fit"], [c["fit"] for p, c in cols.items() if p in base_free])
        stand = _logs_stand_ins(effect, d["fit"], cols, base_free,
                                chi2_fit / seen if seen > 0 else 0.0, -rules.bic)
        distinct = _distinct(d["held"], [c["held"] for p, c in cols.items()
                                         if p in stand]) if n_held else 0.0
        out[effect] = LogsTest(seen, distinct, chi2_fit, floor)
    return out


def _logs_stand_ins(effect: str, d_fit: np.ndarray, cols: dict[str, dict[str, np.ndarray]],
                    base_free: list[str], scale: float, evidence: float) -> set[str]:
    """The parameters standing in for ``effect`` on the held-out part before any refit: those
    of ``base_free`` it interacts with, and the rest of the friction line unless the fit part
    could tell the largest effect it holds (its change ``d_fit`` at the probe, times ``scale``
    in chi-square) from them (:func:`fit_tells`)."""
    stand = set(EFFECTS[effect].interacts) & set(base_free)
    twins = [p for p in line_stand_ins(effect) if p not in stand]
    if twins and not fit_tells(d_fit, [c["fit"] for p, c in cols.items()
                                        if p in base_free or p in twins], evidence, scale):
        stand |= set(twins)
    return stand


__all__ = ["CONFIRM_SHARE", "FRICTION_LINE", "ONE_WAY", "HeldoutTest", "LogsTest",
           "heldout_floor", "heldout_test", "line_stand_ins", "logs_can_test", "one_way",
           "why_one_way"]
