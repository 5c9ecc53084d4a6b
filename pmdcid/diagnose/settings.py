"""diagnose's settings in one object, instead of keyword arguments threaded through the loop."""

from __future__ import annotations

from dataclasses import dataclass, field

from pmdcid.diagnose.rules import Rules


@dataclass(frozen=True)
class Settings:
    """How diagnose searches: the share of a log split in time that is fitted (``split``, the
    rest held out), at most ``max_samples`` compared samples per channel, the ``refit_top``
    strongest screened effects refitted per round, ``max_nfev`` evaluations per refit (four
    times that for the model an accepted effect extends), at most ``max_rounds`` rounds, and
    the :class:`~pmdcid.diagnose.rules.Rules` a candidate must pass."""

    split: float = 0.6
    max_samples: int = 20000
    refit_top: int = 3
    max_nfev: int = 40
    max_rounds: int = 4
    rules: Rules = field(default_factory=Rules)


__all__ = ["Settings"]
