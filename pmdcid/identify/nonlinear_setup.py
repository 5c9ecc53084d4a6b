"""What fit-nonlinear fits: the logs checked, the free parameters, the signals in the cost, and
the working model with its starting values (fit-mechanical's for voltage logs, inverse dynamics
for torque-driven ones). Split from :mod:`.nonlinear`, which runs the grid and the local stage.
"""

from __future__ import annotations

import math

import numpy as np

from pmdcid.errors import FitError, ModelError
from pmdcid.io.mapping import is_setpoint
from pmdcid.model import Model
from pmdcid.notes import Note

SIGNALS = ("omega", "theta")
#: free parameters fitted by default: voltage-driven and torque-driven logs
FREE_V = ("J", "bv", "bc", "dz")
FREE_TAU = ("J", "bv", "bc", "tau0")
#: a lumped model's electrical time constant and the back-EMF's share of its bv
#: (pmdcid/model/lumped.py): fitted with the others when the model has a tau_e
LUMPED_FREE = ("tau_e", "ke_share")
KNOWN_FREE = ("J", "bv", "bc", "dz", "tau0", *LUMPED_FREE)
#: fewest samples per log
MIN_SAMPLES = 50


def default_signals(logs) -> tuple[str, ...]:
    """Signals the simulation error uses by default: the speed, or the angle when no log has one.

    The speed whenever a log has it, measured or derived from the angle: its simulation error
    does not accumulate (viscous friction forgets), so a small force error cannot dominate the
    cost as it does through the open-loop angle, which integrates every error. Weighted by its
    noise (an encoder's quantisation, tiny), the angle of a model that still lacks an effect (a
    load torque, direction-dependent friction) drifts by orders of magnitude more than its
    noise and drags J, bv and bc far from their values to reduce the drift; closed-loop data,
    where a controller holds the real axis on its trajectory, is worse still. The angle is
    fitted when no log has a speed, or on request (``--signals omega,theta``).
    """
    if any(lg.has("omega") for lg in logs):
        return ("omega",)
    if any(lg.has("theta") for lg in logs):
        return ("theta",)
    raise FitError("fit-nonlinear needs a speed 'omega' or angle 'theta' column in the logs "
                   "(map one with -c)")


def start_values(logs, model: Model, free, warns,
                 pick: int = 0) -> tuple[dict[str, float], set[str], int]:
    """Starting values: the model's (fit-mechanical) for voltage logs, inverse dynamics for
    torque-driven logs, else a quasi-static fit with J from a one-sample time constant (too slow
    a sampling to see the acceleration), else the model. Torque-driven logs may give several
    starts (:func:`competing_starts`, lowest simulation error first): ``pick`` chooses one.
    Returns (start, names guessed, how many starts there are)."""
    from pmdcid.identify.inverse_dynamics import fit_inverse_dynamics, fit_quasi_static

    start: dict[str, float] = {}
    guessed: set[str] = set()
    nstarts = 1
    tau_logs = [lg for lg in logs if lg.drive == "tau"]
    if tau_logs and _earlier_mechanics(model):
        tau_logs = []  # a lumped model from fit-mechanical: its J, bv are the better start
    if tau_logs:
        try:
            idm = fit_inverse_dynamics(tau_logs, model)
            start.update({k: v for k, v in idm.values().items() if math.isfinite(v)})
            warns.extend(w for w in idm.warnings if "tau0" not in w)  # tau0: its own rule here
            starts = competing_starts(tau_logs, model, start)
            nstarts = len(starts)
            start.update(starts[min(pick, nstarts - 1)])
        except FitError as exc:
            try:
                start.update(fit_quasi_static(tau_logs, model))
                if not model.has("J"):
                    start["J"] = start["bv"] * max(lg.dt for lg in tau_logs)
                    guessed.add("J")
                warns.append(f"inverse dynamics gave no start ({exc}); bv, bc, tau0 start from "
                             "the torque against the speed (quasi-static), J from a mechanical "
                             "time constant of one sample period")
            except FitError as exc2:
                warns.append(f"inverse dynamics gave no start ({exc}; {exc2}); starting from "
                             "the model")
    for name in ("J", "bv", "bc", "dz", "tau0", *LUMPED_FREE):
        if name not in start and model.has(name):
            start[name] = model.value(name)
    start.setdefault("ke_share", 1.0)
    if "bv" not in start and model.has("b"):
        start["bv"] = model.value("b")
    missing = [n for n in ("J", "bv") if n not in start]
    if missing:
        how = ("put them in the model: the torque-driven logs gave no start" if tau_logs
               else "run fit-mechanical first")
        raise ModelError(f"model lacks {', '.join(missing)} to start fit-nonlinear: {how}",
                         model.path)
    start.setdefault("bc", 0.0)
    start["bc"] = max(start["bc"], 0.0)
    start["bv"] = max(start["bv"], 1e-3 * start["J"])
    if "dz" not in start:
        tb = model.extra.get("fits", {}).get("fit-mechanical", {}).get("breakaway_torque")
        start["dz"] = float(tb) if isinstance(tb, (int, float)) and tb > 0 else start["bc"]
    start.setdefault("tau0", 0.0)
    return start, guessed, nstarts


