"""``pmdcid identify``: a whole rig in one command.

The logs are sorted (``# kind:`` metadata where present, else by content), the paper's stages run
on the logs each applies to, every later stage combining its logs with what the earlier ones
determined (:mod:`pmdcid.fit.priors`), then one joint simulation-error fit over every log
that moves, then
diagnose. Each decision is printed with its reason.

It sits above identify/ and diagnose/ (it calls both); :func:`pmdcid.files.run_identify` runs it
on files (the model written, the report).

Sorting (:func:`classify`): a ``# kind:`` line decides where present, read through the one
vocabulary of log kinds (:mod:`pmdcid.io.kinds`: plan's ``small-steps``, ``levels``,
``staircase``, ``slow-triangle``, ``prbs``... each to the stage it was recorded for); else the
content:

- rotor still (no speed or angle, or a speed within noise of zero) with a current flowing ->
  ``blocked`` (fit-electrical);
- an input that never changes -> ``unused`` (nothing to identify from);
- an input held at levels (one step or many: :func:`~pmdcid.identify.steps.held_steps`, robust
  to a noisy measured voltage) -> ``step`` (fit-mechanical uses every step that settles);
- anything else -> ``rich`` (fit-nonlinear: ramps, triangles, sines, chirps).

The mechanical fit starts from any moving log (:func:`_mechanical_start`): the step logs, else
the steps found inside the rich logs, else a first-order least-squares fit of the moving logs
(:mod:`pmdcid.identify.linstart`, through the logged current where there is one). The joint fit
is checked (:func:`_joint_fit`): one that diverged (a mechanical time constant beyond the logs or
any motor, or under one sample period: J collapsed) is run again from the stages' estimate with
their priors, and dropped, with the reason, when it diverges again. A rig whose logs move never
ends without J: identify then raises naming what failed, with and without ``-o`` alike.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from pmdcid.errors import MAX_MESSAGE, FitError, LogError, PmdcidError, one_line, short_list
from pmdcid.fit.results import ResultProtocol, notes_of
from pmdcid.identify.nonlinear_setup import MIN_SAMPLES, closed_loop_logs
from pmdcid.identify.plausibility import (
    MAX_TAU_MECHANICAL,
    mechanical_tau,
    out_of_bounds,
    stuck_issue,
    typical_speed,
)
from pmdcid.identify.runners import (
    apply_stage,
    fit_stage,
    lumped_mechanical,
    stage_electrical,
    stage_nonlinear,
)
from pmdcid.identify.steps import MIN_PLATEAU_SAMPLES, held_steps
from pmdcid.io.kinds import canonical, describe, stage_class
from pmdcid.model import Model
from pmdcid.model.lumped import is_lumped, mark_lumped, wants_lumped
from pmdcid.model.params import copy_model_into

#: a joint fit whose mechanical time constant exceeds this many times the longest log has not
#: been determined by the logs: it diverged
DIVERGED_DURATIONS = 3.0


@dataclass
class LogPlan:
    """What identify does with one log: its class and why."""

    path: str
    kind: str
    why: str


@dataclass
class IdentifyResult(ResultProtocol):
    """The model identify wrote, the per-log plan, each stage's result and what was skipped."""

    model: Model
    plan: list[LogPlan]
    stages: list[tuple[str, object]] = field(default_factory=list)
    notes: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    diagnose: object = None
    report_dir: str | None = None

    def table(self) -> str:
        lines = ["identify: what each log is used for", ""]
        w = max([len(p.path) for p in self.plan] + [3])
        w = min(w, 48)
        for p in self.plan:
            name = p.path if len(p.path) <= w else "..." + p.path[-(w - 3):]
            lines.append(f"{name:<{w}}  {p.kind:<8} {p.why}")
        for name, res in self.stages:
            lines += ["", f"== {name}", res.table()]
        if self.diagnose is not None:
            lines += ["", "== diagnose", self.diagnose.table()]
        lines += [""] + self.notes
        return "\n".join(lines).rstrip()

    def rows(self) -> list[tuple[str, float, float, str]]:
        """The identified model's parameters."""
        return self.model.rows()

    def apply(self, model: Model) -> None:
        """Make ``model`` the identified model: its parameters, effects and records."""
        copy_model_into(self.model, model)

    def all_notes(self) -> list:
        """Every stage's warnings, identify's own notes and diagnose's, as
        :class:`~pmdcid.notes.Note` (what each concerns, severity, stage)."""
        from pmdcid.fit.results import known_names
        from pmdcid.notes import as_note

        names, logs = known_names(), [p.path for p in self.plan]
        out = [as_note(w, names=names, logs=logs) for w in self.warnings]
        out += [as_note(n, severity="note", stage="identify", names=names, logs=logs)
                for n in self.notes]
        if self.diagnose is not None:
            out += self.diagnose.all_notes()
        return out


