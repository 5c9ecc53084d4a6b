"""End-of-line limits: ``{"R": [min, max], ...}`` (JSON; ``null`` for an open side).

A unit passes when every limited parameter was identified and lies within its limits
(inclusive), on the unit's own estimate; ``failed`` names the others (a parameter the unit
lacks fails as ``name (missing)``, one its logs only bound passes when its whole interval lies
within the limits, else fails as ``name (only bounded: LOW to HIGH)``; a unit that could not be
identified fails as a whole).
"""

from __future__ import annotations

import json
import math

from pmdcid.errors import LogError

#: the ``failed`` text of a unit that could not be identified
NOT_IDENTIFIED = "not identified"


def _bound(v, name: str, path: str) -> float | None:
    if v is None:
        return None
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise LogError(f"limit of {name}: {v!r} is not a finite number or null", path)
    return float(v)


def read_limits(path: str) -> dict[str, tuple[float | None, float | None]]:
    """The limits file as ``name -> (min, max)``; a malformed file raises LogError naming it."""
    from pmdcid.io.text import read_text
    from pmdcid.model.effects import param_spec

    try:
        obj = json.loads(read_text(path))
    except (OSError, UnicodeDecodeError) as exc:
        raise LogError(f"cannot read the limits file ({getattr(exc, 'strerror', None) or exc})",
                       path) from None
    except ValueError as exc:
        raise LogError(f"the limits file is not JSON ({exc})", path) from None
    if not isinstance(obj, dict) or not obj:
        raise LogError('the limits file must be an object like {"R": [2.2, 2.6]}', path)
    out = {}
    for name, pair in obj.items():
        if param_spec(name) is None:
            raise LogError(f"limit of {name!r}: no such parameter (see docs/effects.md)", path)
        if not isinstance(pair, list) or len(pair) != 2:
            raise LogError(f"limit of {name}: give [min, max] (null for an open side)", path)
        lo, hi = (_bound(v, name, path) for v in pair)
        if lo is not None and hi is not None and lo > hi:
            raise LogError(f"limit of {name}: min {lo:g} is above max {hi:g}", path)
        out[name] = (lo, hi)
    return out


def check(row: dict, limits: dict) -> tuple[bool, list[str]]:
    """(pass, failed parameters) of one row (module doc)."""
    if row.get("status") != "ok":
        return False, [NOT_IDENTIFIED]
    failed = []
    for name, (lo, hi) in limits.items():
        got = row["params"].get(name)
        v = float(got[0]) if got is not None and got[0] is not None else math.nan
        # a parameter the logs only bound passes when its whole interval does
        low, high = (float(got[3]), float(got[4])) if got is not None and len(got) > 3 else (v, v)
        if not math.isfinite(v):
            failed.append(f"{name} (missing)")
        elif (lo is not None and low < lo) or (hi is not None and high > hi):
            failed.append(name if low == high else f"{name} (only bounded: {low:.3g} to "
                                                    f"{high:.3g})")
    return not failed, failed


__all__ = ["NOT_IDENTIFIED", "check", "read_limits"]