def reference_column(logs, names=None) -> str | None:
    """The first set-point column any log carries: one of ``names``, or (``names`` None) one
    whose name says it is a set-point (:func:`pmdcid.io.mapping.is_setpoint`: ``omega_ref``,
    ``targetSpeed``, ``speed_sp`` ...); None when there is none."""
    for lg in logs:
        for n in (*lg.extra, *lg.data):
            if (n in names) if names is not None else is_setpoint(n):
                return n
    return None


def closed_loop_logs(logs, names=None) -> bool:
    """True when any log carries a set-point column (:func:`reference_column`)."""
    return reference_column(logs, names) is not None


def competing_starts(logs, model: Model, idm: dict[str, float]) -> list[dict[str, float]]:
    """The torque-driven fit's starts, lowest simulation error on ``logs`` first: inverse
    dynamics' (``idm``), the J, bv, bc the model holds (the first-order least squares of every
    moving log, :mod:`.linstart`, or an earlier run's) and, for closed-loop logs, the
    quasi-static friction with inverse dynamics' J (:func:`closed_loop_start`).

    Inverse dynamics regresses the torque on a filtered acceleration: with a noisy speed its
    cut-off falls to a few Hz and a few dozen rows remain, and a friction that is no
    ``bc sign(omega)`` (Stribeck's, falling from breakaway) is read as inertia and offset
    (bench/torquerig.py's Stribeck rig at 100 Hz: J 2-10 % of the truth, and the local stage,
    held within 10x of its start, could not reach it). Which start is best shows only after
    the fit (a start's own simulation error does not rank the basins it leads to): the fit
    runs from each (:func:`pmdcid.identify.nonlinear.fit_nonlinear`)."""
    sets = [idm]
    held = _model_start(model, idm)
    if held:
        sets.append(held)
    if closed_loop_logs(logs):
        qs = closed_loop_candidate(logs, model, idm)
        if qs:
            sets.append(qs)
    return _by_cost(logs, model, sets)


def _model_start(model: Model, idm: dict[str, float]) -> dict[str, float] | None:
    """The model's own J, bv, bc as a start (tau0 0 unless it holds one), None without J, bv."""
    if not (model.has("J") and model.has("bv")):
        return None
    out = {**idm, "J": model.value("J"), "bv": model.value("bv"),
           "bc": max(model.value("bc"), 0.0) if model.has("bc") else 0.0,
           "tau0": model.value("tau0") if model.has("tau0") else 0.0}
    return out if out["J"] > 0 and out["bv"] > 0 else None


def closed_loop_start(logs, model: Model, idm: dict[str, float]) -> dict[str, float]:
    """Closed-loop logs: inverse dynamics regresses the torque on a speed and an acceleration
    whose noise the controller fed back into that torque (biased: bv 1e-4 of its value on a PI
    loop with 1 rad/s of speed noise, tests/simulate/test_closedloop.py). The quasi-static friction
    (torque against the speed at the samples, no acceleration) with inverse dynamics' J
    competes with it by simulation error; the lower wins."""
    qs = closed_loop_candidate(logs, model, idm)
    return _lowest_cost(logs, model, [idm, qs]) if qs else idm


def closed_loop_candidate(logs, model: Model, idm: dict[str, float]) -> dict[str, float] | None:
    """The quasi-static friction with inverse dynamics' J (None when it gives none)."""
    from pmdcid.identify.inverse_dynamics import fit_quasi_static

    try:
        qs = {**idm, **fit_quasi_static(logs, model)}
    except FitError:
        return None
    qs["bc"] = max(qs["bc"], 0.0)
    return qs if qs["bv"] > 0 and idm.get("J", 0.0) > 0 else None


