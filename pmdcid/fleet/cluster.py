"""The Dask side of a fleet: a local cluster or an existing one, tasks submitted and gathered.

dask.distributed is an optional extra (``pip install 'pmdcid[fleet]'``), imported here only,
when a fleet runs. The default is a local cluster of one-thread worker processes started and
stopped with the run; ``scheduler="tcp://HOST:PORT"`` runs on a cluster started by
``dask scheduler`` / ``dask worker``. Each measurement is one task (:func:`pmdcid.fleet.task.
run_unit`); Dask reschedules a task whose worker died (``distributed.scheduler.
allowed-failures`` times), after which the measurement is a row with ``status="error"``.
Results are handed to the caller as they finish, so each is journaled at once.
"""

from __future__ import annotations

import logging
import os
import sys
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

from pmdcid.errors import PmdcidError, one_line

#: seconds to wait for a scheduler to answer, and for its first worker
CONNECT_TIMEOUT = 30.0
#: how pmdcid asks for the extra
EXTRA = "pip install 'pmdcid[fleet]'"


class ClusterError(PmdcidError):
    """The Dask cluster cannot be started or reached: nothing could run."""


def _distributed():
    try:
        import distributed
    except ImportError:
        raise ClusterError(f"pmdcid fleet needs dask.distributed: {EXTRA}") from None
    return distributed


def default_workers() -> int:
    """The CPUs this process may use (its affinity mask)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except (AttributeError, OSError):  # pragma: no cover - no affinity on this platform
        return max(1, os.cpu_count() or 1)


def worker_env() -> dict[str, str]:
    """The environment of a local cluster's workers: one compute thread each, and the folder
    this pmdcid was imported from first on their path (they run the same code as the caller)."""
    import pmdcid

    here = os.path.dirname(os.path.dirname(os.path.abspath(pmdcid.__file__)))
    path = os.pathsep.join(p for p in (here, os.environ.get("PYTHONPATH", "")) if p)
    return {"PMDCID_THREADS": "1", "PYTHONPATH": path}


@contextmanager
def client_for(scheduler: str | None = None, workers: int | None = None):
    """A ``distributed.Client``: on the scheduler at ``scheduler``, or on a local cluster of
    ``workers`` one-thread processes (default: the CPUs) closed when the block ends."""
    distributed = _distributed()
    if scheduler is not None:
        try:
            client = distributed.Client(scheduler, timeout=CONNECT_TIMEOUT,
                                        set_as_default=False)
        except (OSError, TimeoutError, ValueError) as exc:
            raise ClusterError(f"cannot reach the Dask scheduler at {scheduler}: "
                               f"{one_line(str(exc), 120)}") from None
        with client:
            _wait_for_workers(client, scheduler)
            yield client
        return
    n = workers or default_workers()
    try:
        cluster = distributed.LocalCluster(
            n_workers=n, threads_per_worker=1, processes=True, dashboard_address=":0",
            silence_logs=logging.ERROR, env=worker_env())
    except (OSError, TimeoutError, RuntimeError) as exc:
        raise ClusterError(f"cannot start a local Dask cluster of {n} workers: "
                           f"{one_line(str(exc), 120)}") from None
    with cluster, distributed.Client(cluster, set_as_default=False) as client:
        yield client


def _wait_for_workers(client, scheduler: str) -> None:
    try:
        client.wait_for_workers(1, timeout=CONNECT_TIMEOUT)
    except (OSError, TimeoutError) as exc:
        raise ClusterError(f"the Dask scheduler at {scheduler} has no workers (waited "
                           f"{CONNECT_TIMEOUT:.0f} s: start some with `dask worker "
                           f"{scheduler}`)") from exc


def run_jobs(client, jobs: list[dict], fn: Callable) -> Iterator[dict]:
    """``fn(job)`` for every job on ``client``'s cluster, yielded as each finishes (in any
    order). A job whose workers kept dying, or that raised, is yielded as an error row (not
    journaled: it runs again next time)."""
    distributed = _distributed()
    futures = {client.submit(fn, job, key=f"pmdcid-fleet-{job['key']}", pure=False): job
               for job in jobs}
    for fut in distributed.as_completed(list(futures), loop=client.loop):
        job = futures.pop(fut)
        try:
            yield fut.result()
        except Exception as exc:  # noqa: BLE001 - KilledWorker, a lost scheduler...
            yield failed_row(job, exc)
        finally:
            fut.release()


def failed_row(job: dict, exc: BaseException) -> dict:
    """The row of a job Dask could not run (its worker died, the cluster went away)."""
    why = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
    if type(exc).__name__ == "KilledWorker":
        why = "its worker died every time it ran (out of memory, or a crash)"
    row = {k: job[k] for k in ("key", "unit", "time", "logs", "hashes")}
    row.update(status="error", error=one_line(f"{type(exc).__name__}: {why}"), params={},
               effects=[], lumped=False, warnings=[], journal=False, seconds=float("nan"))
    return row


class Bar:
    """A one-line progress bar on stderr when stderr is a terminal (silent otherwise)."""

    def __init__(self, total: int, stream=None):
        self.stream = stream if stream is not None else sys.stderr
        isatty = getattr(self.stream, "isatty", None)
        self.on = bool(isatty and isatty()) and total > 0
        self.total, self.done, self.errors = total, 0, 0
        self.t0 = time.monotonic()

    def update(self, row: dict) -> None:
        self.done += 1
        self.errors += row.get("status") != "ok"
        if not self.on:
            return
        width = 30
        full = int(width * self.done / self.total)
        rate = self.done / max(time.monotonic() - self.t0, 1e-9) * 3600.0
        self.stream.write(f"\r[{'#' * full}{'.' * (width - full)}] {self.done}/{self.total} "
                          f"units, {self.errors} errors, {rate:.0f}/h ")
        if self.done == self.total:
            self.stream.write("\n")
        self.stream.flush()


__all__ = ["Bar", "ClusterError", "client_for", "default_workers", "failed_row", "run_jobs",
           "worker_env"]
