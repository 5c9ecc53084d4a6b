"""What a command writes: all or nothing, never over a stranger's file, one writer at a time.

- :func:`atomic_write`: every file pmdcid writes is written to a temporary file beside it and
  renamed over it (a failure leaves the old file byte for byte).
- :func:`transaction`: the command-line edge runs every command inside one. Each file the
  command replaces is kept (a hard link to the old version) and each file or folder it creates
  is noted; when the command fails -- any error, a full disk, stdout closed under the final
  message (EPIPE), SIGTERM -- the old versions come back and the new files go. Exit 0 means
  every promised file was written; a non-zero exit leaves nothing new behind.
- :func:`locked`: an exclusive ``flock`` on the folder holding a model, for a stage's
  read-modify-write of the model file (two stages on one model both land their updates).
- :func:`input_at`: the output-is-an-input guard, before any work: no output is ever one of
  the files the command reads (a log, the model, a mapping, a manifest).
- :func:`check_overwrite`: an existing output that is not what pmdcid writes there (a model,
  a diagnose summary) is only replaced with ``--force``.
- :func:`check_target`: the one output guard, before any work and again at every write: pmdcid
  writes regular files only (a FIFO, a device, a socket refused even with ``--force``: ``-o
  /dev/null`` is never replaced), a symlink loop is refused, and a file a command writes into
  an output folder never goes through a symlink leading out of that folder.
- :func:`output_folder`: an output folder created for a block of writes is removed again when
  the block fails (a full disk leaves no empty folder), inside a command or not.
- :func:`check_folder_outputs`: the files a command writes into a folder (report's
  report.html, metrics.json, figures; plan's profiles, plan.json, plan.md, check.json; fleet's
  units.parquet, outliers.csv, fleet.html): guarded as above, and an existing one the tool did
  not write is only replaced with ``--force`` (the rule simulate, export and diagnose follow).
"""

from __future__ import annotations

import errno
import json
import os
import shutil
import stat
import tempfile
from contextlib import contextmanager
from pathlib import Path

from pmdcid.errors import LogError
from pmdcid.runtime.signals import IN_FLIGHT, sigterm_deferred

#: the running command's transaction (None outside the command-line edge: writes are final)
_CURRENT: list[Transaction] = []
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


def keep_written() -> None:
    """Make what the running command wrote so far final, whatever its exit: a fleet whose every
    unit failed keeps units.parquet, outliers.csv and fleet.html (the record of why) and then
    exits 1. No-op outside the command-line edge."""
    tr = current()
    if tr is not None:
        tr.commit()


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


def same_file(a, b, planned: bool = False) -> bool:
    """Whether the paths ``a`` and ``b`` name one existing file; ``planned``: or, when either
    does not exist (yet), the same path once links are resolved (two outputs of one command, a
    log not yet checked, a model file removed since it was read)."""
    a, b = os.fspath(a), os.fspath(b)
    if os.path.exists(a) and os.path.exists(b):
        try:
            return os.path.samefile(a, b)
        except OSError:  # gone between the two calls
            pass
    return planned and os.path.realpath(a) == os.path.realpath(b)


def matched(paths) -> list:
    """``paths`` with each one that is a pattern (``*``, ``?``, ``[``) and names no file itself
    replaced by the files it matches, sorted: a notebook's ``"logs/step_*.csv"``, or a shell
    that does not expand patterns (Windows' cmd and PowerShell pass them as written); other
    items (a :class:`~pmdcid.io.Log`) as they are. A pattern that matches nothing is one
    :class:`LogError` line. The logs a command reads and the inputs its output guard compares
    are both read through this."""
    import glob

    out = []
    for item in paths:
        p = os.fspath(item) if isinstance(item, (str, os.PathLike)) else None
        if p is None or not any(c in p for c in "*?[") or os.path.lexists(p):
            out.append(item)
            continue
        hits = sorted(glob.glob(p))
        if not hits:
            raise LogError("no log file matches this pattern (check the path)", p)
        out += hits
    return out


def input_at(output, inputs, planned: bool = False) -> str | None:
    """The first of ``inputs`` that writing ``output`` would overwrite (:func:`same_file`), or
    None: the one output-is-an-input guard, asked by every writer before any work (each caller
    says it in its own words: which output, which option to change)."""
    return next((inp for inp in inputs if inp and same_file(output, inp, planned)), None)


def json_object(path: str):
    """The JSON object in the file ``path`` (a dict), or None: not one, unreadable or too large
    to be a file pmdcid wrote."""
    try:
        if os.path.getsize(path) > MAX_OURS_BYTES:
            return None
        with open(path, "rb") as fh:
            obj = json.loads(fh.read())  # bytes: UTF-8 (BOM or not) or UTF-16 with its BOM
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
    obj = json_object(p)
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
    return starts_with(path, b"<title>pmdcid report")


