"""The kernel compiled from its generated C (``_kernel.c``), loaded without numba.

``_kernel.c`` is generated from the kernel's one source (the numba-subset Python of
:mod:`pmdcid.simulate.kernel`, :mod:`~pmdcid.simulate.terms`, :mod:`~pmdcid.simulate.layout`
and :mod:`pmdcid.identify.grid`) by :mod:`pmdcid.export.codegen` and committed (a test checks it
is current); the package's build (``setup.py``: a plain ``pip install .``) compiles it into
``_kernel.<platform suffix>`` when a C compiler is present. :func:`load` opens it with ctypes.

Why: a command runs in a fresh process, and numba costs it 0.6-0.9 s before the first
simulation (importing numba, building its typing context, loading its cache); the library loads
in about a millisecond, and ctypes releases Python's lock while it runs, so the finite-difference
Jacobian's threads (:mod:`pmdcid.fit.fdjac`) simulate on every core. :func:`load` returns
it only when the digest it was compiled with (``kernel_digest()``) is the hash of the current
sources (:func:`pmdcid.simulate.cache.sources_hash`), so an edited physics term never runs stale
code; otherwise, or when it was not built (no C compiler) or ``PMDCID_JIT=1``, the callers use
numba's JIT of the same source (:mod:`pmdcid.simulate.lazyjit`). Both compile the same
operations without fast-math or fused multiply-adds (``-ffp-contract=off``): they agree to the
bit on the tests' cases (``tests/simulate/test_compiled.py`` allows 1e-12). The batch runs its
parameter sets one after another here, on threads under the JIT.
"""

from __future__ import annotations

import ctypes
import importlib.machinery
import os
from pathlib import Path
from types import SimpleNamespace

import numpy as np

from pmdcid.simulate.layout import NAMES, NSTATE

NAME = "_kernel"
HERE = Path(__file__).resolve().parent
_LOADED: list = []
NSTATE_P = len(NAMES)
_ARRAY = ctypes.c_void_p
_INT = ctypes.c_int
_DOUBLE = ctypes.c_double
#: the library's functions: name -> (argument types, result type), as codegen writes them
SIGNATURES = {
    "run_states": ([_ARRAY, _INT, _ARRAY, _ARRAY, _ARRAY, _INT, _INT, _ARRAY, _INT, _ARRAY],
                   None),
    "discretize_into": ([_ARRAY, _DOUBLE, _INT, _ARRAY, _ARRAY], None),
    "set_cost": ([_ARRAY, _INT, _ARRAY, _ARRAY, _DOUBLE, _DOUBLE, _DOUBLE], _DOUBLE),
    "kernel_digest": ([], ctypes.c_char_p),
}


def library_path() -> Path | None:
    """The compiled library beside this file (any of this Python's extension suffixes)."""
    for suffix in importlib.machinery.EXTENSION_SUFFIXES:
        path = HERE / (NAME + suffix)
        if path.exists():
            return path
    return None


def load() -> SimpleNamespace | None:
    """The compiled functions (``run``, ``run_into``, ``discretize_into``, ``batch_cost``, with
    the signatures of the numba functions they replace), or None when not built, built from
    other sources, or ``PMDCID_JIT`` is set. Decided once per process."""
    if not _LOADED:
        _LOADED.append(_load())
    return _LOADED[0]


def _load() -> SimpleNamespace | None:
    from pmdcid.simulate.cache import sources_hash

    path = library_path()
    if os.environ.get("PMDCID_JIT") or path is None:
        return None
    try:
        lib = ctypes.CDLL(str(path))
        for name, (args, res) in SIGNATURES.items():
            fn = getattr(lib, name)
            fn.argtypes, fn.restype = args, res
        if lib.kernel_digest().decode() != sources_hash():
            return None
    except (OSError, AttributeError):
        return None
    return _functions(lib)


def _functions(lib) -> SimpleNamespace:
    """Python callables over ``lib`` with the numba functions' signatures (contiguous float64
    arrays, as the callers pass them)."""

    def run_into(u, p, Phi, Gam, nsub, torque_driven, x0, out):
        if out.shape != (len(u), NSTATE) or p.shape != (NSTATE_P,) or len(x0) < 3:
            raise ValueError("run_into: arrays of the wrong shape")
        lib.run_states(_ptr(u), len(u), _ptr(p), _ptr(Phi, (4, 3, 3)), _ptr(Gam, (4, 3, 3)),
                       int(nsub), bool(torque_driven), _ptr(x0), len(x0), _ptr(out))
        return out

    def run(u, p, Phi, Gam, nsub, torque_driven, x0):
        return run_into(u, p, Phi, Gam, nsub, torque_driven, x0, np.empty((len(u), NSTATE)))

    def discretize_into(p, h, torque_driven, Phi, Gam):
        lib.discretize_into(_ptr(p, (NSTATE_P,)), float(h), bool(torque_driven),
                            _ptr(Phi, (4, 3, 3)), _ptr(Gam, (4, 3, 3)))

    def batch_cost(u, P, Phis, Gams, nsub, torque_driven, w_meas, th_meas, sw, sth, omega0,
                   x0, bufs):
        cost = np.empty(len(P))
        out = bufs[0]
        for j in range(len(P)):
            run_into(u, P[j], Phis[j], Gams[j], nsub, torque_driven, x0[j], out)
            cost[j] = lib.set_cost(_ptr(out), len(out), _ptr(w_meas, (len(out),)),
                                   _ptr(th_meas, (len(out),)), sw, sth, omega0)
        return cost

    return SimpleNamespace(run=run, run_into=run_into, discretize_into=discretize_into,
                           batch_cost=batch_cost)


def _ptr(a: np.ndarray, shape: tuple | None = None) -> int:
    """The address of a C-contiguous float64 array (of ``shape`` when given): what the C
    functions read; anything else is refused (ctypes would read it as such)."""
    if a.dtype != np.float64 or not a.flags.c_contiguous or (shape and a.shape != shape):
        raise ValueError(f"the compiled kernel takes C-contiguous float64 arrays"
                         f"{f' of shape {shape}' if shape else ''}, not {a.dtype} {a.shape}")
    return a.ctypes.data


__all__ = ["SIGNATURES", "library_path", "load"]