def _lowest_cost(logs, model: Model, sets: list[dict[str, float]]) -> dict[str, float]:
    """The set of ``sets`` with the lowest speed simulation error on ``logs``."""
    return _by_cost(logs, model, sets)[0]


def _by_cost(logs, model: Model, sets: list[dict[str, float]]) -> list[dict[str, float]]:
    """``sets`` in order of their speed simulation error on ``logs`` (as given when they cannot
    be compared: a log without a speed, a model the kernel refuses)."""
    from pmdcid.fit.problem import noise_level
    from pmdcid.identify.grid import batch_cost
    from pmdcid.simulate import param_values
    from pmdcid.simulate.initial import initial_state

    if len(sets) < 2:
        return sets
    try:
        base = param_values(model, True, {"J": sets[0]["J"]})
    except ModelError:
        return sets
    cost = np.zeros(len(sets))
    for lg in logs:
        if not lg.has("omega"):
            return sets
        sig = noise_level(lg["omega"])
        cost += batch_cost(lg, [{**base, **{k: v for k, v in c.items() if k in base}}
                                for c in sets], {"omega": sig}, x0=initial_state(lg, sig))
    if not np.all(np.isfinite(cost)):
        return sets
    return [sets[i] for i in np.argsort(cost, kind="stable")]


def _earlier_mechanics(model: Model) -> bool:
    """True when an earlier stage (not a start value) wrote J and bv (or b) into ``model``."""
    def staged(n):
        return model.has(n) and model.parameters[n].stage not in ("", "start")
    return staged("J") and (staged("bv") or staged("b"))


def check_logs(logs) -> None:
    """Each log has an input, a speed or angle, and enough samples (else one clear error)."""
    if not logs:
        raise FitError("fit-nonlinear needs at least one log")
    for lg in logs:
        lg.drive  # noqa: B018 - raises when a log has neither v nor tau
        if not (lg.has("omega") or lg.has("theta")):
            lg.require("omega", purpose="fit-nonlinear (a speed 'omega' or an angle 'theta')")
        if lg.n < MIN_SAMPLES:
            raise FitError(f"too short ({lg.n} samples) for a simulation-error fit (needs at "
                           f"least {MIN_SAMPLES})", lg.path)


def require_km(model: Model, logs, stage: str) -> None:
    """The model's torque constant km, which a voltage-driven fit of the mechanics needs: where
    it lacks one and these logs hold the armature current of a turning rotor, the message says
    that fit-electrical gives it from them (ke, km = ke in SI), besides a datasheet's --km."""
    if model.has("km"):
        return
    turning = [str(lg.path) for lg in logs if lg.drive == "v" and lg.has("i") and not lg.blocked]
    if not turning:
        model.require("km", stage=stage)
    raise ModelError(f"model lacks km for {stage}: give --km (datasheet torque constant), or "
                     f"run fit-electrical on {turning[0]}"
                     f"{f' (and {len(turning) - 1} more)' if len(turning) > 1 else ''}: it "
                     "logs the current of a turning rotor, which gives the back-EMF constant "
                     "ke and km = ke in SI", model.path)


def free_parameters(logs, model: Model, free, dead_zone: bool, warns=None,
                    offset: bool = True) -> list[str]:
    """The parameters fitted: given, or J, bv, bc, dz (voltage logs; R, L, km required) or
    J, bv, bc, tau0 (torque logs; dz with ``dead_zone``; tau0 only where the speed moves both
    ways, :func:`both_directions`, and ``offset``, a note in ``warns`` when left out)."""
    any_v = any(lg.drive == "v" for lg in logs)
    if any_v:
        model.require("R", "L", stage="fit-nonlinear")
        require_km(model, logs, "fit-nonlinear")
    if free is None:
        free = list(FREE_V if any_v else FREE_TAU)
        if "tau0" in free and not (offset and both_directions(logs)):
            free.remove("tau0")
            if warns is not None and offset:
                warns.append(Note(OFFSET_ONE_WAY + held_offset(model), about="tau0",
                                  severity="note"))
        if dead_zone and "dz" not in free:
            free.append("dz")
    free = list(dict.fromkeys(free))
    bad = [f for f in free if f not in KNOWN_FREE]
    if bad:
        raise FitError(f"cannot fit {', '.join(bad)} here (choose among "
                       f"{', '.join(KNOWN_FREE)})")
    return free


