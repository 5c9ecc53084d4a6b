"""diagnose prefers a named friction law to the friction curve where the law suffices.

``friction_curve`` (four knot values) can follow almost any speed-dependent friction, so it can
always stand in for quadratic drag, Stribeck or viscous asymmetry, with more parameters and
less meaning. The rule: when the curve is the best passing candidate of a round and a named law
also passes, the curve is chosen only if its ΔBIC (which already charges its extra parameters
log(n) each) beats the best named law's by more than :data:`NAMED_MARGIN`; otherwise the named
law is chosen, and both rows say so. So that the comparison can be made, a round that refits the
curve also refits the best-screened named law.

Being flexible, the curve must also *generalise*: its chi-square gain on the held-out data must
be at least :data:`HELD_SHARE` of its gain on the fit data. A friction law is time-invariant; a
curve that removes 27 % of the fit part's excess but 6 % of the held-out part's (seen on EMPS,
whose validation run it then predicted 14 % worse) follows the fit data, not the friction.
"""

from __future__ import annotations

#: the effect that follows no named law, and the named laws it can stand in for
CURVE = "friction_curve"
NAMED_LAWS = ("quadratic_drag", "stribeck", "viscous_asymmetry")
#: ΔBIC by which the curve must beat the best passing named law to be chosen over it
NAMED_MARGIN = 10.0
#: the curve's held-out chi-square gain must be at least this share of its fit gain
HELD_SHARE = 0.5


def generalises(c) -> str | None:
    """Why the curve candidate ``c`` does not generalise (held-out gain under
    :data:`HELD_SHARE` of its fit gain), or None (also for every other effect)."""
    if c.effect != CURVE or c.gain_fit is None or c.gain_held is None:
        return None
    if c.gain_held >= HELD_SHARE * c.gain_fit:
        return None
    return (f"ΔBIC {c.delta_bic:+.0f} but a flexible curve must generalise: held-out gain "
            f"{100 * c.gain_held:.1f} % < {HELD_SHARE:g} × its fit gain "
            f"{100 * c.gain_fit:.1f} %")


def with_named(ranked: list, screens: list) -> list:
    """``ranked`` (screens to refit) plus the best-screened named law when the curve is among
    them and no named law is (a screen with a start and a negative approximate ΔBIC)."""
    names = {s.effect for s in ranked}
    if CURVE not in names or names & set(NAMED_LAWS):
        return ranked
    named = [s for s in screens if s.effect in NAMED_LAWS and s.start
             and s.approx_delta_bic < 0]
    return ranked + [max(named, key=lambda s: s.gain)] if named else ranked


def prefer_named(best, passing: list, margin: float = NAMED_MARGIN):
    """The candidate to choose: ``best`` (lowest ΔBIC of ``passing``), or the best passing named
    law when ``best`` is the curve and does not beat it by more than ``margin``. Sets the
    curve's ``reason`` when it is passed over."""
    if best.effect != CURVE:
        return best
    named = [c for c in passing if c.effect in NAMED_LAWS]
    if not named:
        return best
    law = min(named, key=lambda c: c.delta_bic)
    if best.delta_bic < law.delta_bic - margin:
        best.reason += (f"; beats the best named law {law.effect} (ΔBIC {law.delta_bic:+.0f}) "
                        f"by more than {margin:g}")
        return best
    best.reason += (f"; not chosen: the named law {law.effect} explains it about as well "
                    f"(ΔBIC {law.delta_bic:+.0f} vs {best.delta_bic:+.0f}, the curve must beat "
                    f"it by more than {margin:g})")
    law.reason += f"; preferred to {CURVE} (a named law that suffices)"
    return law


__all__ = ["CURVE", "HELD_SHARE", "NAMED_LAWS", "NAMED_MARGIN", "generalises", "prefer_named",
           "with_named"]
