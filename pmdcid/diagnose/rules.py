"""diagnose's rule set, in one place: when a refitted candidate counts, and when it is kept.

A candidate is first *checked* (is its refit evidence at all?), then *judged* against the rules:

- **refit failed**: the refit's chi-square on the fit part is above the model it extends (the
  effect at its neutral value is one of the points it could reach): the optimiser failed, which
  says nothing about the effect. Never counted.
- **degenerate**: a parameter of the effect ends at a bound (the refit ran out of room: the
  effect stands in for something else), or the row is identical to another candidate's (two
  effects the logs cannot tell apart). Never counted.
- the rules, in order: ΔBIC on the fit part below ``bic``; the held-out data able to test the
  effect at all (:mod:`pmdcid.diagnose.testable`: one log at one operating point cannot test a
  delay or a speed law; such an effect is *possible, not testable with these logs*, unless
  each of two or more logs' transients, held out in turn, can test it:
  :mod:`pmdcid.diagnose.crosslog`) and bearing out what they can tell; the held-out likelihood
  ratio below ``heldout``; the effect's size at least ``min_z`` standard errors; the
  chi-square drop at least ``min_gain`` of the excess on both parts; the speed NRMSE of no log
  held out whole (or head held out across logs, or the time split's held-out parts beside
  them) rising by more than ``max_rise`` (relative).
  The first rule a candidate fails is its reason.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from pmdcid.diagnose.testable import why_one_way
from pmdcid.identify.offset import OFFSET_BIC
from pmdcid.model import EFFECTS

#: a refit above the model it extends by more than this share of its chi-square has failed
FAILED_REL = 1e-6
#: a parameter within this share of its bound's distance (or of its value) sits at the bound
AT_BOUND_REL = 1e-3
#: two candidates whose fit chi-squares agree within this share are the same row
SAME_ROW_REL = 1e-7


@dataclass(frozen=True)
class Rules:
    """The thresholds a candidate must pass."""

    bic: float = OFFSET_BIC  # the evidence every effect needs, a torque offset's in identify too
    heldout: float = -10.0
    min_z: float = 5.0
    min_gain: float = 0.01
    max_rise: float = 0.05


def failed_refit(chi2_fit: float, extends_fit: float) -> bool:
    """A refit whose fit-part chi-square is above that of the model it extends."""
    return chi2_fit > extends_fit * (1.0 + FAILED_REL)


def at_bound(value: float, lower: float, upper: float) -> str | None:
    """'lower' or 'upper' when ``value`` sits at a finite bound, else None."""
    for side, b in (("lower", lower), ("upper", upper)):
        if math.isfinite(b) and b != 0.0 and abs(value - b) <= AT_BOUND_REL * abs(b):
            return side
    return None


def _pct(x: float) -> str:
    return f"{100 * x:.1f} %"


def judge(c, rules: Rules) -> tuple[bool, str]:
    """(passes, why) for a refitted, counted candidate (see the module's rule order)."""
    if not c.delta_bic < rules.bic:
        return False, f"ΔBIC {c.delta_bic:+.1f} ≥ {rules.bic:g}"
    pre = f"ΔBIC {c.delta_bic:+.0f} but "
    untested = _untested(c)
    if untested:
        return False, untested
    if c.heldout is not None and not c.heldout < rules.heldout:
        return False, pre + (f"held-out Δ {c.heldout:+.1f} ≥ {rules.heldout:g} (no gain on "
                             "data it was not fitted on)")
    z = c.z if c.z is not None else math.nan
    if not z >= rules.min_z:
        return False, pre + f"size {z:.2g} standard errors < {rules.min_z:g}"
    gf = c.gain_fit if c.gain_fit is not None else 0.0
    gh = c.gain_held if c.gain_held is not None else 1.0
    if min(gf, gh) < rules.min_gain:
        part = "fit" if gf < gh else "held-out"
        return False, pre + f"{part} gain {_pct(min(gf, gh))} < {_pct(rules.min_gain)}"
    if c.rise is not None and c.rise > rules.max_rise:
        return False, pre + (f"speed NRMSE of held-out log {c.rise_log} rises {_pct(c.rise)} > "
                             f"{_pct(rules.max_rise)}")
    held = f", held-out Δ {c.heldout:+.0f}" if c.heldout is not None else ""
    where = getattr(c.test, "where", "")
    if where:
        held += f" on the transients of {where} held out"
    return True, (f"passes: ΔBIC {c.delta_bic:+.0f}{held}, {z:.3g} standard errors, gains "
                  f"{_pct(gf)} / {_pct(gh)}")


UNTESTABLE = "possible, not testable with these logs"


def _untested(c) -> str | None:
    """Why the held-out data cannot test or do not bear out candidate ``c`` (None: they do)."""
    t = c.test
    if t is None:
        return None
    if getattr(t, "one_way", False):
        record = EFFECTS[c.effect].record or "motion in both directions"
        return (f"{UNTESTABLE}: {why_one_way(c.effect)} (ΔBIC {c.delta_bic:+.0f} on the fit "
                f"part); to test it, record {record}")
    if not t.testable:
        return (f"{UNTESTABLE}: on the data held out it changes nothing the other parameters "
                f"could not (distinguishable χ² {t.distinct:.3g} < {t.floor:.3g}; ΔBIC "
                f"{c.delta_bic:+.0f} on the fit part); to test it, record "
                f"{EFFECTS[c.effect].record or 'other operating points'}")
    if not t.confirms:
        return (f"ΔBIC {c.delta_bic:+.0f} but the held-out data do not bear it out: of the "
                f"χ² {t.distinct:.3g} by which they can tell it from the other parameters, "
                f"{t.confirmed:.3g} is gained")
    return None


def same_rows(cands) -> dict[str, str]:
    """Candidates (of one round, refitted and counted) whose rows are identical to another's:
    effect -> the effect it duplicates (both of a pair are named)."""
    out: dict[str, str] = {}
    for j, c in enumerate(cands):
        for d in cands[:j]:
            a, b = c.chi2_fit, d.chi2_fit
            if a is None or b is None or d.effect in out:
                continue
            if abs(a - b) <= SAME_ROW_REL * max(abs(a), abs(b), 1e-300):
                out[c.effect] = d.effect
                out.setdefault(d.effect, c.effect)
                break
    return out


__all__ = ["UNTESTABLE", "Rules", "at_bound", "failed_refit", "judge", "same_rows"]
