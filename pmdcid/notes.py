"""Warnings and notes as data: what a stage says beside its numbers, and what it concerns.

A :class:`Note` is a ``str`` (its text, so every caller that prints, joins or searches the
stages' ``warnings`` lists keeps working) that also carries:

- ``about``: the parameters it qualifies (``("dz",)``: the dead zone's ± 58 % is why), the
  log it is about (``log``), or neither (the fit as a whole: "reduced chi-square 10.3 >> 1");
- ``severity``: ``"warning"`` (a number is less trustworthy than its table says, or the data
  look wrong) or ``"note"`` (how a number was obtained: "lumped model: per-volt parameters");
- ``stage``: the stage that gave it (``fit-nonlinear``, ``diagnose``, ...).

Stages give it explicitly where they know (``Note(text, about="dz")``); a plain string from a
stage, a diagnose summary or a model file read back is read by :func:`as_note`'s one rule:
a leading log path names the log, and the parameter names the text gives before its first
colon are what it concerns ("dz is not identifiable from these logs: ..." -> dz). The model file
keeps them (``"notes"``, :func:`to_records`), the CLI prints them, the report shows them beside
the rows they qualify, the API exposes them (``result.notes``).
"""

from __future__ import annotations

import re

SEVERITIES = ("warning", "note")


class Note(str):
    """One warning or note: the text (the string itself), ``about``, ``log``, ``severity``,
    ``stage`` (module docstring)."""

    def __new__(cls, text: str, about=(), *, severity: str = "warning", stage: str = "",
                log: str = ""):
        if severity not in SEVERITIES:
            raise ValueError(f"severity must be one of {SEVERITIES}, not {severity!r}")
        self = super().__new__(cls, str(text))
        self.about = (about,) if isinstance(about, str) else tuple(about)
        self.severity = severity
        self.stage = stage
        self.log = log
        return self

    def __reduce__(self):  # pickled (report workers, multiprocessing) with its fields
        return (_rebuild, (str(self), self.about, self.severity, self.stage, self.log))

    def __repr__(self) -> str:
        about = f", about={list(self.about)}" if self.about else ""
        return f"Note({str(self)!r}{about}, severity={self.severity!r})"

    @property
    def text(self) -> str:
        return str(self)

    def in_stage(self, stage: str, prefix: bool = True) -> Note:
        """This note as given by ``stage`` (its text prefixed ``stage: `` when ``prefix``)."""
        text = f"{stage}: {self}" if prefix else str(self)
        return Note(text, self.about, severity=self.severity, stage=stage, log=self.log)

    def to_dict(self) -> dict:
        """JSON-safe: text, about, severity, stage, log."""
        return {"text": str(self), "about": list(self.about), "severity": self.severity,
                "stage": self.stage, "log": self.log}


def _rebuild(text, about, severity, stage, log) -> Note:
    return Note(text, about, severity=severity, stage=stage, log=log)


#: a parameter name as a word: not inside a longer name, not a unit's letter after a number
_WORD = r"(?<![\w.]){}(?![\w(])"


def _names_in(text: str, names) -> tuple[str, ...]:
    head = re.split(r":\s", text, maxsplit=1)[0]
    return tuple(n for n in names if re.search(_WORD.format(re.escape(n)), head))


def _leading_log(text: str, stage: str, logs) -> tuple[str, str]:
    """(the log path ``text`` starts with, after a ``stage: `` prefix, or ''; the rest)."""
    body = text[len(stage) + 2:] if stage and text.startswith(f"{stage}: ") else text
    log = next((p for p in logs if p and body.startswith(f"{p}:")), "")
    return log, body[len(log) + 1:].lstrip() if log else body


def as_note(item, *, severity: str = "warning", stage: str = "", names=(), logs=()) -> Note:
    """``item`` (a :class:`Note`, a plain string, or a dict from :meth:`Note.to_dict`) as a
    Note (a Note without a stage gets ``stage``). A plain string's ``about`` is read by the
    module docstring's rule over ``names`` (parameter or effect names) and ``logs`` (paths);
    a dict's log, when it names none, by the same rule."""
    if isinstance(item, Note):
        return item.in_stage(stage, prefix=False) if stage and not item.stage else item
    if isinstance(item, dict):
        text, stage = str(item.get("text", "")), item.get("stage", stage)
        log = item.get("log") or _leading_log(text, stage, logs)[0]
        return Note(text, item.get("about", ()), severity=item.get("severity", severity),
                    stage=stage, log=log)
    text = str(item)
    log, body = _leading_log(text, stage, logs)
    return Note(text, _names_in(body, names), severity=severity, stage=stage, log=log)


def to_records(notes) -> list[dict]:
    """Notes as JSON-safe dicts (a plain string: a warning about nothing in particular)."""
    return [as_note(n).to_dict() for n in notes]


__all__ = ["SEVERITIES", "Note", "as_note", "to_records"]
