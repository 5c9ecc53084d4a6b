"""What a command writes: all or nothing, never over a stranger's file, one writer at a time.

- :func:`transaction`: the command-line edge runs every command inside one. Each file the
  command replaces is kept (a hard link to the old version) and each file or folder it creates
  is noted; when the command fails -- any error, a full disk, stdout closed under the final
  message (EPIPE), SIGTERM -- the old versions come back and the new files go. Exit 0 means
  every promised file was written; a non-zero exit leaves nothing new behind.
- :func:`install_sigterm`: every signal that can end a command (:data:`ENDING_SIGNALS`:
  SIGTERM, SIGHUP -- a closed terminal or ssh session --, SIGQUIT; one the process was started
  ignoring, as under ``nohup``, stays ignored) becomes an exception
  (:class:`Terminated`, a BaseException like KeyboardInterrupt: no ``except Exception`` in a
  fit can swallow it), so in-flight temporary files are removed and the transaction rolled back
  like any other failure; the command exits 128 + the signal's number.
- :func:`locked`: an exclusive ``flock`` on the folder holding a model, for a stage's
  read-modify-write of the model file (two stages on one model both land their updates).
- :func:`check_overwrite`: an existing output that is not what pmdcid writes there (a model,
  a diagnose summary) is only replaced with ``--force``.
- :func:`check_target`: the one output guard, before any work and again at every write: pmdcid
  writes regular files only (a FIFO, a device, a socket refused even with ``--force``: ``-o
  /dev/null`` is never replaced), a symlink loop is refused, and a file a command writes into
  an output folder never goes through a symlink leading out of that folder.
- :func:`output_folder`: an output folder created for a block of writes is removed again when
  the block fails (a full disk leaves no empty folder), inside a command or not.
- :func:`check_folder_outputs`: the files a command writes into a folder (report's
  report.html, metrics.json, figures): guarded as above, and an existing one the tool did not
  write is only replaced with ``--force`` (the rule simulate, export and diagnose follow).
"""

from __future__ import annotations

import errno
import json
import os
import shutil
import signal
import stat
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


#: the signals that end a command, each handled as SIGTERM is (names: absent on some platforms)
ENDING_SIGNALS = tuple(getattr(signal, n) for n in ("SIGTERM", "SIGHUP", "SIGQUIT")
                       if hasattr(signal, n))


@contextmanager
def sigterm_deferred():
    """The ending signals held back for the block (main thread, POSIX): a temporary file
    created and registered in :data:`IN_FLIGHT` inside it is never left behind by a signal
    arriving between the two (the signal is delivered, and the file removed, once the block
    ends)."""
    mask = getattr(signal, "pthread_sigmask", None)
    if mask is None or threading.current_thread() is not threading.main_thread():
        yield
        return
    old = mask(signal.SIG_BLOCK, set(ENDING_SIGNALS))
    try:
        yield
    finally:
        mask(signal.SIG_SETMASK, old)


class Terminated(BaseException):
    """An ending signal arrived (SIGTERM, SIGHUP, SIGQUIT): unwind, clean up, exit 128 + its
    number. A BaseException, as KeyboardInterrupt: ``except Exception`` never swallows it."""

    def __init__(self, signum: int = getattr(signal, "SIGTERM", 15)):
        super().__init__(signum)
        self.signum = signum

    @property
    def name(self) -> str:
        try:
            return signal.Signals(self.signum).name
        except ValueError:
            return f"signal {self.signum}"


def install_sigterm() -> None:
    """Turn every signal of :data:`ENDING_SIGNALS` into :class:`Terminated` (main thread only;
    a no-op elsewhere)."""
    if threading.current_thread() is not threading.main_thread():
        return

    def handler(signum, frame):
        for tmp in list(IN_FLIGHT):
            if not tmp.endswith(".undo.tmp"):  # backups are restored by the rollback
                try:
                    os.unlink(tmp)
                except OSError:
                    pass
        raise Terminated(signum)

    for sig in ENDING_SIGNALS:
        try:
            if signal.getsignal(sig) == signal.SIG_IGN:  # nohup: the user asked to go on
                continue
            signal.signal(sig, handler)
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