def input_changes(u: np.ndarray) -> int:
    """Number of changes of a zero-order-held input [count]: sample-to-sample jumps above its
    noise (5 robust std of the first difference; a commanded input has none). A ramp or a
    sine changes at every sample; a noisy measured input that drifts slowly without a single
    jump above its noise counts as changing at every sample too."""
    u = np.asarray(u, float)
    u = u[np.isfinite(u)]
    span = float(np.max(u) - np.min(u)) if u.size else 0.0
    if not span > 0:
        return 0
    d = np.abs(np.diff(u))
    moving = int(np.count_nonzero(d > 1e-9 * span))
    if moving > 0.1 * len(d):
        return moving  # changes at most samples: a ramp, sine, chirp (or a noisy input)
    # robust scale of the sample-to-sample change (0 for a held, commanded input)
    sd = 1.4826 * float(np.median(d)) / math.sqrt(2.0)
    jumps = int(np.count_nonzero(d > max(5.0 * sd, 1e-9 * span)))
    if jumps == 0 and span > 20.0 * sd:
        return len(u) - 1
    return jumps


def _still(log) -> bool:
    """True when the rotor never moves: no speed or angle, a measured speed within 5 noise std
    of zero, or (speed derived from the angle) an angle that stays within 5 noise std."""
    from pmdcid.io.derive import noise_std

    if not (log.has("omega") or log.has("theta")):
        return True
    sig = "omega" if log.has("omega") and "omega" not in log.derived else "theta"
    if not log.has(sig) or sig in log.derived:
        return False
    x = np.asarray(log[sig], float)
    x = x[np.isfinite(x)]
    if sig == "theta":
        x = x - x[0] if x.size else x
    return bool(x.size == 0 or np.max(np.abs(x)) < 5 * max(noise_std(x), 1e-12))


def _measures_nothing(log) -> str:
    """Why a log with an input and no measurement identifies nothing, and what to map."""
    hint = (f"unmapped: {short_list(list(log.extra), 4)}; map one, e.g. "
            f"-c omega={next(iter(log.extra))}*SCALE" if log.extra
            else "map one with -c omega=SOURCE*SCALE")
    return (f"measures no speed, angle or current (it has {', '.join(['t', *log.data])}; "
            f"{hint})")


def classify(log) -> LogPlan:
    """The class of one log (module docstring) and the reason, in words."""
    if log.n < MIN_PLATEAU_SAMPLES:  # said as such, not as "no step" or "nothing moves"
        return LogPlan(log.path, "unused", f"only {log.n} samples: too short for any stage (a "
                                           f"step needs {MIN_PLATEAU_SAMPLES}, a simulation-"
                                           f"error fit {MIN_SAMPLES})")
    cls = stage_class(log.kind)
    if cls is not None:
        return LogPlan(log.path, cls, f"'# kind: {log.kind}' in the file "
                                      f"({describe(canonical(log.kind))})")
    if not any(log.has(c) for c in ("i", "omega", "theta")):
        return LogPlan(log.path, "unused", _measures_nothing(log))
    if log.has("i") and log.drive == "v" and _still(log):
        return LogPlan(log.path, "blocked", "the rotor stays still while current flows")
    n = input_changes(log.u)
    if _still(log):
        why = ("the input never changes: nothing to identify" if n == 0 else
               "the rotor never moves (and no current is logged)")
        return LogPlan(log.path, "unused", why)
    if n == 0:
        return _constant_input(log)
    steps = held_steps(log.t, log.u)
    if steps:
        return LogPlan(log.path, "step", f"the input is held at levels ({len(steps)} step"
                                         f"{'s' if len(steps) > 1 else ''})")
    return LogPlan(log.path, "rich", "the input varies between its samples (ramp, sine, "
                                     "chirp...)")


