"""The fleet's journal: one result file per measurement, so that a run can be resumed.

Each measurement's key is a SHA-256 over its unit, its time, the content of its log files and
the options it ran with (``--km``, diagnose, the column mapping, the pmdcid version): the same
logs with the same options give the same key, a changed byte or option a new one. A finished
measurement is committed as ``DIR/results/<key>.json`` through a temporary file, ``fsync`` and
a rename, so a result file is whole or absent whatever moment the run is killed at; the summary
table is rebuilt from the files whose keys the manifest asks for, so a row is never lost or
doubled. The journal is not part of the command's all-or-nothing transaction
(:mod:`pmdcid.runtime.outputs`): it is what a failed or killed run leaves for the next one.
"""

from __future__ import annotations

import hashlib
import json
import os
import tempfile
from contextlib import contextmanager

from pmdcid.errors import LogError

#: the journal's folder inside DIR
RESULTS = "results"
#: bytes read at a time when hashing a log
CHUNK = 1 << 20


def file_hash(path: str) -> str:
    """SHA-256 of the file's bytes (hex)."""
    h = hashlib.sha256()
    with open(path, "rb") as fh:
        for block in iter(lambda: fh.read(CHUNK), b""):
            h.update(block)
    return h.hexdigest()


def measurement_key(unit: str, time: str | None, hashes: list[str], options: dict) -> str:
    """The journal key of one measurement (module doc): hex SHA-256."""
    doc = json.dumps({"unit": unit, "time": time, "logs": hashes, "options": options},
                     sort_keys=True)
    return hashlib.sha256(doc.encode()).hexdigest()


def results_dir(out_dir: str) -> str:
    return os.path.join(out_dir, RESULTS)


def load(out_dir: str, keys) -> dict[str, dict]:
    """The committed results among ``keys`` (key -> row); a file that cannot be read as a
    result is ignored (its measurement runs again)."""
    found = {}
    for key in keys:
        p = os.path.join(results_dir(out_dir), f"{key}.json")
        try:
            with open(p, encoding="utf-8") as fh:
                row = json.load(fh)
        except (OSError, ValueError):
            continue
        if isinstance(row, dict) and row.get("key") == key:
            found[key] = row
    return found


def commit(out_dir: str, row: dict) -> None:
    """Write ``row`` as its measurement's result file, whole or not at all (module doc)."""
    from pmdcid.runtime.signals import IN_FLIGHT, sigterm_deferred

    folder = results_dir(out_dir)
    os.makedirs(folder, exist_ok=True)
    data = json.dumps(row, sort_keys=True, allow_nan=True).encode()
    with sigterm_deferred():
        fd, tmp = tempfile.mkstemp(prefix=f".{row['key'][:16]}.", suffix=".tmp", dir=folder)
        IN_FLIGHT.add(tmp)
    try:
        with os.fdopen(fd, "wb") as fh:
            fh.write(data)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, os.path.join(folder, f"{row['key']}.json"))
        _fsync_dir(folder)
    except OSError as exc:
        raise LogError(f"cannot write a result ({exc.strerror or exc})", folder) from None
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
        IN_FLIGHT.discard(tmp)


def _fsync_dir(folder: str) -> None:
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


@contextmanager
def exclusive(out_dir: str):
    """Hold DIR for one fleet run: a second run on the same DIR stops at once with one line
    instead of computing the same units beside it (a non-blocking ``flock`` on the folder)."""
    try:
        import fcntl
    except ImportError:  # pragma: no cover - not POSIX: no lock
        yield
        return
    fd = os.open(out_dir, os.O_RDONLY)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            raise LogError("another pmdcid fleet is running on this folder; wait for it or "
                           "choose another -o", out_dir) from None
        yield
    finally:
        os.close(fd)


__all__ = ["commit", "exclusive", "file_hash", "load", "measurement_key", "results_dir"]
