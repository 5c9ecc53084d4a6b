"""Units of model-file values: a value given in a prefixed unit is converted, never ignored.

Every parameter has one canonical SI unit (:mod:`pmdcid.model.params`). A model file may state a
value in that unit with an SI prefix (``"unit": "mohm"``, ``"mH"``, ``"mN m/A"``, ``"uH"``,
``"kohm"``): the value is scaled to the canonical unit when the model is read. An empty unit means
the canonical one. Any other unit is refused with one line: a value whose unit the tool cannot
read must not be used as if it were SI.
"""

from __future__ import annotations

import re

from pmdcid.errors import ModelError

PREFIXES: dict[str, float] = {
    "": 1.0, "p": 1e-12, "n": 1e-9, "u": 1e-6, "m": 1e-3, "c": 1e-2, "k": 1e3, "M": 1e6, "G": 1e9,
}

#: other spellings of the same canonical unit (after :func:`_norm`); a linear axis's units too
ALIASES: dict[str, tuple[str, ...]] = {
    "ohm": ("ohms",),
    "Nm/A": ("N/A", "Vs/rad", "Vs"),
    "kgm^2": ("kg",),
    "Nms/rad": ("Nms", "Ns/m"),
    "Nm": ("N",),
    "rad/s": ("m/s",),
    "rad": ("m",),
}


def _norm(unit: str) -> str:
    u = str(unit).strip()
    for a, b in (("Ω", "ohm"), ("µ", "u"), ("μ", "u"), ("²", "^2"), ("·", ""), ("*", ""),
                 (" ", ""), ("Ohm", "ohm"), ("OHM", "ohm"), ("m2", "m^2")):
        u = u.replace(a, b)
    return u


_INERTIA = re.compile(r"([pnumck]?)g([pnumck]?)m\^2")


def _inertia_factor(u: str) -> float | None:
    """A moment of inertia in prefixed grams and metres (``g cm^2``, ``kg mm^2``, ``g m^2``)
    -> kg m^2."""
    m = _INERTIA.fullmatch(u)
    if m is None:
        return None
    return PREFIXES[m.group(1)] * 1e-3 * PREFIXES[m.group(2)] ** 2


def unit_factor(unit: str, canonical: str) -> float | None:
    """Factor turning a value in ``unit`` into ``canonical`` (None: not a prefixed form of it)."""
    u, c = _norm(unit), _norm(canonical)
    if u in ("", c):
        return 1.0
    if c == "kgm^2" and _inertia_factor(u) is not None:
        return _inertia_factor(u)
    forms = (c, *ALIASES.get(c, ()))
    for form in forms:
        if u == form:
            return 1.0
        if u.endswith(form) and u[: -len(form)] in PREFIXES:
            if form.startswith("kg"):  # 'g' forms would be needed to prefix kg: refuse
                return None
            return PREFIXES[u[: -len(form)]]
    return None


def to_canonical(name: str, value: float, unit: str, canonical: str, path) -> float:
    """``value`` in ``unit`` converted to ``canonical``, or a :class:`ModelError`."""
    if not canonical or canonical == "1":
        if _norm(unit) in ("", "1", "-"):
            return value
    k = unit_factor(unit, canonical)
    if k is None:
        raise ModelError(f"parameter '{name}' has unit {str(unit)[:30]!r}, which pmdcid cannot "
                         f"convert to {canonical} (give the value in {canonical}, or in "
                         f"{canonical} with an SI prefix such as m{canonical})", path)
    return value * k
