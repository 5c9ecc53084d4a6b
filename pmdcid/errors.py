"""The one exception family of pmdcid.

Library code raises :class:`PmdcidError` (or a subclass) for every problem with the user's data,
files or model. The command-line edge turns it into one line on stderr and exit status 1.
"""

from __future__ import annotations

import warnings

#: longest error or warning line the tool prints [characters]: a message built from a huge input
#: (120 000 column names, a 200 KB cell) keeps its head, which names the problem, and its tail,
#: which says what to do
MAX_MESSAGE = 300


def one_line(message: str, limit: int = MAX_MESSAGE) -> str:
    """``message`` on one line (newlines and runs of blanks collapsed), at most ``limit`` chars."""
    s = " ".join(str(message).split())
    if len(s) <= limit:
        return s
    tail = max(40, limit // 5)
    return s[: limit - tail - 5] + " ... " + s[-tail:]


def short_list(names, limit: int = 12) -> str:
    """``a, b, c`` for a list of names, only the first ``limit`` then ``... (N more)``."""
    names = [str(n)[:40] for n in names]
    if len(names) <= limit:
        return ", ".join(names)
    return ", ".join(names[:limit]) + f", ... ({len(names) - limit} more)"


class PmdcidError(Exception):
    """A problem with the user's data, files or model: one clear line, names the file if any."""

    def __init__(self, message: str, path: str | None = None, limit: int = MAX_MESSAGE):
        self.path = str(path) if path is not None else None
        if self.path is not None and len(self.path) > 120:
            self.path = self.path[:60] + "..." + self.path[-57:]
        #: the longest line the message may be (more than MAX_MESSAGE only for a message made
        #: of several bounded reasons, each of which says what to do: identify's)
        self.limit = limit
        text = f"{self.path}: {message}" if self.path else str(message)
        super().__init__(one_line(text, limit))


class LogError(PmdcidError):
    """A log file cannot be read or does not carry what a command needs."""


class MappingError(LogError):
    """A column mapping given as text (``-c CANON=SOURCE...``) that does not parse, found only
    when it is read against a log's names (a right-hand side holding ``/`` may be a signal's
    name): the option's value is at fault, and the command line says so as a usage error."""


class ModelError(PmdcidError):
    """A model file is missing, malformed, or lacks parameters a stage needs."""


class FitError(PmdcidError):
    """An identification stage could not produce a trustworthy result from the data given."""


class NoStepError(FitError):
    """fit-mechanical found no held step the speed settles after: fit-nonlinear (simulation
    error) is the stage for such logs, and the message says so."""


class ArgumentError(PmdcidError, ValueError):
    """A front-door argument of the right type with a value out of range (``km=-1``,
    ``vmax=-12``, ``x0={"speed": 1}``): one line naming the argument. A ValueError too, so code
    catching either catches it; the command line checks its options before, as usage errors."""


class PmdcidWarning(UserWarning):
    """Suspicious but usable data: the tool says so and goes on."""


def warn(message: str, path: str | None = None) -> None:
    """Emit a :class:`PmdcidWarning` (printed as one line by the CLI)."""
    warnings.warn(one_line(f"{path}: {message}" if path else message), PmdcidWarning,
                  stacklevel=2)