#: the note when the logs turn one way only
OFFSET_ONE_WAY = ("the speed never reverses in these logs: a torque offset tau0 cannot be told "
                  "from Coulomb friction (bc + tau0 is what they determine), so tau0 is not "
                  "fitted")
#: a moving sample's speed is beyond this many noise levels; each direction must hold at least
#: :data:`DIRECTION_SHARE` of the moving samples
MOVING_NOISE = 4.0
DIRECTION_SHARE = 0.01


def held_offset(model: Model) -> str:
    if model.has("tau0") and "torque_offset" in model.effects:
        return f" (the model's tau0 = {model.value('tau0'):.3g} from other data is kept)"
    return " (0: torque_offset not written)"


def both_directions(logs) -> bool:
    """True when the measured speed (or the angle's first difference) moves clearly both ways
    over ``logs``: each direction holds at least 1 % of the samples faster than 4 noise levels
    and 2 % of the 99th-percentile speed. Only then is a constant torque (tau0, the same sign
    either way) told from Coulomb friction (bc sign(omega))."""
    return _both_ways(*_motion_counts(logs))


def rests(logs) -> bool:
    """True when at least :data:`DIRECTION_SHARE` of the samples over ``logs`` do not move
    clearly (the speed within the threshold of :func:`both_directions`): the rotor at rest,
    or barely turning, where a speed sensor's offset is read as it is and not as a shift of
    the friction line. An offset beyond that threshold hides such samples among the moving
    ones: the logs are then said not to rest (the conservative side)."""
    return _rests(*_motion_counts(logs))


def rests_or_both_ways(logs) -> bool:
    """:func:`rests` or :func:`both_directions`, the samples counted once."""
    counts = _motion_counts(logs)
    return _rests(*counts) or _both_ways(*counts)


def _both_ways(pos: int, neg: int, still: int) -> bool:
    return min(pos, neg) >= DIRECTION_SHARE * max(pos + neg, 1) and min(pos, neg) > 0


def _rests(pos: int, neg: int, still: int) -> bool:
    total = pos + neg + still
    return total > 0 and still >= DIRECTION_SHARE * total


def _motion_counts(logs) -> tuple[int, int, int]:
    """Samples moving clearly forwards, backwards, and not clearly moving, over ``logs``
    (the measured speed, else the angle's first difference; logs with neither skipped)."""
    from pmdcid.fit.problem import noise_level

    pos = neg = still = 0
    for lg in logs:
        if lg.has("omega"):
            w = np.asarray(lg["omega"], float)
        elif lg.has("theta"):
            w = np.diff(np.asarray(lg["theta"], float)) / lg.dt
        else:
            continue
        w = w[np.isfinite(w)]
        if len(w) < 5:
            continue
        thr = max(MOVING_NOISE * noise_level(w), 0.02 * float(np.percentile(np.abs(w), 99)))
        pos += int(np.sum(w > thr))
        neg += int(np.sum(w < -thr))
        still += int(np.sum(np.abs(w) <= thr))
    return pos, neg, still


def chosen_signals(logs, signals) -> tuple[tuple[str, ...], list[str]]:
    """The measured signals in the cost (given or :func:`default_signals`), and a warning for
    each one derived from the other."""
    signals = tuple(signals) if signals else default_signals(logs)
    unknown = [s for s in signals if s not in SIGNALS]
    if unknown:
        raise FitError(f"unknown signal(s) {', '.join(unknown)} (choose omega, theta)")
    warns: list[str] = []
    for s in signals if len(signals) > 1 else ():
        if any(s in lg.derived for lg in logs):
            warns.append(f"'{s}' is derived from the other measured signal in some logs: it "
                         "adds no independent information")
    return signals, warns


def working_model(logs, model: Model, free, warns, pick: int = 0):
    """A copy of ``model`` holding the starting values (:func:`start_values`, the ``pick``-th
    start) of the fitted parameters and of those it lacks (no dead zone unless the model has one
    or it is fitted); returns (model, start values, names guessed, how many starts there are)."""
    work = model.copy()
    if "tau0" in free:
        work.add_effect("torque_offset")
    start, guessed, nstarts = start_values(logs, work, free, warns, pick)
    if "dz" not in free and not work.has("dz"):
        start["dz"] = 0.0
    for name in ("J", "bv", "bc", "dz", "tau0", *LUMPED_FREE):
        if name in free or (not work.has(name) and name in ("J", "bv", "bc", "dz")):
            work.set(name, start[name], stage="start")
    return work, start, guessed, nstarts