def _constant_input(log) -> LogPlan:
    """A log whose input never changes while the rotor moves: a step applied at its first sample
    (fit-mechanical reads it as a step from rest there, or, a rotor already turning, its steady
    speed) or a coast-down (the joint fit uses it). Sorted as rich before, a step log fitted
    from a first-order start with the lag tested by two whole lumped fits: lego-ev3's 20 duty
    steps took identify 34 s, held-out 0.064; as steps 1.2 s, 0.063 (bench/realbench.py)."""
    if float(np.max(np.abs(log.u))) > 0:
        return LogPlan(log.path, "step", "the input is held from the first sample while the "
                                         "rotor moves (a step applied at the log's start)")
    return LogPlan(log.path, "rich", "no input while the rotor moves (a coast-down)")


def identify(logs, model: Model, *, km: float | None = None, run_diagnose: bool = True,
             priors: bool = True, progress=None, controller=None) -> IdentifyResult:
    """Identify a whole rig from ``logs`` starting from ``model`` (may be empty).

    ``km`` [N m/A]: the datasheet torque constant. ``run_diagnose``: search the effect catalogue
    on every log after the joint fit. ``priors``: later stages combine with earlier estimates.
    ``progress(msg)``: called before each stage. ``controller``: the controller spec of
    closed-loop logs (:mod:`pmdcid.identify.closedfit`), passed to the nonlinear fits.
    Returns an :class:`IdentifyResult` (the model given is not modified).
    """
    say = progress or (lambda msg: None)
    _check_controller(logs, controller)
    work = model.copy()
    if km is not None:
        work.set("km", km, stage="datasheet")
    plan = [classify(lg) for lg in logs]
    res = IdentifyResult(work, plan)
    res.fitted_on(logs, model)
    groups = {k: [lg for lg, p in zip(logs, plan, strict=True) if p.kind == k]
              for k in ("blocked", "step", "rich")}
    if groups["blocked"]:
        say("fit-electrical")
        _stage(res, "fit-electrical", groups["blocked"], stage_electrical)
    moving = groups["step"] + groups["rich"]
    if not moving:
        if not res.stages:
            why = res.notes[0] if res.notes else f"{plan[0].path}: {plan[0].why}" + (
                f" (and {len(plan) - 1} more log(s))" if len(plan) > 1 else "")
            raise FitError(f"no log identifies anything: {why}; give logs where the input "
                           "changes and the rotor moves (steps, ramps) or blocked-rotor "
                           "current steps")
        return res
    if not groups["blocked"] and not res.model.has("R"):
        _free_running_electrical(res, moving, say)
    elif groups["blocked"] and res.model.has("R") and not res.model.has("km"):
        _back_emf_beside_blocked(res, moving, say)
    if wants_lumped(moving, res.model) and not is_lumped(res.model):
        mark_lumped(res.model)
        res.notes.append("no current and no R: the model is lumped (per-volt parameters; "
                         "see the model file's lumped_note)")
    elif (not is_lumped(res.model) and not res.model.has("km")
          and any(lg.drive == "v" for lg in moving)):
        mark_lumped(res.model)
        res.notes.append("no km (no datasheet, and the back-EMF was not resolved): the "
                         "mechanical part is identified per volt (lumped); give --km for SI")
    _mechanical_start(res, groups, say)
    if groups["rich"] and groups["step"] and _staged_mech(res):
        say("fit-nonlinear")
        _stage(res, "fit-nonlinear", groups["rich"], _nonlinear(priors, controller))
    say("joint fit")
    _joint_fit(res, moving, model, controller)
    _require_mechanics(res, moving)
    if run_diagnose and any(name.startswith("joint") for name, _ in res.stages):
        say("diagnose")
        _diagnose(res, moving, say)
    return res


def _check_controller(logs, controller) -> None:
    """A controller whose reference column no log carries is refused before any stage runs
    (each closed-loop fit would otherwise be skipped in turn, and a model fitted as if no loop
    ran be written)."""
    if controller is None or any(controller.reference in lg.data or
                                 controller.reference in lg.extra for lg in logs):
        return
    have = short_list(dict.fromkeys(c for lg in logs for c in (*lg.data, *lg.extra)), 8)
    raise LogError(f"the controller's reference column '{controller.reference}' is in none of "
                   f"the logs (they have {have}): name the set-point column with the spec's "
                   "reference=COLUMN (or map it, -c omega_ref=COLUMN), or leave out --controller "
                   "for open-loop logs", ", ".join(lg.path for lg in logs))


