"""The one vocabulary of log kinds: what ``plan`` writes, ``identify`` sorts, ``simulate`` keeps
and honours, and the report names.

A log may say what it is in a ``# kind:`` comment. Every spelling a user or an earlier version
wrote (``slow_triangle``, ``Slow-Triangle``, ``free-speed-step``) is read as one canonical kind
(:func:`canonical`), and each canonical kind has one use in ``identify`` (:func:`stage_class`):

- ``blocked``: the rotor held, a voltage step -> R, L (fit-electrical);
- ``step``: an input held at levels long enough for the speed to settle (free-speed steps,
  staircases, levels, small steps) -> fit-mechanical finds every step, then the joint fit;
- ``rich``: an input that keeps changing (ramps, triangles, sines, chirps, PRBS) -> fit-nonlinear
  and the joint fit.

Unknown kinds are kept as written and sorted by what the input does.
"""

from __future__ import annotations

#: canonical kind -> (identify's class, what it is, in words)
KINDS: dict[str, tuple[str, str]] = {
    "blocked-rotor": ("blocked", "blocked-rotor voltage step (rotor held)"),
    "free-speed-step": ("step", "free-speed voltage step"),
    "steps": ("step", "free steps in both directions"),
    "small-steps": ("step", "small steps up and back to rest"),
    "staircase": ("step", "staircase of held levels"),
    "levels": ("step", "levels held until the speed settles"),
    "triangle": ("rich", "triangle"),
    "slow-triangle": ("rich", "slow triangle"),
    "ramp": ("rich", "ramp"),
    "prbs": ("rich", "pseudo-random binary sequence"),
    "aprbs": ("rich", "amplitude-modulated pseudo-random sequence"),
    "sine": ("rich", "sine"),
    "chirp": ("rich", "chirp"),
    "rich": ("rich", "varied input"),
}

#: other spellings -> canonical kind
ALIASES = {
    "blocked": "blocked-rotor", "blocked-step": "blocked-rotor", "locked-rotor": "blocked-rotor",
    "stall": "blocked-rotor", "step": "free-speed-step", "free-step": "free-speed-step",
    "stair": "staircase", "stairs": "staircase", "level": "levels", "small-step": "small-steps",
    "sinus": "sine", "sweep": "chirp",
}

#: identify's classes, in the order the stages use them
CLASSES = ("blocked", "step", "rich")


def canonical(kind: str | None) -> str | None:
    """The canonical spelling of a ``# kind:`` value (lower case, ``-`` for ``_`` and spaces);
    None for no kind. An unknown kind comes back normalised, not refused."""
    if kind is None:
        return None
    k = "-".join(str(kind).strip().lower().replace("_", "-").split())
    if not k:
        return None
    return ALIASES.get(k, k)


def stage_class(kind: str | None) -> str | None:
    """identify's class of a kind (``blocked``, ``step``, ``rich``), None when unknown (the log
    is then sorted by its content)."""
    entry = KINDS.get(canonical(kind) or "")
    if entry is not None:
        return entry[0]
    k = canonical(kind) or ""
    return "blocked" if "block" in k else None


def is_blocked(kind: str | None) -> bool:
    """True for a kind that says the rotor was held."""
    return stage_class(kind) == "blocked"


def describe(kind: str | None) -> str:
    """A kind in words (the canonical name when unknown)."""
    k = canonical(kind)
    return KINDS[k][1] if k in KINDS else (k or "no kind")


__all__ = ["ALIASES", "CLASSES", "KINDS", "canonical", "describe", "is_blocked", "stage_class"]
