"""The signals that end a command, as an exception that unwinds like any other failure.

- :func:`install_sigterm`: every signal that can end a command (:data:`ENDING_SIGNALS`:
  SIGTERM, SIGHUP -- a closed terminal or ssh session --, SIGQUIT; one the process was started
  ignoring, as under ``nohup``, stays ignored) becomes an exception (:class:`Terminated`, a
  BaseException like KeyboardInterrupt: no ``except Exception`` in a fit can swallow it), so
  in-flight temporary files (:data:`IN_FLIGHT`) are removed and the command's transaction
  (:mod:`pmdcid.runtime.outputs`) rolled back like any other failure; the command exits 128 +
  the signal's number.
- :func:`sigterm_deferred`: the ending signals held back while a temporary file is created and
  registered, so that none is left behind.
"""

from __future__ import annotations

import os
import signal
import threading
from contextlib import contextmanager

#: temporary files being written right now (removed on SIGTERM)
IN_FLIGHT: set[str] = set()


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


__all__ = ["ENDING_SIGNALS", "IN_FLIGHT", "Terminated", "install_sigterm", "sigterm_deferred"]