def _mechanical_start(res: IdentifyResult, groups, say) -> None:
    """J and viscous friction before the joint fit, from the first source that gives them: the
    step logs (fit-mechanical), the steps inside the rich logs, a first-order least-squares fit
    of every moving log (:mod:`pmdcid.identify.linstart`)."""
    unsettled = []
    if groups["step"]:
        say("fit-mechanical")
        unsettled = _step_stage(res, groups)
    # a controller's output (a closed-loop log: a set-point column) is no step experiment: its
    # jumps answer the measured speed, and a step fit there reads the loop's lag as a latency
    inside = [lg for lg in groups["rich"] if not _has_mech(res.model)
              and not closed_loop_logs([lg]) and lg not in unsettled and _any_step(lg)]
    if inside:
        say("fit-mechanical")
        _inside_stage(res, inside)
    if not _has_mech(res.model):
        say("linear start")
        _stage(res, "linear start (first-order fit of the moving logs)",
               groups["step"] + groups["rich"], _linear_start)


def _step_stage(res: IdentifyResult, groups) -> list:
    """fit-mechanical on the step logs. A log held at levels most of whose steps end before the
    speed settles (fit-mechanical refused more of them as too short than it used: an APRBS, a
    fast random staircase) is no step experiment: the few steps that pass are fitted with the
    response of the earlier ones still in them (a time constant of a few ms behind a dead time
    of a tenth of a second). Such logs are sorted as rich (fit-nonlinear, by simulation error),
    and fit-mechanical runs again without them. Returns those logs."""
    before = res.model
    _stage(res, "fit-mechanical", groups["step"], _mechanical)
    if res.model is before:
        return []
    steps = res.stages[-1][1].steps
    unsettled = [lg for lg in groups["step"] if _mostly_unsettled(steps, lg.path)]
    if not unsettled:
        return []
    _undo(res, before)
    for lg in unsettled:
        groups["step"].remove(lg)
        groups["rich"].append(lg)
        k = next(j for j, p in enumerate(res.plan) if p.path == lg.path and p.kind == "step")
        res.plan[k] = LogPlan(lg.path, "rich", res.plan[k].why + ", most too short for the "
                              "speed to settle (an APRBS): fitted by simulation error")
    if groups["step"]:
        _stage(res, "fit-mechanical", groups["step"], _mechanical)
    return unsettled


def _inside_stage(res: IdentifyResult, inside) -> None:
    """fit-mechanical on the steps inside the rich logs, kept where it determines J (J at least
    two of its standard errors: :func:`_determines_j`). Where most of a PRBS's steps end before
    the speed settles, the few that pass can carry the earlier levels' response: the plan's
    PRBS for the paper's motor (current logged) gave J 0.00085 +- 0.015 for 0.0031, and the
    joint fit started there stopped short (J' +4.9 standard errors). Such a J says nothing: the
    first-order fit of every moving log starts the joint fit instead."""
    before = res.model
    name = "fit-mechanical (steps inside the rich logs)"
    _stage(res, name, inside, _inside_mechanical)
    if res.model is before or _determines_j(res.model):
        return
    j = res.model.parameters["J"]
    _undo(res, before)
    res.notes.append(f"{name}: J = {j.value:.3g} +- {j.stderr:.2g} is not determined by the "
                     "steps that settle: not used; the mechanics start from a first-order fit")


def _inside_mechanical(logs, model):
    """fit-mechanical on the steps inside rich logs as a start for the joint fit: J and the
    friction, not the steps' latency. Its fit simulates the whole log (an APRBS) without the
    dead zone, whose late starts a latency then takes: bench/newrigs.py arduino-aprbs seed 7
    (an H-bridge dead band, 20 ms samples) wrote a 52 ms sensor_delay that the joint fit,
    which does not refit it, kept: the held-out runs at 0.124 against the stages' 0.034. A
    delay the logs hold is diagnose's to find, tested on held-out data."""
    res = _mechanical(logs, model)
    late = res.estimates.pop("delay", None)
    if late is not None and math.isfinite(late.value):
        res.warnings.append(f"the steps' latency ({1e3 * late.value:.3g} ms) is not kept: "
                            "these steps start from levels inside a rich log, a start for the "
                            "joint fit; diagnose tests a sensor delay on held-out data")
    return res


def _determines_j(model: Model) -> bool:
    """J written with a standard error at most half its value."""
    if not model.has("J"):
        return False
    j = model.parameters["J"]
    return bool(math.isfinite(j.stderr) and 0.0 < 2.0 * j.stderr <= abs(j.value))


