"""``plan --check``: which effects diagnose screens could these logs test, and what to record.

diagnose adds an effect only where held-out data can tell it from the base parameters it
interacts with (:mod:`pmdcid.diagnose.testable`); otherwise it lists it as "possible, not
testable with these logs" with the effect's ``record`` hint. Here the same split of the logs
(:func:`pmdcid.diagnose.folds.holdout_plan`: repeats held out whole, other logs split in time),
the same effects (diagnose's search pool on these logs and this model), the same free base
parameters and the same held-out floor are used, at the model's values with each effect at the
size diagnose probes it with (:func:`pmdcid.plan.effect_errors.probe_of`):
:func:`pmdcid.diagnose.testable.logs_can_test`. Before any refit, so a necessary condition: an
effect listed as testable may still not be borne out by the data; one listed as not testable
cannot be added by diagnose on these logs.
"""

from __future__ import annotations

from pmdcid.diagnose.folds import holdout_plan
from pmdcid.diagnose.loop import free_base, search_pool
from pmdcid.diagnose.residuals import context
from pmdcid.diagnose.rules import UNTESTABLE, Rules
from pmdcid.diagnose.testable import logs_can_test, why_one_way
from pmdcid.fit.problem import Problem
from pmdcid.model import EFFECTS, Model
from pmdcid.plan.effect_errors import probe_of
from pmdcid.simulate import logs_for, param_values


def effects_testable(logs, model: Model) -> list[dict]:
    """One row per effect diagnose would screen on ``logs`` with ``model``: ``effect``,
    ``testable`` (bool), ``record`` (what to record where it is not), ``why`` (in words), and
    the chi-squares behind it (``heldout_distinct`` of the largest effect the fit part could
    hold, the ``floor`` it must reach)."""
    seen = logs_for(logs, model)
    problem = Problem(seen, plan=holdout_plan(seen))
    vals = param_values(model, torque_driven=all(lg.drive == "tau" for lg in seen))
    ctx = context(problem, vals, problem.simulate_all(vals))
    probes, rows = {}, []
    for e in search_pool(problem, model, None):
        col = probe_of(EFFECTS[e], ctx)
        if col is None:
            rows.append(_row(e, False, "no probe at these logs' scales (nothing for the "
                                       "effect to act on)"))
        else:
            probes[e] = col
    tests = logs_can_test(problem, vals, probes, free_base(problem, vals, model),
                          ctx.torque_scale, Rules())
    for e, t in tests.items():
        why = (f"the data held out could tell it from {_others(e)}" if t.testable else
               f"{UNTESTABLE}: {why_one_way(e)}" if t.one_way else
               f"{UNTESTABLE}: even an effect explaining all of the fit part's χ² would change "
               f"the data held out by {t.largest:.3g} χ² (< {t.floor:.3g}) beyond what "
               f"{_others(e)} could absorb")
        rows.append(_row(e, t.testable, why, t.largest, t.floor))
    order = list(EFFECTS)
    return sorted(rows, key=lambda r: order.index(r["effect"]))


def _others(effect: str) -> str:
    inter = EFFECTS[effect].interacts
    return ", ".join(inter) if inter else "the model as it is"


def _row(effect: str, testable: bool, why: str, distinct=None, floor=None) -> dict:
    return {"effect": effect, "testable": bool(testable),
            "record": None if testable else (EFFECTS[effect].record or "other operating points"),
            "why": why, "heldout_distinct": distinct, "floor": floor}


__all__ = ["effects_testable"]
