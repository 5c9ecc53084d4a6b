"""The report's figures drawn by the calling process and worker processes on the spare CPUs.

Issue #16: drawing is most of a report's time (``figures.py``: ~0.15 s a figure, matplotlib's
per-figure floor) and used one core. :class:`FigureDrawer` starts up to :data:`MAX_WORKERS`
worker processes, one per spare CPU (``cpus.workers() - 1``; ``PMDCID_THREADS=1``: none, the
serial path), when the report has at least :data:`MIN_JOBS` figures. Workers are started with
multiprocessing's "spawn" (never fork: the caller may hold live threads and numba state), as
early as the caller can, so that their import of matplotlib and PIL (~0.7 s) overlaps the
caller's simulations. When the figures are known, the caller and the workers claim jobs from
one shared counter, each drawing with its own ``FigurePool``; a worker sends back (index, PNG)
and never writes a file. Whatever a worker does not deliver (it did not start, died, stalled for
:data:`STALL_SECONDS`, or its job raised) the caller draws itself, so the report is complete,
fails as the serial path fails, and every PNG has the serial path's bytes
(``tests/system/test_report_parallel.py``).
"""

from __future__ import annotations

import pickle
import sys
import threading
from collections.abc import Callable
from dataclasses import dataclass

#: fewer figures than this are drawn serially: a worker draws nothing until its imports are
#: done (~0.7 s, about four figures), so a one-log report's 3-4 figures would gain nothing
MIN_JOBS = 8
#: workers at most (each holds matplotlib, ~100 MB, and a copy of the figures' data)
MAX_WORKERS = 3
#: array elements (8 bytes each) sent to the workers at most; the figures of larger logs are
#: drawn by the caller, which holds their data already (a 2-million-row log carries ~16 M)
MAX_SHARED_ELEMENTS = 8_000_000
#: a worker silent this long while it holds a claimed figure is given up on [s]
STALL_SECONDS = 60.0
#: what :func:`_take` answers when the lock's holder died
STUCK = -1
#: how long one wait on the shared counter's lock lasts before checking the others live [s]
LOCK_WAIT = 1.0


@dataclass(frozen=True)
class FigureJob:
    """One PNG: ``fn(*args)`` (``fn(*args, pool=pool)`` when ``pooled``). Jobs sharing one
    ``args`` tuple are sent once; ``size`` is the number of array elements ``args`` carries."""

    name: str
    fn: Callable
    args: tuple
    pooled: bool = False
    size: int = 0


def draw(job: FigureJob, pool) -> bytes:
    return job.fn(*job.args, pool=pool) if job.pooled else job.fn(*job.args)


