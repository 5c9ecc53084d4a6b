"""The compiled kernel ahead of time: a plain extension module, loaded without numba.

:func:`main` (``make aot``, run by ``make install``, ``test``, ``bench`` and ``demo`` when a
source changed) compiles the kernel's numba
functions, each from its unchanged source (:data:`EXPORTS`), with numba's ahead-of-time compiler
(``numba.pycc``) into ``pmdcid/simulate/_compiled.*.so``, stamped with the hash of the sources it
was made from.

Why: a command runs in a fresh process, and numba costs it 0.6-0.9 s before the first
simulation (importing numba, building its typing context, which imports scipy.linalg, loading
the cache); the extension module loads in about a millisecond. :func:`load` returns it only when
its stamp matches the current sources, so an edited physics term never runs stale code;
otherwise, or when it was not built (no C compiler, a numba without ``numba.pycc``, or
``PMDCID_JIT=1``), the callers use numba's JIT as before (:mod:`pmdcid.simulate.lazyjit`).
Both are LLVM code of the same source without fast-math and give the same bits
(``tests/test_aot.py``). The batch runs its parameter sets one after another here (``prange`` is
a plain loop ahead of time), on threads under the JIT; each set's cost is summed in the same
order.
"""

from __future__ import annotations

import hashlib
import importlib
import os
import sys
from pathlib import Path
from types import SimpleNamespace

NAME = "_compiled"
HERE = Path(__file__).resolve().parent
STAMP = HERE / f"{NAME}.sha1"
#: exported name -> (module, numba function, signature: contiguous float64 arrays, as the
#: callers pass them)
EXPORTS = {
    "run": ("pmdcid.simulate.kernel", "_run",
            "f8[:,::1](f8[::1], f8[::1], f8[:,:,::1], f8[:,:,::1], i8, b1, f8[::1])"),
    "discretize_into": ("pmdcid.simulate.kernel", "discretize_into",
                        "void(f8[::1], f8, b1, f8[:,:,::1], f8[:,:,::1])"),
    "batch_cost": ("pmdcid.identify.grid", "_batch_cost",
                   "f8[::1](f8[::1], f8[:,::1], f8[:,:,:,::1], f8[:,:,:,::1], i8, b1, f8[::1], "
                   "f8[::1], f8, f8, f8, f8[::1], f8[:,:,::1])"),
    "run_into": ("pmdcid.simulate.kernel", "_run_into",
                 "f8[:,::1](f8[::1], f8[::1], f8[:,:,::1], f8[:,:,::1], i8, b1, f8[::1], "
                 "f8[:,::1])"),
}
_LOADED: list = []


def digest() -> str:
    """Hash of the compiled functions' sources (:mod:`pmdcid.simulate.cache`) and this file."""
    from pmdcid.simulate.cache import sources_hash

    return hashlib.sha1((sources_hash() + "\n").encode() + Path(__file__).read_bytes()).hexdigest()


def load() -> SimpleNamespace | None:
    """The ahead-of-time functions (attributes as :data:`EXPORTS`), or None when not built,
    built from other sources, or ``PMDCID_JIT`` is set. Decided once per process."""
    if not _LOADED:
        _LOADED.append(_load())
    return _LOADED[0]


def _load() -> SimpleNamespace | None:
    if os.environ.get("PMDCID_JIT"):  # force numba's JIT (tests comparing the two)
        return None
    try:
        if STAMP.read_text().strip() != digest():
            return None
        mod = importlib.import_module(f"pmdcid.simulate.{NAME}")
        return SimpleNamespace(**{k: getattr(mod, k) for k in EXPORTS})
    except (OSError, ImportError, AttributeError):
        return None


def jit() -> SimpleNamespace:
    """numba's JIT versions of :data:`EXPORTS` (compiled, or loaded from numba's cache)."""
    from pmdcid.simulate.lazyjit import real

    return SimpleNamespace(**{k: real(getattr(importlib.import_module(m), f))
                              for k, (m, f, _) in EXPORTS.items()})


def build(out_dir: Path = HERE) -> Path:
    """Compile the extension module into ``out_dir`` and stamp it; returns its path."""
    import warnings

    from pmdcid.simulate.lazyjit import materialize

    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # numba.pycc's pending-deprecation notice
        from numba.pycc import CC

    stamp = out_dir / STAMP.name
    stamp.unlink(missing_ok=True)
    functions = jit()  # every module imported and its placeholders swapped for numba's
    materialize()
    _release_gil_in_wrappers()
    cc = CC(NAME)
    cc.output_dir = str(out_dir)
    cc.verbose = False
    for name, (_, _, sig) in EXPORTS.items():
        cc.export(name, sig)(getattr(functions, name).py_func)
    cc.compile()
    stamp.write_text(digest() + "\n")
    return Path(cc.output_file)


def _release_gil_in_wrappers() -> None:
    """Make ``numba.pycc`` compile its Python wrappers as ``nogil=True`` does for the JIT: the
    kernel then runs without Python's lock, so that threads (the finite-difference Jacobian's
    columns, :mod:`pmdcid.identify.fdjac`) simulate on both cores. ``pycc`` has no option for
    it; its compile flags are numba's ``Flags``, whose ``release_gil`` the wrapper honours. A
    numba where this fails builds a module that holds the lock: correct, one core."""
    try:
        from numba.core.compiler import Flags
        from numba.pycc import compiler

        if getattr(compiler.Flags, "_pmdcid_nogil", False):
            return

        class NoGilFlags(Flags):
            _pmdcid_nogil = True

            def __init__(self, *args, **kwargs):
                super().__init__(*args, **kwargs)
                self.release_gil = True

        compiler.Flags = NoGilFlags
    except (ImportError, AttributeError):  # pragma: no cover - a numba laid out otherwise
        pass


def main() -> int:
    try:
        path = build()
    except Exception as exc:  # noqa: BLE001 - optional: the JIT serves when this fails
        why = f"{type(exc).__name__}: {exc}".splitlines()[0][:200]
        print(f"pmdcid: ahead-of-time kernel not built ({why}); numba's JIT will be used",
              file=sys.stderr)
        STAMP.write_text(f"not built: {why}\n")  # matches no hash; make will not retry
        return 0
    print(f"pmdcid: built {path.name}")
    return 0
