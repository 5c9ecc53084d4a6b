"""Independent simulations on the CPUs this process may use, without oversubscribing them.

The fits' costly work comes in independent pieces: the finite-difference Jacobian's columns
(:mod:`.fdjac`), a diagnose candidate's starts, the candidates of a diagnose round. The compiled
kernel releases Python's lock (:mod:`pmdcid.simulate.compiled`), so threads simulate on several
cores at once.

:func:`pmap` maps a function over such pieces: the calling thread works through them itself,
and each *spare CPU* (a token; :func:`workers` CPUs in all, the caller holding one) that is free
at the call lends a helper thread. Nested maps (a candidate's Jacobian) take only the tokens
still free, so at most :func:`workers` threads compute at any time; a caller waiting for its
helpers' last pieces lends its own token meanwhile. Each piece is computed by the same code
whichever thread runs it and results come back in order, so every fit is bit for bit the same
for any number of threads. ``PMDCID_THREADS=1`` (or a single CPU) runs everything serially in
the calling thread.

An interrupt (Ctrl-C, SIGTERM, SIGHUP: an exception that ends the command) stops the work
promptly: no thread takes another piece of any map (:data:`CANCEL`), a helper thread's nested
map raises :class:`Cancelled` at once, and the caller re-raises the interrupt as soon as the
helpers have left the piece they were in.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable, Sequence

_STATE: dict = {}
_LOCK = threading.Lock()
#: set by an interrupt: every map stops handing out pieces (cleared by the next top-level map)
CANCEL = threading.Event()
_DEPTH = threading.local()
#: the names of the helper threads
PREFIX = "pmdcid-cpu"


class Cancelled(Exception):
    """A map was cancelled by an interrupt elsewhere (see module doc)."""


def _interrupt(exc: BaseException) -> bool:
    """Whether ``exc`` ends the command (Ctrl-C, SIGTERM/SIGHUP's exception, exit)."""
    from pmdcid.runtime.signals import Terminated

    return isinstance(exc, (KeyboardInterrupt, SystemExit, Terminated, Cancelled))


def workers() -> int:
    """CPUs to compute on: those of this process's affinity mask (``os.sched_getaffinity``),
    at most ``PMDCID_THREADS`` when set to a positive integer (1: serial)."""
    try:
        n = len(os.sched_getaffinity(0))
    except (AttributeError, OSError):  # pragma: no cover - platforms without affinity
        n = os.cpu_count() or 1
    env = os.environ.get("PMDCID_THREADS", "").strip()
    if env:
        try:
            n = min(n, max(1, int(env)))
        except ValueError:  # not an integer: the user's setting ignored, every usable CPU
            pass
    return max(1, n)


def _spares(n: int):
    """(semaphore of the n - 1 spare CPUs, helper executor), made once per worker count."""
    with _LOCK:
        if _STATE.get("n") != n:
            from concurrent.futures import ThreadPoolExecutor

            _STATE.update(n=n, sem=threading.Semaphore(n - 1),
                          pool=ThreadPoolExecutor(4 * n, thread_name_prefix=PREFIX))
        return _STATE["sem"], _STATE["pool"]


def pmap(fn: Callable, items: Sequence, parallel: bool = True) -> list:
    """``[fn(x) for x in items]``, the pieces shared with the spare CPUs free at the call
    (module doc). The first exception in item order is raised after every piece has run; an
    interrupt at once (module doc)."""
    items = list(items)
    helper = threading.current_thread().name.startswith(PREFIX)
    depth = getattr(_DEPTH, "n", 0)
    if not helper and depth == 0:
        CANCEL.clear()  # a new piece of work: an earlier interrupt is over
    elif CANCEL.is_set():
        raise Cancelled()
    _DEPTH.n = depth + 1
    try:
        return _pmap(fn, items, workers() if parallel else 1)
    finally:
        _DEPTH.n = depth


def _pmap(fn: Callable, items: list, n: int) -> list:
    if n < 2 or len(items) < 2:
        return [fn(x) for x in items]
    sem, pool = _spares(n)
    results: list = [None] * len(items)
    errors: list = [None] * len(items)
    order = iter(range(len(items)))
    take_lock = threading.Lock()

    def take():
        with take_lock:
            return None if CANCEL.is_set() else next(order, None)

    def work():
        k = take()
        while k is not None:
            try:
                results[k] = fn(items[k])
            except BaseException as exc:  # noqa: BLE001 - re-raised in the caller, in order
                errors[k] = exc
                if _interrupt(exc):
                    CANCEL.set()
            k = take()

    def helper():
        try:
            work()
        finally:
            sem.release()

    helpers = []
    for _ in range(min(n - 1, len(items) - 1)):
        if not sem.acquire(blocking=False):
            break
        helpers.append(pool.submit(helper))
    work()
    if helpers:
        sem.release()  # lend this thread's CPU while the helpers finish their pieces
        try:
            _wait(helpers)
        finally:
            sem.acquire()
    first = next((e for e in errors if e is not None and _interrupt(e)), None)
    first = first or next((e for e in errors if e is not None), None)
    if first is not None:
        raise first
    return results


def _wait(helpers) -> None:
    """Wait for the helpers; an interrupt meanwhile cancels their remaining pieces, and is
    raised once they have left the piece they were in."""
    try:
        for h in helpers:
            h.result()
    except BaseException:
        CANCEL.set()
        for h in helpers:
            h.exception()
        raise


__all__ = ["pmap", "workers"]