def spare_workers(n_jobs: int) -> int:
    """Worker processes worth starting for ``n_jobs`` figures (0: serial)."""
    from pmdcid.runtime.cpus import workers

    if n_jobs < MIN_JOBS:
        return 0
    return max(0, min(workers() - 1, MAX_WORKERS, n_jobs // MIN_JOBS))


class FigureDrawer:
    """Draws a report's :class:`FigureJob` s (module doc); a context manager owning the workers."""

    def __init__(self, n_jobs: int):
        import multiprocessing as mp

        self._procs, self._conns, self._senders, self._counter = [], [], [], None
        self._next = 0  # the next shared job when the caller claims alone
        self._used = False
        self._receivers: list[threading.Thread] = []
        self._results = None
        n = spare_workers(n_jobs)
        if not n:
            return
        import queue

        ctx = mp.get_context("spawn")
        self._results = queue.SimpleQueue()
        try:
            self._counter = ctx.Value("q", 0)  # the next shared job to claim
            for _ in range(n):
                ours, theirs = ctx.Pipe()
                proc = ctx.Process(target=_serve, args=(theirs, self._counter), daemon=True,
                                   name="pmdcid-figures")
                _start_quietly(proc)
                theirs.close()  # the worker's end lives in the worker only: EOF when it ends
                self._procs.append(proc)
                self._conns.append(ours)
                # its results are read as they come: a full pipe would stop the worker
                t = threading.Thread(target=_receive, args=(ours, self._results), daemon=True)
                t.start()
                self._receivers.append(t)
        except Exception:  # noqa: BLE001 - no worker today: whatever started helps, or serial
            if not self._procs:
                self._counter = None
        except BaseException:  # Ctrl-C while starting: no worker outlives this
            self.close()
            raise

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.close()

    def draw(self, jobs: list[FigureJob]) -> dict[str, bytes]:
        """``{job.name: PNG}`` in job order, the same bytes whoever draws them. The workers
        serve one list of jobs: a second call draws in this process."""
        from pmdcid.report.figures import FigurePool

        if self._used:
            self.close()
        self._used = True
        pool = FigurePool()
        out: list = [None] * len(jobs)
        shared = self._share(jobs)
        for k in sorted(set(range(len(jobs))) - set(shared)):  # too large to send, or no worker
            out[k] = draw(jobs[k], pool)
        j = self._claim(len(shared))
        while j is not None:
            out[shared[j]] = draw(jobs[shared[j]], pool)
            j = self._claim(len(shared))
        self._collect(shared, out)
        for k, png in enumerate(out):
            if png is None:  # not delivered, or failed there: drawn (or failing) as serially
                out[k] = draw(jobs[k], pool)
        return {job.name: png for job, png in zip(jobs, out, strict=True)}

    def _share(self, jobs) -> list[int]:
        """Send the workers the jobs within :data:`MAX_SHARED_ELEMENTS`; their indices."""
        if not self._procs:
            return []
        shared, seen, total = [], set(), 0
        for k, job in enumerate(jobs):
            size = 0 if id(job.args) in seen else job.size
            if total + size <= MAX_SHARED_ELEMENTS:
                seen.add(id(job.args))
                total += size
                shared.append(k)
        try:
            payload = pickle.dumps((_rc_params(), [jobs[k] for k in shared]),
                                   protocol=pickle.HIGHEST_PROTOCOL)
        except Exception:  # noqa: BLE001 - something not picklable: the caller draws it all
            self.close()
            return []
        for conn in self._conns:  # in threads: a worker still importing reads it later
            t = threading.Thread(target=_send, args=(conn, payload), daemon=True)
            t.start()
            self._senders.append(t)
        return shared

    def _claim(self, n: int) -> int | None:
        if self._counter is not None:
            k = _take(self._counter, n, lambda: not all(p.is_alive() for p in self._procs))
            if k != STUCK:
                return k
            # a worker died holding the counter's lock: claim alone from here (a job a live
            # worker also draws is answered twice, with the same bytes)
            self._next, self._counter = self._counter.value, None
        k, self._next = self._next, self._next + 1
        return k if k < n else None

    def _collect(self, shared: list[int], out: list) -> None:
        """Take the workers' PNGs until every shared job is answered or no worker can."""
        import queue

        waiting = {k for k in shared if out[k] is None}
        live = len(self._receivers)
        while waiting and live:
            try:
                got = self._results.get(timeout=STALL_SECONDS)
            except queue.Empty:  # a worker stalled: the caller draws the rest
                return
            if got is None:  # a worker ended
                live -= 1
                continue
            j, png = got
            out[shared[j]] = png
            waiting.discard(shared[j])

    def close(self) -> None:
        """Stop the workers (done or not) and wait for them; idempotent."""
        procs, self._procs = self._procs, []
        for p in procs:
            if p.is_alive():
                p.terminate()
        for p in procs:
            p.join(5.0)
            if p.is_alive():  # pragma: no cover - SIGTERM ignored
                p.kill()
                p.join()
        for t in self._senders + self._receivers:  # their peers are gone: they end now
            t.join()
        for conn in self._conns:
            conn.close()
        self._senders, self._receivers, self._conns, self._counter = [], [], [], None


def _take(counter, n: int, stuck: Callable[[], bool]) -> int | None:
    """The next shared job index; None: all are claimed; :data:`STUCK`: the lock stayed taken
    and ``stuck()`` says the process that may hold it is gone."""
    lock = counter.get_lock()
    while not lock.acquire(True, LOCK_WAIT):
        if stuck():
            return STUCK
    try:
        k = counter.value
        counter.value = k + 1
    finally:
        lock.release()
    return k if k < n else None


def _rc_params() -> dict | None:
    """matplotlib's settings as the caller has them (None: not imported, so as a worker's)."""
    if "matplotlib" not in sys.modules:
        return None
    import matplotlib

    rc = matplotlib.rcParams  # dict's own access: rcParams["backend"] would resolve a backend
    return {k: dict.__getitem__(rc, k) for k in dict.keys(rc) if k != "backend"}


def _send(conn, payload: bytes) -> None:
    try:
        conn.send_bytes(payload)
    except (OSError, ValueError):  # the worker ended first: the caller draws its share
        pass


def _receive(conn, results) -> None:
    """Put each (index, PNG) a worker sends into ``results``, then None when it ends."""
    try:
        while True:
            results.put(conn.recv())
    except Exception:  # noqa: BLE001 - EOF, a reset pipe, a torn message: the worker is done
        pass
    finally:
        results.put(None)


def _start_quietly(proc) -> None:
    """Start a spawn worker that neither runs the caller's ``__main__`` (an unguarded script
    would run again in it) nor takes Ctrl-C (the caller handles it): SIGINT is blocked while it
    starts, and a blocked signal stays blocked in the child."""
    import signal
    import types

    main = sys.modules.get("__main__")
    mask = hasattr(signal, "pthread_sigmask")
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT}) if mask else None
    sys.modules["__main__"] = types.ModuleType("__main__")
    try:
        proc.start()
    finally:
        if main is not None:
            sys.modules["__main__"] = main
        if mask:
            signal.pthread_sigmask(signal.SIG_SETMASK, old)


def _serve(conn, counter) -> None:  # pragma: no cover - runs in the worker process
    """The worker: import and warm up the drawing, wait for the jobs, draw what it claims."""
    import os
    import signal
    from multiprocessing import parent_process

    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        import matplotlib

        from pmdcid.report.figures import FigurePool, _new, _png

        fig, axes = _new(1, 1, 2.0)
        axes[0, 0].set_title("warm-up")
        _png(fig)  # fonts, text layout and the PNG encoder loaded before the jobs come
        rc, jobs = pickle.loads(conn.recv_bytes())
        if rc is not None:
            matplotlib.rcParams.update(rc)
        pool = FigurePool()
        parent = parent_process()
        gone = lambda: parent is not None and not parent.is_alive()  # noqa: E731
        j = _take(counter, len(jobs), gone)
        while j is not None and j != STUCK:
            try:
                png = draw(jobs[j], pool)
            except Exception:  # noqa: BLE001 - the caller draws it and reports its error
                png = None
            conn.send((j, png))
            j = _take(counter, len(jobs), gone)
    except BaseException:  # noqa: BLE001 - EOF, a broken pipe, anything: the caller draws
        pass
    finally:
        conn.close()
        os._exit(0)  # no interpreter teardown: nothing of the worker's is left to flush
