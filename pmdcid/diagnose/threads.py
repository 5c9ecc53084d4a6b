"""One BLAS thread while diagnose runs.

Diagnose makes thousands of tiny linear-algebra calls (the kernel's 6x6 matrix exponentials)
between larger ones; OpenBLAS's thread pool, woken by the large ones, makes the tiny ones up to a
thousand times slower on a loaded machine (measured: 7 us -> 8 ms per exponential). The large
ones are small enough to run well on one thread. Uses threadpoolctl when installed, otherwise the
set/get functions of the OpenBLAS libraries numpy and scipy have loaded.
"""

from __future__ import annotations

import contextlib
import ctypes

_PAIRS = (("scipy_openblas_set_num_threads64_", "scipy_openblas_get_num_threads64_"),
          ("scipy_openblas_set_num_threads", "scipy_openblas_get_num_threads"),
          ("openblas_set_num_threads", "openblas_get_num_threads"))


def _openblas_libs():
    """(set, get) function pairs of every OpenBLAS library loaded in this process."""
    paths = set()
    try:
        with open("/proc/self/maps") as fh:
            for line in fh:
                p = line.split()[-1]
                name = p.rsplit("/", 1)[-1].lower()
                if "openblas" in name and (".so" in name or name.endswith(".dylib")):
                    paths.add(p)
    except OSError:
        return []
    out = []
    for p in sorted(paths):
        try:
            lib = ctypes.CDLL(p)
        except OSError:
            continue
        for s, g in _PAIRS:
            if hasattr(lib, s) and hasattr(lib, g):
                out.append((getattr(lib, s), getattr(lib, g)))
                break
    return out


@contextlib.contextmanager
def single_blas_thread():
    """Context manager: BLAS limited to one thread inside, restored after."""
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        threadpool_limits = None
    if threadpool_limits is not None:
        with threadpool_limits(limits=1, user_api="blas"):
            yield
        return
    libs = _openblas_libs()
    saved = []
    for set_, get in libs:
        try:
            saved.append((set_, int(get())))
            set_(1)
        except Exception:  # pragma: no cover - an unexpected library: leave it alone
            continue
    try:
        yield
    finally:
        for set_, n in saved:
            set_(n)
