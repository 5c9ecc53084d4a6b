"""What a command writes: all or nothing, never over a stranger's file, one writer at a time.

- :func:`transaction`: the command-line edge runs every command inside one. Each file the
  command replaces is kept (a hard link to the old version) and each file or folder it creates
  is noted; when the command fails -- any error, a full disk, stdout closed under the final
  message (EPIPE), SIGTERM -- the old versions come back and the new files go. Exit 0 means
  every promised file was written; a non-zero exit leaves nothing new behind.
- :func:`install_sigterm`: SIGTERM becomes an exception, so in-flight temporary files are
  removed and the transaction rolled back like any other failure.
- :func:`locked`: an exclusive ``flock`` on the folder holding a model, for a stage's
  read-modify-write of the model file (two stages on one model both land their updates).
- :func:`check_overwrite`: an existing output that is not what pmdcid writes there (a model,
  a diagnose summary) is only replaced with ``--force``.
"""

from __future__ import annotations

import json
import os
import shutil
import signal
import tempfile
import threading
from contextlib import contextmanager

from pmdcid.errors import LogError

#: the running command's transaction (None outside the command-line edge: writes are final)
_CURRENT: list[Transaction] = []
#: temporary files being written right now (removed on SIGTERM)
IN_FLIGHT: set[str] = set()
#: files larger than this are never taken for a model or a summary
MAX_OURS_BYTES = 50 << 20


class Transaction:
    """Old versions of replaced files and the list of created ones (see module doc)."""

    def __init__(self):
        self.backups: dict[str, str | None] = {}  # real path -> backup path (None: was absent)
        self.dirs: list[str] = []

    def before_replace(self, real: str) -> None:
        if real in self.backups:
            return
        if not os.path.exists(real):
            self.backups[real] = None
            return
        with sigterm_deferred():  # the backup is registered before a SIGTERM can act
            fd, bak = tempfile.mkstemp(prefix=f".{os.path.basename(real)}.",
                                       suffix=".undo.tmp", dir=os.path.dirname(real) or ".")
            os.close(fd)
            os.unlink(bak)
            try:
                os.link(real, bak)
            except OSError:
                shutil.copy2(real, bak)
            IN_FLIGHT.add(bak)
            self.backups[real] = bak

    def created_dir(self, path: str) -> None:
        self.dirs.append(os.path.realpath(path))

    def rollback(self) -> None:
        for real, bak in self.backups.items():
            try:
                if bak is None:
                    if os.path.exists(real):
                        os.unlink(real)
                else:
                    os.replace(bak, real)
                    IN_FLIGHT.discard(bak)
            except OSError:
                pass
        for d in reversed(self.dirs):
            shutil.rmtree(d, ignore_errors=True)
        self.backups, self.dirs = {}, []

    def commit(self) -> None:
        for bak in self.backups.values():
            if bak is not None:
                try:
                    os.unlink(bak)
                except OSError:
                    pass
                IN_FLIGHT.discard(bak)
        self.backups, self.dirs = {}, []


@contextmanager
def transaction():
    """Run the block as one all-or-nothing command (see module doc)."""
    tr = Transaction()
    _CURRENT.append(tr)
    ok = False
    try:
        yield tr
        ok = True
    except SystemExit as exc:
        ok = exc.code in (0, None)
        raise
    except BaseException as exc:
        ok = type(exc).__name__ == "Exit" and getattr(exc, "exit_code", 1) == 0  # click's Exit
        raise
    finally:
        _CURRENT.remove(tr)
        tr.commit() if ok else tr.rollback()


def current() -> Transaction | None:
    return _CURRENT[-1] if _CURRENT else None


@contextmanager
def sigterm_deferred():
    """SIGTERM held back for the block (main thread, POSIX): a temporary file created and
    registered in :data:`IN_FLIGHT` inside it is never left behind by a SIGTERM arriving between
    the two (the signal is delivered, and the file removed, once the block ends)."""
    mask = getattr(signal, "pthread_sigmask", None)
    if mask is None or threading.current_thread() is not threading.main_thread():
        yield
        return
    old = mask(signal.SIG_BLOCK, {signal.SIGTERM})
    try:
        yield
    finally:
        mask(signal.SIG_SETMASK, old)


class Terminated(Exception):
    """SIGTERM arrived: unwind, clean up, exit 143."""


def install_sigterm() -> None:
    """Turn SIGTERM into :class:`Terminated` (main thread only; a no-op elsewhere)."""
    if threading.current_thread() is not threading.main_thread():
        return

    def handler(signum, frame):
        for tmp in list(IN_FLIGHT):
            if not tmp.endswith(".undo.tmp"):  # backups are restored by the rollback
                try:
                    os.unlink(tmp)
                except OSError:
                    pass
        raise Terminated()

    try:
        signal.signal(signal.SIGTERM, handler)
    except (ValueError, OSError):
        pass


@contextmanager
def locked(path):
    """Exclusive lock on the folder of ``path`` for the block (no lock file is left behind)."""
    folder = os.path.dirname(os.path.realpath(path)) or "."
    try:
        import fcntl

        fd = os.open(folder, os.O_RDONLY)
    except (ImportError, OSError):
        yield
        return
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)
        yield
    finally:
        os.close(fd)


def _json_object(path: str):
    from pmdcid.io.text import read_text

    try:
        if os.path.getsize(path) > MAX_OURS_BYTES:
            return None
        obj = json.loads(read_text(path))
    except (OSError, ValueError, RecursionError):
        return None
    return obj if isinstance(obj, dict) else None


def check_overwrite(path, kind: str, force: bool = False, option: str = "-o") -> None:
    """Refuse to replace an existing ``path`` that is not a pmdcid ``kind`` ('model' or
    'summary') unless ``force``: its content would be lost."""
    p = str(path)
    if force or not os.path.lexists(p) or os.path.isdir(p):
        return
    if not os.path.exists(p):  # a dangling symlink: its target is created
        return
    obj = _json_object(p)
    ours = obj is not None and ("parameters" in obj if kind == "model" else "added" in obj)
    if not ours:
        raise LogError(f"exists and is not a pmdcid {kind} file: {option} would overwrite it; "
                       "choose another name, or use --force", p)
