"""``pmdcid identify``: a whole rig in one command.

The logs are sorted (``# kind:`` metadata where present, else by content), the paper's stages run
on the logs each applies to, every later stage combining its logs with what the earlier ones
determined (:mod:`pmdcid.identify.priors`), then one joint simulation-error fit over every log
that moves, then
diagnose and the report. Each decision is printed with its reason.

It sits above identify/, diagnose/ and report/ (it calls all three) and below cli/.

Sorting by content (:func:`classify`):

- rotor still (no speed or angle, or a speed within noise of zero) with a current flowing ->
  ``blocked`` (fit-electrical);
- an input with one change (a step, up or down), or a step and its return -> ``step``
  (fit-mechanical);
- an input that never changes -> ``unused`` (nothing to identify from);
- anything else -> ``rich`` (fit-nonlinear: ramps, triangles, sines, chirps, staircases).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from pmdcid.errors import FitError, PmdcidError
from pmdcid.identify.results import ResultProtocol, notes_of
from pmdcid.model import Model
from pmdcid.model.lumped import is_lumped, mark_lumped, wants_lumped
from pmdcid.model.params import copy_model_into

#: metadata kinds -> class
KIND_META = {"blocked-rotor": "blocked", "blocked": "blocked", "free-speed-step": "step",
             "step": "step", "triangle": "rich", "ramp": "rich", "rich": "rich"}
#: a step log: one jump, or a jump and its return (a log cut after the input went back)
STEP_CHANGES = 2


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
        from pmdcid.identify.results import known_names
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
    if not (log.has("omega") or log.has("theta")):
        return True
    if log.has("omega") and "omega" not in log.derived:
        w = np.asarray(log["omega"], float)
        from pmdcid.io.derive import noise_std

        sd = noise_std(w[np.isfinite(w)])
        return bool(np.nanmax(np.abs(w)) < 5 * max(sd, 1e-12))
    return False


def _measures_nothing(log) -> str:
    """Why a log with an input and no measurement identifies nothing, and what to map."""
    from pmdcid.errors import short_list

    hint = (f"unmapped: {short_list(list(log.extra), 4)}; map one, e.g. "
            f"-c omega={next(iter(log.extra))}*SCALE" if log.extra
            else "map one with -c omega=SOURCE*SCALE")
    return (f"measures no speed, angle or current (it has {', '.join(['t', *log.data])}; "
            f"{hint})")


def classify(log) -> LogPlan:
    """The class of one log (module docstring) and the reason, in words."""
    kind = (log.kind or "").strip().lower()
    if kind in KIND_META:
        return LogPlan(log.path, KIND_META[kind], f"'# kind: {kind}' in the file")
    if not any(log.has(c) for c in ("i", "omega", "theta")):
        return LogPlan(log.path, "unused", _measures_nothing(log))
    if log.has("i") and log.drive == "v" and _still(log):
        return LogPlan(log.path, "blocked", "the rotor stays still while current flows")
    n = input_changes(log.u)
    if n == 0:
        return LogPlan(log.path, "unused", "the input never changes: nothing to identify")
    if _still(log):
        return LogPlan(log.path, "unused", "the rotor never moves (and no current is logged)")
    if n <= STEP_CHANGES:
        return LogPlan(log.path, "step", "one step in the input" + (
            " (and its return)" if n == 2 else ""))
    return LogPlan(log.path, "rich", f"the input changes {n} times (ramp, sine, staircase...)")


def identify(logs, model: Model, *, km: float | None = None, run_diagnose: bool = True,
             priors: bool = True, progress=None) -> IdentifyResult:
    """Identify a whole rig from ``logs`` starting from ``model`` (may be empty).

    ``km`` [N m/A]: the datasheet torque constant. ``run_diagnose``: search the effect catalogue
    on every log after the joint fit. ``priors``: later stages combine with earlier estimates.
    ``progress(msg)``: called before each stage. Returns an :class:`IdentifyResult` (the model
    given is not modified).
    """
    say = progress or (lambda msg: None)
    work = model.copy()
    if km is not None:
        work.set("km", km, stage="datasheet")
    plan = [classify(lg) for lg in logs]
    res = IdentifyResult(work, plan)
    groups = {k: [lg for lg, p in zip(logs, plan, strict=True) if p.kind == k]
              for k in ("blocked", "step", "rich")}
    if groups["blocked"]:
        say("fit-electrical")
        _stage(res, "fit-electrical", groups["blocked"], _electrical)
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
    if wants_lumped(moving, res.model) and not is_lumped(res.model):
        mark_lumped(res.model)
        res.notes.append("no current and no R: the model is lumped (per-volt parameters; "
                         "see the model file's lumped_note)")
    elif (not is_lumped(res.model) and not res.model.has("km")
          and any(lg.drive == "v" for lg in moving)):
        mark_lumped(res.model)
        res.notes.append("no km (no datasheet, and the back-EMF was not resolved): the "
                         "mechanical part is identified per volt (lumped); give --km for SI")
    if groups["step"]:
        say("fit-mechanical")
        _stage(res, "fit-mechanical", groups["step"], _mechanical)
    if groups["rich"] and groups["step"] and _has_mech(res.model):
        say("fit-nonlinear")
        _stage(res, "fit-nonlinear", groups["rich"], _nonlinear(priors))
    say("joint fit")
    _stage(res, "joint fit (all moving logs)", moving, _nonlinear(False))
    if not res.stages:
        raise FitError("no stage could use these logs: " + "; ".join(res.notes))
    if run_diagnose and any(name.startswith("joint") for name, _ in res.stages):
        say("diagnose")
        _diagnose(res, moving, say)
    return res


def _free_running_electrical(res: IdentifyResult, moving, say) -> None:
    """No blocked-rotor logs and no R: R, L and the back-EMF constant ke from the moving logs
    that log current (fit-electrical's free-running path, v = R i + L di/dt + ke omega). Without
    a datasheet km, the SI identity km = ke of an ideal motor gives it (said in the notes)."""
    with_current = [lg for lg in moving if lg.has("i") and lg.drive == "v" and lg.has("omega")]
    if not with_current:
        return
    say("fit-electrical (free-running)")
    _stage(res, "fit-electrical (free-running logs)", with_current, _electrical)
    m = res.model
    if not m.has("km") and "back_emf" in m.effects and m.has("ke"):
        ke = m.parameters["ke"]
        m.set("km", ke.value, ke.stderr, stage="ke (km = ke, no datasheet)")
        res.notes.append(f"no datasheet km: km = ke = {ke.value:.4g} (an ideal motor's torque and "
                         "back-EMF constants are one number in SI; iron and brush losses make the "
                         "true km slightly smaller); give --km to use the datasheet's")


def _has_mech(model: Model) -> bool:
    return model.has("J") and (model.has("bv") or model.has("b"))


def _stage(res: IdentifyResult, name: str, logs, fit) -> None:
    """Run one stage; a stage that cannot use its logs is noted, the others go on."""
    try:
        out = fit(logs, res.model)
    except PmdcidError as exc:
        res.notes.append(f"{name}: skipped: {exc}")
        return
    new = res.model.copy()
    out.apply(new)
    if is_lumped(res.model):
        from pmdcid.identify.runners import per_volt

        per_volt(out)
        mark_lumped(new)
    res.model = new
    res.stages.append((name, out))
    res.warnings += [w.in_stage(name) for w in notes_of(out)]


def _electrical(logs, model):
    from pmdcid.identify.electrical import fit_electrical

    return fit_electrical(logs, model)


def _mechanical(logs, model):
    from pmdcid.identify.mechanical import fit_mechanical
    from pmdcid.identify.runners import lumped_mechanical

    if is_lumped(model):
        return lumped_mechanical(logs, model, fit_mechanical)
    if not model.has("km"):
        raise FitError("fit-mechanical needs km: give --km (datasheet) or leave out the "
                       "current to identify a lumped model")
    return fit_mechanical(logs, model)


def _nonlinear(priors: bool):
    def run(logs, model):
        from pmdcid.identify.runners import stage_nonlinear

        return stage_nonlinear(logs, model, priors=priors)

    return run


def _diagnose(res: IdentifyResult, logs, say=None) -> None:
    from pmdcid.diagnose.loop import diagnose
    from pmdcid.simulate import logs_for

    # how the joint fit read slow inputs between samples: its ramp, or held (0) when it read
    # none (J not free there, or no slow log): diagnose refits under the same reading
    joint = [out for name, out in res.stages if name.startswith("joint")]
    ramp = getattr(joint[-1], "estimates", {}).get("ramp") if joint else None
    try:
        out = diagnose(logs_for(logs, res.model), res.model, progress=say,
                       ramp=ramp.value if ramp is not None else 0.0)
    except PmdcidError as exc:
        res.notes.append(f"diagnose: skipped: {exc}")
        return
    if is_lumped(res.model):
        mark_lumped(out.model)
    res.model = out.model
    res.diagnose = out


def run_identify(paths, model_path, out_dir=None, mapping=None, km=None, run_diagnose=True,
                 priors=True, progress=None, force=False) -> IdentifyResult:
    """``pmdcid identify`` on files: read, identify, write MODEL atomically, then the report.

    The plausibility gate (:mod:`pmdcid.identify.plausibility`) checks the logs before and the
    model before it is written, as every stage command does; ``force`` makes it warn instead."""
    import os

    from pmdcid.errors import LogError
    from pmdcid.identify.plausibility import gate, gate_result
    from pmdcid.io import read_logs
    from pmdcid.io.outputs import locked
    from pmdcid.model import load_model, save_model
    from pmdcid.simulate.substeps import bounded_for

    for p in paths:
        if os.path.exists(p) and os.path.exists(model_path) and os.path.samefile(p, model_path):
            raise LogError(f"the model file would overwrite the input log {p}; choose another -m",
                           model_path)
    if out_dir is not None:
        from pmdcid.report import check_out_dir

        check_out_dir(out_dir)
    model = load_model(model_path, must_exist=False)
    logs = read_logs(paths, mapping, defer=True)

    def value(name, given=None):
        return given if given is not None else (
            model.parameters[name].value if name in model.parameters else None)

    gate(logs, force, value("km", km), value("R"))
    with bounded_for(model_path):
        res = identify(logs, model, km=km, run_diagnose=run_diagnose, priors=priors,
                       progress=progress)
    res.model.extra.setdefault("fits", {})["identify"] = {
        "logs": {p.path: {"kind": p.kind, "why": p.why} for p in res.plan},
        "stages": [name for name, _ in res.stages], "notes": res.notes}
    res.record_notes(res.model)
    gate_result(res.model, logs, force)
    with locked(model_path):
        save_model(res.model, model_path)
    if out_dir is not None:
        from pmdcid.report import make_report

        summary = res.diagnose.summary if res.diagnose is not None else None
        shown = [lg for lg, p in zip(logs, res.plan, strict=True) if p.kind != "unused"]
        rep = make_report(shown, res.model, out_dir, summary=summary, progress=progress)
        res.report_dir = rep.out_dir
    return res


__all__ = ["IdentifyResult", "LogPlan", "classify", "identify", "input_changes",
           "run_identify"]
