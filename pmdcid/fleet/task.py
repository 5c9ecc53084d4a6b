"""One measurement identified on a Dask worker: the task the fleet submits per unit.

:func:`run_unit` calls :func:`pmdcid.files.run_identify`, the function ``pmdcid identify``
runs, on the measurement's log files with the fleet's options, writing the model into a
temporary folder of the worker; the parameters are the same bits as a lone ``pmdcid identify``
of those logs gives (every fit is bit for bit the same for any number of threads,
:mod:`pmdcid.runtime.cpus`). It never raises for a unit's own problem: a
:class:`~pmdcid.errors.PmdcidError` becomes a row with ``status="error"`` and the one-line
message, so the other units go on.

The worker's logs are read from the manifest's paths (on a cluster, the workers see the same
files: a shared folder), each checked against the content hash the client computed, so a
result is never attributed to other bytes than those the journal names.
"""

from __future__ import annotations

import os
import tempfile
import time
import warnings

from pmdcid.errors import PmdcidError, PmdcidWarning, one_line


def _threads_per_task() -> None:
    """A worker process computes with as many threads as Dask gives it tasks at once
    (``PMDCID_THREADS``, unless set): N one-thread workers on N CPUs do not each start
    helper threads on every CPU."""
    if os.environ.get("PMDCID_THREADS"):
        return
    try:
        from distributed import get_worker

        n = get_worker().state.nthreads
    except (ImportError, ValueError, AttributeError):
        return
    os.environ["PMDCID_THREADS"] = str(max(1, int(n)))


def _check_logs(job: dict) -> None:
    from pmdcid.errors import LogError
    from pmdcid.fleet.journal import file_hash

    for path, want in zip(job["logs"], job["hashes"], strict=True):
        if not os.path.isfile(path):
            raise LogError("not found on the worker's host (a cluster's workers need the logs "
                           "at the manifest's paths: a shared folder)", path)
        if file_hash(path) != want:
            raise LogError("changed while the fleet ran (its content hash differs from the "
                           "one read at the start)", path)


def _identify(job: dict) -> dict:
    """The identified model of one measurement as ``{params, effects, lumped, warnings}``."""
    from pmdcid.files import run_identify
    from pmdcid.model.lumped import is_lumped

    with tempfile.TemporaryDirectory(prefix="pmdcid-fleet-") as tmp, \
            warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always", PmdcidWarning)
        res = run_identify(list(job["logs"]), os.path.join(tmp, "model.json"), None,
                           job.get("mapping"), km=job.get("km"),
                           run_diagnose=job.get("diagnose", True), progress=None)
    params = {name: [p.value, p.stderr, p.unit, *(p.interval or ())]
              for name, p in res.model.parameters.items()}
    said = [one_line(str(w.message)) for w in caught if issubclass(w.category, PmdcidWarning)]
    return {"params": params, "effects": list(res.model.effects),
            "lumped": bool(is_lumped(res.model)), "warnings": said + list(res.warnings)}


def run_unit(job: dict) -> dict:
    """Identify one measurement (module doc). ``job``: ``key``, ``unit``, ``time`` (ISO text
    or None), ``logs`` (paths), ``hashes`` (their SHA-256), and the options ``km`` [N m/A],
    ``diagnose``, ``mapping``. Returns the row: the job's fields, ``status`` (``ok`` or
    ``error``), ``error`` (one line), ``params`` (name -> [value, stderr, unit], and low, high
    where the logs only bound it), ``effects``,
    ``lumped``, ``warnings``, ``seconds`` (wall time of the task [s]), ``cpu_seconds`` (CPU
    time of its thread [s]: one-thread workers) and ``journal``
    (False for a failure that may not happen again: an internal error)."""
    import pmdcid

    _threads_per_task()
    t0, c0 = time.perf_counter(), time.thread_time()
    row = {k: job[k] for k in ("key", "unit", "time", "logs", "hashes")}
    row.update(status="ok", error="", params={}, effects=[], lumped=False, warnings=[],
               journal=True, version=pmdcid.__version__)
    try:
        _check_logs(job)
        row.update(_identify(job))
    except PmdcidError as exc:
        row.update(status="error", error=one_line(str(exc)))
    except Exception as exc:  # noqa: BLE001 - a bug must not stop the fleet: said, not journaled
        msg = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
        row.update(status="error", journal=False,
                   error=one_line(f"internal error {type(exc).__name__}: {msg[:160]}"))
    row["seconds"] = time.perf_counter() - t0
    row["cpu_seconds"] = time.thread_time() - c0
    return row


__all__ = ["run_unit"]
