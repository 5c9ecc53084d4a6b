"""The fleet manifest: which log files belong to which unit, measured when.

A CSV with columns ``unit,log`` (one row per log file, several rows per unit; paths relative
to the manifest's folder), an optional ``time`` (ISO 8601: when the unit was measured) and any
other columns, kept as the unit's attributes (``batch``, ``line``...). The rows of one unit at
one time form one :class:`Measurement`, identified as one rig by ``pmdcid identify``.
"""

from __future__ import annotations

import csv
import io
import os
from dataclasses import dataclass, field
from datetime import datetime, timezone

from pmdcid.errors import LogError

#: columns the manifest must have
REQUIRED = ("unit", "log")
#: columns with a meaning of their own (every other column is an attribute)
RESERVED = ("unit", "log", "time")
#: the most rows a manifest may hold (a bigger one is almost surely not a manifest)
MAX_ROWS = 1_000_000


@dataclass
class Measurement:
    """One unit measured once: its log files (absolute paths, manifest order), the time
    (UTC, None when the manifest gives none) and its attributes (column -> text)."""

    unit: str
    time: datetime | None
    logs: list[str] = field(default_factory=list)
    attrs: dict[str, str] = field(default_factory=dict)

    @property
    def label(self) -> str:
        """``unit`` or ``unit@time`` (for messages)."""
        return self.unit if self.time is None else f"{self.unit}@{self.time.isoformat()}"


def parse_time(text: str, where: str) -> datetime | None:
    """An ISO 8601 time as an aware UTC datetime (a naive time is taken as UTC); '' -> None."""
    text = text.strip()
    if not text:
        return None
    if text[-1:] in ("Z", "z"):  # UTC designator (Python 3.10's parser lacks it)
        text = text[:-1] + "+00:00"
    try:
        t = datetime.fromisoformat(text)
    except ValueError:
        raise LogError(f"{where}: time {text[:40]!r} is not ISO 8601 (e.g. 2026-03-01T08:30:00)"
                       ) from None
    if t.tzinfo is None:
        t = t.replace(tzinfo=timezone.utc)
    return t.astimezone(timezone.utc)


def _rows(path: str) -> tuple[list[str], list[list[str]]]:
    from pmdcid.io.text import read_text

    try:
        text = read_text(path)
    except UnicodeDecodeError:
        raise LogError("the manifest is not UTF-8 text", path) from None
    except OSError as exc:
        raise LogError(f"cannot read the manifest ({exc.strerror or exc})", path) from None
    lines = [ln for ln in text.splitlines() if ln.strip() and not ln.lstrip().startswith("#")]
    rows = list(csv.reader(io.StringIO("\n".join(lines))))
    if not rows:
        raise LogError("the manifest is empty: give a CSV with columns unit,log[,time,...]", path)
    if len(rows) > MAX_ROWS + 1:
        raise LogError(f"the manifest has {len(rows) - 1} rows, more than {MAX_ROWS}", path)
    header = [h.strip() for h in rows[0]]
    missing = [c for c in REQUIRED if c not in header]
    if missing:
        raise LogError(f"the manifest lacks the column(s) {', '.join(missing)} (header: "
                       f"{', '.join(header)[:120]}); give unit,log[,time,...]", path)
    if len(set(header)) != len(header) or "" in header:
        raise LogError("the manifest's header has an empty or repeated column name", path)
    return header, rows[1:]


def _record(header: list[str], row: list[str], where: str) -> dict[str, str]:
    if len(row) != len(header):
        raise LogError(f"{where}: {len(row)} cells for {len(header)} columns")
    rec = {h: c.strip() for h, c in zip(header, row, strict=True)}
    if not rec["unit"]:
        raise LogError(f"{where}: empty unit name")
    if not rec["log"]:
        raise LogError(f"{where}: empty log path")
    return rec


def read_manifest(path: str | os.PathLike) -> list[Measurement]:
    """The manifest's measurements, in the order their units first appear (see module doc).
    A malformed manifest (missing columns, a bad time, a unit's rows disagreeing on an
    attribute) raises :class:`~pmdcid.errors.LogError` naming the file and line."""
    path = str(path)
    header, rows = _rows(path)
    if not rows:
        raise LogError("the manifest lists no units (a header and no rows)", path)
    folder = os.path.dirname(os.path.abspath(path))
    found: dict[tuple[str, datetime | None], Measurement] = {}
    for k, row in enumerate(rows, start=2):
        where = f"{path}: row {k}"
        rec = _record(header, row, where)
        time = parse_time(rec.get("time", ""), where)
        m = found.setdefault((rec["unit"], time), Measurement(rec["unit"], time))
        log = os.path.normpath(os.path.join(folder, rec["log"]))
        if log in m.logs:
            raise LogError(f"{where}: log {rec['log']} listed twice for unit {m.label}")
        m.logs.append(log)
        for name, value in rec.items():
            if name in RESERVED or not value:
                continue
            if m.attrs.setdefault(name, value) != value:
                raise LogError(f"{where}: unit {m.label} has {name}={m.attrs[name]!r} on an "
                               f"earlier row and {value!r} here")
    return list(found.values())


__all__ = ["Measurement", "parse_time", "read_manifest"]