def _is_metrics(path: str) -> bool:
    obj = json_object(path)
    return obj is not None and {"version", "parameters", "logs"} <= set(obj)


#: what pmdcid writes under each name of an output folder (by suffix): how it recognises its own
OURS_IN_FOLDER = {"report.html": _is_report_page, "metrics.json": _is_metrics, ".png": _is_png}


def _ours_in_folder(path: str, ours: dict) -> bool:
    name = os.path.basename(path)
    test = ours.get(name) or ours.get(os.path.splitext(name)[1])
    return test is not None and test(path)


def starts_with(path: str, text: bytes, within: int = 4096) -> bool:
    """Whether ``text`` is in the first ``within`` bytes of the file ``path`` (a marker pmdcid
    writes at the top of its files)."""
    try:
        with open(path, "rb") as fh:
            return text in fh.read(within)
    except OSError:
        return False


def check_folder_outputs(folder, names, force: bool = False, option: str = "-o",
                         ours: dict | None = None) -> None:
    """Refuse, before anything is written, a file ``names`` would replace in ``folder`` that is
    not a regular file inside it (:func:`check_target`), or -- without ``force`` -- that pmdcid
    did not write: ``ours`` maps a name (or a suffix) to the test that recognises what pmdcid
    writes under it (default :data:`OURS_IN_FOLDER`, report's files; plan and fleet pass
    theirs)."""
    ours = OURS_IN_FOLDER if ours is None else ours
    for name in names:
        target = os.path.join(str(folder), name)
        check_target(target, folder, option)
        if force or not os.path.lexists(target) or not os.path.exists(target):
            continue
        if os.path.isdir(target) or not _ours_in_folder(target, ours):
            raise LogError(f"exists and was not written by pmdcid: {option} {folder} would "
                           "replace it; move it, choose another folder, or use --force", target)


@contextmanager
def output_folder(path):
    """Create the folder ``path`` (parents too) for the block's writes; yield it as a Path. The
    folders this created are removed when the block fails: by the command's rollback inside a
    transaction, at once outside one (the library's functions)."""
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


def atomic_write(path: str | os.PathLike, fill, binary: bool = False) -> None:
    """Write ``path`` atomically: ``fill(fh)`` writes a temporary file in the same folder (opened
    in binary mode when ``binary``), which then replaces ``path`` (os.replace). On any failure
    (SIGTERM included, see :mod:`pmdcid.runtime.signals`) the temporary file is removed and an
    existing ``path`` is left byte-for-byte as it was. A symlink is written through: its target
    is replaced, the link stays. Inside a command's transaction the old version is kept until
    the command succeeds.
    """
    check_target(path)  # regular files only, no symlink loop
    p = Path(os.path.realpath(path)) if os.path.islink(path) else Path(path)
    folder = p.parent if str(p.parent) else Path(".")
    if not folder.exists():
        up = next((a for a in folder.parents if a.exists()), None)
        if up is not None and not up.is_dir():
            raise LogError("is a file, not a folder: cannot write outputs under it", str(up))
        raise LogError("output folder does not exist: create it first", str(folder))
    if not folder.is_dir():
        raise LogError("is a file, not a folder: cannot write outputs under it", str(folder))
    with sigterm_deferred():  # registered before a SIGTERM can leave it behind
        try:
            fd, tmp = tempfile.mkstemp(prefix=f".{p.name}.", suffix=".tmp", dir=folder)
        except OSError as exc:
            raise LogError(f"cannot write here ({exc.strerror})", str(folder)) from None
        IN_FLIGHT.add(tmp)
    try:
        with os.fdopen(fd, "wb" if binary else "w") as fh:
            fill(fh)
            fh.flush()
            os.fsync(fh.fileno())
        if p.exists():
            os.chmod(tmp, p.stat().st_mode & 0o777)
        else:
            umask = os.umask(0)
            os.umask(umask)
            os.chmod(tmp, 0o666 & ~umask)
        tr = current()
        if tr is not None:
            tr.before_replace(os.path.realpath(p))
        os.replace(tmp, p)
    except BaseException as exc:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        if isinstance(exc, OSError):
            raise LogError(f"cannot write ({exc.strerror})", str(path)) from None
        raise
    finally:
        IN_FLIGHT.discard(tmp)


def atomic_write_text(path: str | os.PathLike, text: str) -> None:
    """Write ``text`` to ``path`` atomically (see :func:`atomic_write`)."""
    atomic_write(path, lambda fh: fh.write(text))
