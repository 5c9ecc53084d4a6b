"""The one exception family of pmdcid.

Library code raises :class:`PmdcidError` (or a subclass) for every problem with the user's data,
files or model. The command-line edge turns it into one line on stderr and exit status 1.
"""

from __future__ import annotations

import warnings


class PmdcidError(Exception):
    """A problem with the user's data, files or model: one clear line, names the file if any."""

    def __init__(self, message: str, path: str | None = None):
        self.path = str(path) if path is not None else None
        super().__init__(f"{self.path}: {message}" if self.path else message)


class LogError(PmdcidError):
    """A log file cannot be read or does not carry what a command needs."""


class ModelError(PmdcidError):
    """A model file is missing, malformed, or lacks parameters a stage needs."""


class FitError(PmdcidError):
    """An identification stage could not produce a trustworthy result from the data given."""


class PmdcidWarning(UserWarning):
    """Suspicious but usable data: the tool says so and goes on."""


def warn(message: str, path: str | None = None) -> None:
    """Emit a :class:`PmdcidWarning` (printed as one line by the CLI)."""
    warnings.warn(f"{path}: {message}" if path else message, PmdcidWarning, stacklevel=2)