def _mostly_unsettled(steps, path: str) -> bool:
    """More of the log's steps refused as too short to settle than used."""
    mine = [s for s in steps if s.path == path]
    short = sum(1 for s in mine if not s.moved and s.note == "plateau too short")
    return short > sum(1 for s in mine if s.moved)


def _any_step(log) -> bool:
    from pmdcid.identify.steps import find_steps

    try:
        return bool(find_steps(log.t, log.u))
    except FitError:
        return False


def _staged_mech(res: IdentifyResult) -> bool:
    """J and bv from a stage that fitted them (fit-mechanical), not a start value."""
    return _has_mech(res.model) and res.model.parameters["J"].stage != "start"


def _joint_fit(res: IdentifyResult, moving, given: Model, controller=None) -> None:
    """The joint fit over every moving log, checked: one whose mechanical time constant the logs
    cannot have determined (beyond any motor's, or :data:`DIVERGED_DURATIONS` times the longest
    log) diverged; it runs again from the stages' estimate with their priors, and is dropped
    (the stages' model kept, the reason noted) when it diverges again. It replaces what this
    run's stages wrote (:func:`_written_here`) as one set; a value ``given`` (the model file
    identify started from) is left where these logs do not determine it."""
    name = "joint fit (all moving logs)"
    before = res.model
    mine = _written_here(res.model, given)
    _stage(res, name, moving, _nonlinear(False, controller, replaces=mine))
    why = _diverged(res.model, before, moving)
    if why is None:
        return
    _undo(res, before)
    res.notes.append(f"{name}: diverged ({why}); fitted again from the stages' estimate with "
                     "their priors")
    _stage(res, name, moving, _nonlinear(True, controller, replaces=mine))
    again = _diverged(res.model, before, moving)
    if again is not None:
        _undo(res, before)
        res.notes.append(f"{name}: diverged again ({again}): not used; the model holds the "
                         "stages' estimates")


def _written_here(model: Model, given: Model) -> frozenset[str]:
    """The parameters of ``model`` this identify run's stages wrote: absent from ``given``,
    the model it started from, or changed since."""
    return frozenset(n for n, p in model.parameters.items()
                     if n not in given.parameters or given.parameters[n].value != p.value
                     or given.parameters[n].stage != p.stage)


def _undo(res: IdentifyResult, before: Model) -> None:
    """Forget the last stage if it changed the model (its result and warnings)."""
    if res.model is before:
        return
    name, _ = res.stages.pop()
    res.warnings = [w for w in res.warnings if not w.startswith(f"{name}: ")]
    res.model = before


def _diverged(model: Model, before: Model, logs) -> str | None:
    """Why a fitted model's mechanics cannot be what the logs determined (None: plausible)."""
    if model is before:
        return None
    stuck = stuck_issue(model, logs)
    if stuck:
        return stuck.split(". ")[0]
    speed = typical_speed(logs)
    tau = mechanical_tau(model, speed)
    longest = max(float(lg.t[-1] - lg.t[0]) for lg in logs)
    if not math.isfinite(tau) or tau <= 0:
        return "no finite mechanical time constant"
    dt = min(float(lg.t[1] - lg.t[0]) for lg in logs)
    if tau < dt:  # J collapsed to ~0: no sampled speed can show it
        return f"mechanical time constant {tau:.3g} s, under one sample period ({dt:.3g} s)"
    if tau > MAX_TAU_MECHANICAL or tau > DIVERGED_DURATIONS * longest:
        was = mechanical_tau(before, speed)
        was = f"; the stages gave {was:.3g} s" if math.isfinite(was) else ""
        return f"mechanical time constant {tau:.3g} s, the longest log {longest:.3g} s{was}"
    return None


def _require_mechanics(res: IdentifyResult, moving) -> None:
    """Moving logs and still no J a stage fitted (none, or only the linear start's, a start
    value without an uncertainty that no fit confirmed): raise, naming what each stage said (no
    half model, no guessed one)."""
    if _staged_mech(res):
        return
    # each stage's whole reason (a stage's name and its one error line, bounded as such): its
    # end says what to do (the speed's sign, the unit to map); the line is as long as they are
    each = 2 * MAX_MESSAGE
    said = "; ".join(one_line(n, each) for n in res.notes) or "no stage gave J"
    raise FitError("identify could not fit the mechanics (J, bv) from the moving logs: " + said,
                   ", ".join(lg.path for lg in moving), limit=each * (len(res.notes) + 1))


