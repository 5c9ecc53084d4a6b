"""Keep numba's on-disk cache of the compiled kernel true to the source.

numba (``cache=True``) re-compiles a function when *its own* file changes, not when a function
it inlines from another module does: editing a physics term in :mod:`pmdcid.simulate.terms` or
the parameter layout would leave the kernel (and the batch grid of fit-nonlinear) running the old
compiled code. At import, before anything is compiled, a hash of those sources is compared with
the one stored beside the cache; when it differs the cached machine code is removed, so the
next call compiles afresh. A read-only install (no write access) is left alone.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

_PKG = Path(__file__).resolve().parent.parent
#: sources the compiled functions inline, and the folders holding their cached machine code
SOURCES = ("simulate/terms.py", "simulate/layout.py", "simulate/kernel.py", "identify/grid.py")
CACHE_DIRS = ("simulate/__pycache__", "identify/__pycache__")
STAMP = "simulate/__pycache__/pmdcid-kernel-sources.sha1"


def sources_hash() -> str:
    h = hashlib.sha1()
    for rel in SOURCES:
        try:
            h.update((_PKG / rel).read_bytes())
        except OSError:
            h.update(rel.encode())
    return h.hexdigest()


def invalidate_if_stale() -> bool:
    """Remove cached compiled code made from other sources; True when something was removed."""
    stamp = _PKG / STAMP
    digest = sources_hash()
    try:
        if stamp.read_text().strip() == digest:
            return False
    except OSError:
        pass
    removed = False
    try:
        for d in CACHE_DIRS:
            for f in (_PKG / d).glob("*.nb[ic]"):
                f.unlink()
                removed = True
        stamp.parent.mkdir(parents=True, exist_ok=True)
        stamp.write_text(digest + "\n")
    except OSError:
        pass
    return removed


__all__ = ["invalidate_if_stale", "sources_hash"]
