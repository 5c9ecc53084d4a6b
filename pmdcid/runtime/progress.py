"""Progress for the long operations (identify, diagnose, report): one line per stage on stderr,
with the seconds elapsed, when stderr is a terminal; silent otherwise (pipes, files, CI logs,
notebooks), so that captured output holds results only.

The library's long functions take ``progress=callable`` (called with a short message as each
stage starts); the command line passes :func:`stage_lines`.
"""

from __future__ import annotations

import sys
import time


class StageLines:
    """A progress callback writing ``... MESSAGE (T s)`` lines to ``stream`` (default: stderr)
    when it is a terminal, or always when ``force``; a no-op otherwise."""

    def __init__(self, stream=None, force: bool | None = None):
        self.stream = stream if stream is not None else sys.stderr
        if force is None:
            isatty = getattr(self.stream, "isatty", None)
            force = bool(isatty and isatty())
        self.on = force
        self.t0 = time.monotonic()

    def __call__(self, msg: str) -> None:
        if self.on:
            self.stream.write(f"... {msg} ({time.monotonic() - self.t0:.0f} s)\n")
            self.stream.flush()


def stage_lines(stream=None, force: bool | None = None) -> StageLines:
    """The progress callback for the command line and the library (see :class:`StageLines`)."""
    return StageLines(stream, force)


def resolve(progress):
    """A library function's ``progress`` argument as a callback: None -> :func:`stage_lines`
    (lines on a terminal only), False -> silent, a callable -> itself."""
    if progress is None or progress is True:
        return stage_lines()
    if progress is False:
        return lambda msg: None
    return progress


__all__ = ["StageLines", "resolve", "stage_lines"]