_KINDS = ((stat.S_ISFIFO, "a FIFO (named pipe)"), (stat.S_ISCHR, "a character device"),
          (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"))


def _special(mode: int) -> str | None:
    return next((name for test, name in _KINDS if test(mode)), None)


def check_target(path, folder=None, option: str = "-o") -> None:
    """The one output guard (see module doc): raise a one-line :class:`LogError` naming
    ``path`` when it is a symlink loop or exists and is not a regular file or a folder, or --
    with ``folder``, the output folder it is written into -- when it leads out of ``folder``."""
    p = str(path)
    try:
        st = os.stat(p)
    except OSError as exc:
        if exc.errno == errno.ELOOP:
            raise LogError("is a symlink loop: pmdcid will not replace it; remove the link or "
                           f"choose another {option}", p) from None
        st = None
    if st is not None:
        kind = _special(st.st_mode)
        if kind is not None:
            raise LogError(f"is {kind}, not a regular file: pmdcid writes regular files only "
                           f"(even with --force); choose another {option}", p)
    if folder is not None and os.path.islink(p):
        base = os.path.realpath(folder)
        real = os.path.realpath(p)
        if os.path.commonpath([base, real]) != base:
            raise LogError(f"is a symlink leading out of the output folder {folder} (to {real}): "
                           f"pmdcid never writes through it; remove the link or choose another "
                           f"{option}", p)


def _is_png(path: str) -> bool:
    try:
        with open(path, "rb") as fh:
            return fh.read(8) == b"\x89PNG\r\n\x1a\n"
    except OSError:
        return False


def _is_report_page(path: str) -> bool:
    try:
        with open(path, "rb") as fh:
            return b"<title>pmdcid report" in fh.read(4096)
    except OSError:
        return False


def _is_metrics(path: str) -> bool:
    obj = _json_object(path)
    return obj is not None and {"version", "parameters", "logs"} <= set(obj)


#: what pmdcid writes under each name of an output folder (by suffix): how it recognises its own
OURS_IN_FOLDER = {"report.html": _is_report_page, "metrics.json": _is_metrics, ".png": _is_png}


def _ours_in_folder(path: str) -> bool:
    name = os.path.basename(path)
    test = OURS_IN_FOLDER.get(name) or OURS_IN_FOLDER.get(os.path.splitext(name)[1])
    return test is not None and test(path)


def check_folder_outputs(folder, names, force: bool = False, option: str = "-o") -> None:
    """Refuse, before anything is written, a file ``names`` would replace in ``folder`` that is
    not a regular file inside it (:func:`check_target`), or -- without ``force`` -- that pmdcid
    did not write (:data:`OURS_IN_FOLDER`)."""
    for name in names:
        target = os.path.join(str(folder), name)
        check_target(target, folder, option)
        if force or not os.path.lexists(target) or not os.path.exists(target):
            continue
        if os.path.isdir(target) or not _ours_in_folder(target):
            raise LogError(f"exists and was not written by pmdcid: {option} {folder} would "
                           "replace it; move it, choose another folder, or use --force", target)


@contextmanager
def output_folder(path):
    """Create the folder ``path`` (parents too) for the block's writes; yield it as a Path. The
    folders this created are removed when the block fails: by the command's rollback inside a
    transaction, at once outside one (the library's functions)."""
    from pathlib import Path

    p = Path(path)
    first_new = next((a for a in reversed([p, *p.parents]) if not os.path.lexists(a)), None)
    try:
        p.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise LogError(f"cannot create the output folder ({exc.strerror or exc})", str(p)) from None
    tr = current()
    if first_new is not None and tr is not None:
        tr.created_dir(str(first_new))
    try:
        yield p
    except BaseException:
        if first_new is not None and tr is None:
            shutil.rmtree(first_new, ignore_errors=True)
        raise