def _free_running_electrical(res: IdentifyResult, moving, say) -> None:
    """No blocked-rotor logs and no R: R, L and the back-EMF constant ke from the moving logs
    that log current (fit-electrical's free-running path, v = R i + L di/dt + ke omega). Without
    a datasheet km, the SI identity km = ke of an ideal motor gives it (said in the notes)."""
    with_current = [lg for lg in moving if lg.has("i") and lg.drive == "v" and lg.has("omega")]
    if not with_current:
        return
    from pmdcid.identify.freerun import KM_FROM_KE, KM_FROM_KE_NOTE

    say("fit-electrical (free-running)")
    _stage(res, "fit-electrical (free-running logs)", with_current, stage_electrical)
    m = res.model
    if m.has("km") and m.parameters["km"].stage == KM_FROM_KE:
        res.notes.append(KM_FROM_KE_NOTE.format(ke=m.value("km")))


def _back_emf_beside_blocked(res: IdentifyResult, moving, say) -> None:
    """Blocked-rotor logs gave R and L, no datasheet km, and moving logs log the current: the
    back-EMF constant ke from those logs (the free-running fit), km = ke as without blocked
    logs; R and L stay the blocked rotor's (an L it did not resolve, written as an interval,
    takes the moving logs' where they resolve it). Before, such a rig (the usual lab set: blocked
    steps, free steps, current logged) was identified per volt, 'no current' said, and its
    report stopped on the current it logged."""
    keep = {n: res.model.parameters[n] for n in ("R", "L") if res.model.has(n)
            and res.model.parameters[n].interval is None}   # an L not resolved: the new fit's
    before = len(res.stages)
    _free_running_electrical(res, moving, say)
    if len(res.stages) == before or not res.model.has("km"):
        return
    for name, par in keep.items():
        res.model.parameters[name] = par
    res.notes.append(f"{' and '.join(keep) or 'nothing'} from the blocked-rotor logs, ke (and "
                     "km = ke) from the moving logs' current")


def _has_mech(model: Model) -> bool:
    return model.has("J") and (model.has("bv") or model.has("b"))


def _stage(res: IdentifyResult, name: str, logs, fit) -> None:
    """Run one stage; a stage that cannot use its logs, or whose result leaves a parameter
    outside its physical bounds, is noted, the others go on."""
    try:
        out = fit_stage(fit, logs, res.model)
    except PmdcidError as exc:
        res.notes.append(f"{name}: skipped: {exc}")
        return
    new = res.model.copy()
    apply_stage(out, new)
    bad = out_of_bounds(new)
    if bad is not None:  # never a start for the next stage (J at its floor: minutes per fit)
        res.notes.append(f"{name}: skipped: the fit gives {bad}")
        return
    res.model = new
    res.stages.append((name, out))
    res.warnings += [w.in_stage(name) for w in notes_of(out)]


def _linear_start(logs, model):
    from pmdcid.identify.linstart import linear_start

    return linear_start(logs, model)


def _mechanical(logs, model):
    from pmdcid.identify.mechanical import fit_mechanical

    if is_lumped(model):
        return lumped_mechanical(logs, model, fit_mechanical)
    if not model.has("km") and any(lg.drive == "v" for lg in logs):  # torque steps need none
        raise FitError("fit-mechanical needs km: give --km (datasheet) or leave out the "
                       "current to identify a lumped model")
    return fit_mechanical(logs, model)


def _nonlinear(priors: bool, controller=None, replaces: frozenset[str] = frozenset()):
    def run(logs, model):
        return stage_nonlinear(logs, model, priors=priors, controller=controller,
                               replaces=replaces)

    return run


def _diagnose(res: IdentifyResult, logs, say=None) -> None:
    from pmdcid.diagnose.entry import diagnose_logs

    # how the joint fit read slow inputs between samples: its ramp, or held (0) when it read
    # none (J not free there, or no slow log): diagnose refits under the same reading
    joint = [out for name, out in res.stages if name.startswith("joint")]
    ramp = getattr(joint[-1], "estimates", {}).get("ramp") if joint else None
    try:
        out = diagnose_logs(logs, res.model, progress=say,
                            ramp=ramp.value if ramp is not None else 0.0)
    except PmdcidError as exc:
        res.notes.append(f"diagnose: skipped: {exc}")
        return
    res.model = out.model
    res.diagnose = out


__all__ = ["IdentifyResult", "LogPlan", "classify", "identify", "input_changes"]
