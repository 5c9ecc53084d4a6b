"""``njit`` and ``prange`` that import numba only when a compiled function is first needed.

The kernel's sources (:mod:`pmdcid.simulate.terms`, :mod:`~pmdcid.simulate.kernel`,
:mod:`pmdcid.identify.grid`) stay numba source, decorated with this module's :func:`njit`.
Importing them costs nothing: each decorated function is a :class:`Lazy` placeholder. When the
compiled C kernel (:mod:`pmdcid.simulate.compiled`) serves, numba is never imported (its import
and typing context cost a command ~0.6-0.9 s). The first time a JIT function is needed,
:func:`materialize` imports numba, decorates every placeholder with ``numba.njit`` and the same
options (``cache=True``: numba's on-disk cache as before) and puts the dispatchers, and
``numba.prange``, in place of the placeholders in the globals of every loaded ``pmdcid`` module,
so that numba resolves the names inside compiled code as before. Calling a placeholder
materializes and calls its dispatcher.
"""

from __future__ import annotations

import sys

_PENDING: list[Lazy] = []
_NUMBA = None


def prange(*args):
    """``range`` until numba is loaded; then replaced by ``numba.prange`` (see module doc)."""
    return range(*args)


class Lazy:
    """A function to be compiled with ``numba.njit(**options)`` when first needed."""

    def __init__(self, py_func, options: dict):
        self.py_func = py_func
        self.options = options
        self.dispatcher = None
        self.__name__ = py_func.__name__
        self.__qualname__ = py_func.__qualname__
        self.__module__ = py_func.__module__
        self.__doc__ = py_func.__doc__
        self.__wrapped__ = py_func

    def __call__(self, *args):
        if self.dispatcher is None:
            materialize()
        return self.dispatcher(*args)

    def __repr__(self) -> str:
        return f"<lazy njit {self.__module__}.{self.__qualname__}>"


def njit(*args, **options):
    """``@njit(...)`` as numba's: a :class:`Lazy` placeholder until numba is loaded, numba's
    dispatcher directly once it is."""
    if args and callable(args[0]) and not options:
        return njit()(args[0])

    def decorate(fn):
        if _NUMBA is not None:
            return _NUMBA.njit(**options)(fn)
        lazy = Lazy(fn, options)
        _PENDING.append(lazy)
        return lazy

    return decorate


def materialize():
    """Import numba and swap every placeholder (and :func:`prange`) for numba's objects."""
    global _NUMBA
    if _NUMBA is not None:
        return _NUMBA
    import numba

    placeholder = prange  # this module's own name is swapped too, in the loop below
    swap = {id(placeholder): numba.prange}
    for lazy in _PENDING:  # registration order: a function's callees were decorated before it
        lazy.dispatcher = numba.njit(**lazy.options)(lazy.py_func)
        swap[id(lazy)] = lazy.dispatcher
    for name, mod in list(sys.modules.items()):
        if name == "pmdcid" or name.startswith("pmdcid."):
            ns = getattr(mod, "__dict__", {})
            for key, val in list(ns.items()):
                if id(val) in swap and (val is placeholder or isinstance(val, Lazy)):
                    ns[key] = swap[id(val)]
    _PENDING.clear()
    _NUMBA = numba
    return numba


def real(fn):
    """The numba dispatcher of ``fn`` (a placeholder or already a dispatcher)."""
    if isinstance(fn, Lazy):
        materialize()
        return fn.dispatcher
    return fn


__all__ = ["Lazy", "materialize", "njit", "prange", "real"]
