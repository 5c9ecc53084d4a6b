"""What diagnose hands back: the result object, the model it writes, the summary
(docs/cli.md's keys and more) with the errors before and after, on the logs held out whole
too, and the residual's shape when it is still not white."""

from __future__ import annotations

from dataclasses import dataclass, field

from pmdcid.diagnose.candidates import Candidate, effect_free
from pmdcid.diagnose.drive_warnings import drive_warnings
from pmdcid.diagnose.folds import floor_of
from pmdcid.diagnose.residuals import drift_notes, drift_problem, error_table, pooled, whiteness
from pmdcid.diagnose.rules import UNTESTABLE
from pmdcid.diagnose.shape import residual_shapes
from pmdcid.diagnose.testable import one_way, why_one_way
from pmdcid.fit.problem import FitOutcome
from pmdcid.fit.results import ResultProtocol, write_estimate
from pmdcid.model import EFFECTS, Model
from pmdcid.model.params import copy_model_into

STAGE = "diagnose"


@dataclass
class DiagnoseResult(ResultProtocol):
    """The new model, the summary (docs/cli.md), per-log errors and the candidates."""

    model: Model
    summary: dict
    candidates: list[Candidate]
    paths: list[str]
    before: list[dict[str, float]]
    after: list[dict[str, float]]
    history: list[Candidate] = field(default_factory=list)

    def table(self) -> str:
        from pmdcid.diagnose.table import format_table

        return format_table(self)

    def rows(self) -> list[tuple[str, float, float, str]]:
        """The new model's parameters."""
        return self.model.rows()

    def apply(self, model: Model) -> None:
        """Make ``model`` the diagnosed model: its parameters, effects and records."""
        copy_model_into(self.model, model)


def write_model(new: Model, final: FitOutcome, free: list[str], added: list[str]) -> None:
    """The added effects and every refitted estimate into ``new``; a km written as ke follows
    a refitted ke (:func:`~pmdcid.identify.freerun.follow_ke`)."""
    from pmdcid.identify.freerun import follow_ke

    km_before = new.value("km") if new.has("km") else 0.0
    for e in added:
        new.add_effect(e)
        for p in EFFECTS[e].held:
            new.set(p, final.values[p], stage=STAGE)
    for est in final.estimates.values():
        write_estimate(new, est, STAGE)
    follow_ke(new, km_before)


def heldout_errors(run, base: FitOutcome, final_vals: dict[str, float],
                   added: list[str], lag: tuple[str, ...] = ()) -> list[dict]:
    """Speed (and current) NRMSE of every log held out whole: the base refitted on the fit part
    against the final effects refitted on the fit part (neither saw these logs); ``lag``: the
    lag's parameters when diagnose wrote one (:mod:`pmdcid.diagnose.lag`), refitted too."""
    held = run.problem.held_logs
    if not held:
        return []
    after_vals = base.values
    if added or lag:
        free = run.base_free + [p for e in added for p in effect_free(e)] + list(lag)
        after_vals = run.fit(final_vals, list(dict.fromkeys(free))).values
    b = error_table(run.problem, run.problem.simulate_all(base.values))
    a = error_table(run.problem, run.problem.simulate_all(after_vals))
    return [{"log": run.problem.logs[k].path, "before": b[k], "after": a[k]} for k in held]


def untestable(cands: list[Candidate], pool=(), logs=()) -> list[dict]:
    """Effects the fit part supports that no held-out data here can test, and the direction
    effects of the search ``pool`` that ``logs`` turning one way cannot test at all, supported
    or not (:func:`~pmdcid.diagnose.testable.one_way`): what to record."""
    out = [{"effect": c.effect, "record": EFFECTS[c.effect].record, "reason": c.reason}
           for c in cands if c.reason.startswith(UNTESTABLE)]
    listed = {u["effect"] for u in out}
    return out + [{"effect": e, "record": EFFECTS[e].record,
                   "reason": f"{UNTESTABLE}: {why_one_way(e)}"}
                  for e in pool if e not in listed and one_way(e, logs)]


def summarise(run, new: Model, base: FitOutcome, final_vals: dict[str, float],
              added: list[str], seen: dict[str, Candidate], history: list[Candidate],
              notes: list[str], lag: tuple[str, ...] = ()) -> DiagnoseResult:
    """The summary (docs/cli.md's keys and more), the residual's shape when unexplained;
    ``lag``: the lag's parameters when diagnose wrote one in a delay's place."""
    problem = run.problem
    before = error_table(problem, problem.simulate_all(run.vals0))
    final_sims = problem.simulate_all(final_vals)
    after = error_table(problem, final_sims) if added or lag else before
    white = whiteness(problem, final_sims)
    unexplained = any(w.structured for w in white)
    shapes: list[dict] = []
    if unexplained:
        dp = drift_problem(problem)
        if dp is not None:
            notes.extend(drift_notes(dp, final_vals, run.settings.max_nfev))
        shapes = residual_shapes(problem, final_sims,
                                 floor_of(run.floors), pooled(after)["omega_nrmse"])
    cands = sorted(seen.values(), key=lambda c: (not c.chosen, c.delta_bic))
    new.extra.setdefault("fits", {})[STAGE] = {
        "logs": [log.path for log in problem.logs], "added": list(added)}
    summary = {
        "added": list(added),
        "candidates": [c.to_json() for c in cands],
        "before": pooled(before),
        "after": pooled(after),
        "unexplained": bool(unexplained),
        "untestable": untestable(cands, getattr(run, "pool", ()), problem.logs),
        "residual_shape": shapes,
        "notes": notes,
        "warnings": drive_warnings(problem, final_sims, final_vals, added, new),
        "holdout": [{"log": log.path, "part": p} for log, p in zip(problem.logs, problem.plan,
                                                                    strict=True)],
        "heldout": heldout_errors(run, base, final_vals, added, lag),
        "repeatability": [f.to_json() for f in run.floors],
        "logs": [{"path": log.path, "before": b, "after": a}
                 for log, b, a in zip(problem.logs, before, after, strict=True)],
        "whiteness": [{"log": problem.logs[w.log].path, "signal": w.signal,
                       "std_over_noise": w.ratio, "rho1": w.rho1, "ljung_box_p": w.p_value,
                       "structured": w.structured} for w in white],
    }
    return DiagnoseResult(new, summary, cands, [log.path for log in problem.logs], before, after,
                          history)


__all__ = ["DiagnoseResult", "heldout_errors", "summarise", "untestable", "write_model"]
