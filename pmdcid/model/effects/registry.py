"""The effect record and the catalogue's queries.

An :class:`Effect` declares its parameters (name, unit, neutral value, bounds), where it acts
(``electrical``, ``mechanical``, ``sensor`` or ``input``), the base parameters it interacts with,
its physics and residual signature in words, and what diagnose needs to search for it: its probes,
the starting guess, tighter refit bounds, a physical size bound and what to record to test it.
The simulation kernel evaluates every effect's term from the flat parameter vector; an effect
that is not listed in a model's ``effects`` has its parameters held at their neutral values, so
it is exactly off.

:data:`EFFECTS` is filled by :mod:`pmdcid.model.effects` (one module per effect, registered in
diagnose's search order); ``param_spec``, ``unit_of`` and ``bounds_of`` answer for any
parameter, base or effect.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

from pmdcid.model.spec import BASE_PARAMS, ParamSpec, bound_reach, bound_words, range_words


@dataclass(frozen=True)
class Effect:
    """One catalogue effect."""

    name: str
    #: its physics and its signature in the residual, in words
    doc: str
    params: tuple[ParamSpec, ...]
    acts_on: str  # "electrical" | "mechanical" | "sensor" | "input"
    #: the base parameters it interacts with: refitted with it, and those that can stand in
    #: for it where the data hold only part of what it acts on (one speed level cannot tell a
    #: drag law from bv): :mod:`pmdcid.diagnose.testable` projects them out of its held-out
    #: signature
    interacts: tuple[str, ...] = ()
    #: ``signature(ctx) -> list[Probe]``: small parameter settings switching the effect on, whose
    #: simulated change is the effect's signature in the residual
    #: (:class:`pmdcid.model.residual.ResidualContext`, :class:`~pmdcid.model.residual.Probe`)
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
    #: physical for these logs (a delay of many samples, a sensor bias the size of the speed);
    #: ``values`` the refit's parameters, ``ctx`` the residual context (scales, the shortest
    #: sample period), ``start`` the parameter values before diagnose
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


def within_range(name: str, low: float, high: float) -> tuple[float, float]:
    """[low, high] cut to ``name``'s own range (its lower bound, or 0 where that is higher,
    to its upper; unchanged for an unknown name): what a model file can hold
    (:func:`pmdcid.model.params.check_interval`). A bound the logs leave wider than physics is
    physics' (a lag the steps leave open up to 9 s, an inductance bound of 1 s x R)."""
    spec = param_spec(name)
    if spec is None:
        return float(low), float(high)
    return max(float(low), min(spec.lower, 0.0)), min(float(high), spec.upper)


def stderr_words(name: str, value: float,
                 stderr: float) -> tuple[str, tuple[float, float] | None]:
    """(words, interval) to write in place of a standard error of ``name`` that is none: one
    spanning its whole declared range (:func:`range_only`: the words, no interval), or one read
    at a declared bound where the fit stopped (:func:`pmdcid.model.spec.bound_reach`: the words
    and the interval from the bound two standard errors into the range); ("", None) where the
    standard error stands. The one rule the model's writer
    (:meth:`pmdcid.model.params.Model.set`) and the results as shown
    (:func:`pmdcid.fit.results.shown`) apply."""
    words = range_only(name, value, stderr)
    spec = param_spec(name)
    if words or spec is None:
        return words, None
    reach = bound_reach(value, stderr, spec.lower, spec.upper)
    if reach is None:
        return "", None
    return bound_words(spec.lower if reach[0] == spec.lower else spec.upper), reach


def range_only(name: str, value: float, stderr: float) -> str:
    """The words for a standard error of ``name`` that spans its whole declared range (its
    value +-2 ``stderr`` covers [lower, upper]: :func:`pmdcid.model.spec.spans_range`), to
    write in its place (``stderr`` then NaN, null in the model file); "" for any other (an
    unknown name, a range open on a side, a standard error that says something). The one rule
    for every bounded parameter, base or effect: the model's writer
    (:meth:`pmdcid.model.params.Model.set`) and the results as shown
    (:func:`pmdcid.fit.results.shown`; the fits keep their own numbers) both apply it."""
    spec = param_spec(name)
    if spec is None or not spec.spanned(value, stderr):
        return ""
    return range_words(spec.lower, spec.upper, spec.unit)
