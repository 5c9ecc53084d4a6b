"""Log files beyond CSV: one reader interface, one module per format, chosen by extension.

Every reader module defines ``EXTENSIONS`` (lower-case, with the dot), ``EXTRA`` (the optional
dependency that installs its library: ``pip install 'pmdcid[EXTRA]'``) and ``load(path,
wanted=None)`` (``wanted``: the names the mappings read, a hint a reader may use to read less),
which returns a :class:`Signals`: every numeric signal of the file by the name the file gives
it, as **series** (each with its own time stamps: MCAP topics, wpilog entries, TDMS channels,
MDF channel groups) or as a **table** (columns sharing one time column, as in a CSV file:
Parquet, MATLAB ``.mat``). :func:`read` turns them into a checked
:class:`~pmdcid.io.logs.Log` with the ``-c`` column mappings; :func:`channels` lists them
(``pmdcid channels FILE``). CSV keeps its own reader (:func:`pmdcid.io.logs.read_log`), listed
here as the ``csv`` format. docs/io.md has the table of formats and an example of each.
"""

from __future__ import annotations

import importlib
import os
from dataclasses import dataclass, field

import numpy as np

from pmdcid.errors import LogError

#: extension -> module of this package reading it (CSV: :mod:`pmdcid.io.logs` itself)
READERS: dict[str, str] = {
    ".mcap": "mcapfile",
    ".wpilog": "wpilog",
    ".mf4": "mdf",
    ".mdf": "mdf",
    ".tdms": "tdms",
    ".mat": "matfile",
    ".parquet": "parquet",
    ".pq": "parquet",
}


@dataclass
class Series:
    """One signal: values ``x`` at instants ``t`` [s from the file's first time stamp], or
    ``t`` None for a table column (its time is the table's time column); ``unit`` as the file
    stores it (None when it stores none)."""

    x: np.ndarray
    t: np.ndarray | None = None
    unit: str | None = None


@dataclass
class Signals:
    """What a reader found: ``series`` name -> :class:`Series` (one with 0 samples too, a
    channel that recorded nothing: listed, and refused where a mapping uses it); ``table`` True
    when they are columns sharing a time column; ``meta`` file-level metadata (``# key:
    value`` as in CSV)."""

    series: dict[str, Series]
    table: bool = False
    meta: dict[str, str] = field(default_factory=dict)
    #: other names ``-c`` may give a signal -> its name in ``series`` (MDF: ``group/channel``
    #: for a channel named by its own name)
    aliases: dict[str, str] = field(default_factory=dict)


#: first bytes of each format -> (what the file is, the extension that reads it)
MAGICS: tuple[tuple[bytes, str, str], ...] = (
    (b"\x89MCAP0\r\n", "an MCAP file", ".mcap"), (b"WPILOG", "a WPILib DataLog", ".wpilog"),
    (b"MDF     ", "an ASAM MDF file", ".mf4"), (b"UnFinMF ", "an ASAM MDF file", ".mf4"),
    (b"TDSm", "a LabVIEW TDMS file", ".tdms"), (b"PAR1", "a Parquet file", ".parquet"),
    (b"MATLAB ", "a MATLAB .mat file", ".mat"))


def sniffed(head: bytes) -> tuple[str, str] | None:
    """(what the file is, its extension) when ``head`` (its first bytes) starts as a format
    this package reads, else None."""
    return next(((what, ext) for magic, what, ext in MAGICS if head.startswith(magic)), None)


def _check_kind(p: str) -> None:
    """An empty file, or one whose first bytes are another format's (a CSV named .mf4, an MDF
    named .tdms), refused in one line that says what it is and what to name it."""
    ext = extension(p)
    with open(p, "rb") as fh:
        head = fh.read(512)
    if not head:
        raise LogError(f"is empty (0 bytes): no {ext} file was written into it", p)
    kind = sniffed(head)
    if kind is not None and READERS.get(kind[1]) != READERS[ext]:
        raise LogError(f"is {kind[0]} (its first bytes say so), not a {ext} file: name it "
                       f"{kind[1]} to read it", p)
    line = head.split(b"\n", 1)[0].strip()
    if kind is None and b"\x00" not in head and line and any(c in line for c in b",;\t"):
        try:
            first = line.decode("utf-8")
        except UnicodeDecodeError:
            return
        raise LogError(f"is text (its first line {first[:40]!r}), not a {ext} file: a CSV log? "
                       "name it .csv to read it", p)


def extension(path) -> str:
    """The lower-case extension of ``path`` ('' for none)."""
    return os.path.splitext(str(path))[1].lower()


def is_other_format(path) -> bool:
    """True when ``path``'s extension names a format read by this package (not CSV)."""
    return extension(path) in READERS


def reader(path):
    """The reader module for ``path``'s extension."""
    return importlib.import_module(f"pmdcid.io.formats.{READERS[extension(path)]}")


def own_time_fix(path) -> str | None:
    """How a user gives the time of a series file (its signals carry their own time stamps, so
    ``-c t=COLUMN*UNIT`` cannot rescale them) in seconds: its reader's ``TIME_UNIT_FIX``, a
    sentence with ``{unit}`` for the unit the time looks like; None for CSV and tables."""
    if not is_other_format(path):
        return None
    return getattr(reader(path), "TIME_UNIT_FIX", None)


def byte_count(n: int) -> str:
    """``n`` bytes in words, for a message ("1 byte", "24 bytes")."""
    return "1 byte" if n == 1 else f"{n} bytes"


def need(module: str, extra: str, path: str, what: str):
    """Import ``module`` (the format's library) or raise one line naming the extra to install."""
    try:
        return importlib.import_module(module)
    except ImportError:
        raise LogError(f"reading {what} files needs the package '{module.split('.')[0]}': "
                       f"pip install 'pmdcid[{extra}]'", path) from None


def load(path, wanted: list[str] | None = None) -> Signals:
    """The signals of a non-CSV log file (a missing file, a folder: one line). ``wanted``: the
    names the mappings read (a reader may read only those: MCAP decodes only their topics)."""
    p = str(path)
    if not os.path.exists(p):
        raise LogError("no such log file (check the path)", p)
    if os.path.isdir(p):
        raise LogError("is a folder, not a log file", p)
    _check_kind(p)
    sig = reader(p).load(p, wanted)
    if not any(len(s.x) for s in sig.series.values()):
        raise LogError(f"holds no numeric signal a motor log could use ({extension(p)} file)", p)
    return sig


def read(log_type: type, path, mapping=None, defer: bool = False):
    """A checked ``log_type`` (:class:`~pmdcid.io.logs.Log`, given by the caller:
    :mod:`pmdcid.io.build`) from a non-CSV file: signals named by ``mapping`` (``-c
    CANON=SOURCE``, the CSV syntax); series on several clocks put on the input's clock."""
    from pmdcid.io.formats.assemble import series_log, table_log
    from pmdcid.io.mapping import ColumnMap

    p = str(path)
    mapping = mapping or ColumnMap()
    wanted = [s.text.split("=", 1)[1].strip() if "=" in s.text else s.source
              for s in mapping.specs.values()]
    sig = load(p, wanted)
    mapping = dealiased(mapping, sig.aliases)
    if sig.table:
        return table_log(log_type, p, sig, mapping, defer)
    return series_log(log_type, p, sig, mapping, defer)


def dealiased(mapping, aliases: dict[str, str]):
    """``mapping`` with each right-hand side that starts with an alias of a signal (followed by
    its end or a scale) naming the signal by its own name (``motor/n_mot*rpm`` -> ``n_mot*rpm``)."""
    from dataclasses import replace

    from pmdcid.io.mapping import ColumnMap, parse_spec

    if not aliases:
        return mapping
    specs = {}
    for canon, spec in mapping.specs.items():
        rhs = (spec.text.split("=", 1)[1] if "=" in spec.text else spec.source).strip()
        sign, body = ("-", rhs[1:].lstrip()) if rhs.startswith("-") else ("", rhs)
        hit = max((a for a in aliases if body == a or (body.startswith(a)
                                                       and body[len(a)] in "*/+-")),
                  key=len, default=None)
        if spec.expr is None and hit is not None:
            new = parse_spec(f"{canon}={sign}{aliases[hit]}{body[len(hit):]}")
            spec = replace(new, origin=spec.origin)
        specs[canon] = spec
    return ColumnMap(specs, mapping.cutoff_hz)


@dataclass
class Channel:
    """One signal of a file as ``pmdcid channels`` lists it: ``rate`` [Hz] the median rate
    (None: no time), ``unit`` as stored (None: none)."""

    name: str
    samples: int
    rate: float | None
    unit: str | None


def rate_of(t) -> float | None:
    """1 / the median interval of instants ``t`` [s] (None when they cannot tell)."""
    if t is None or len(t) < 2:
        return None
    dtv = np.diff(np.asarray(t, float))
    dtv = dtv[dtv > 0]
    if not len(dtv):
        return None
    return float(1.0 / np.median(dtv))


def channels(path) -> list[Channel]:
    """The signals ``path`` holds (any format, CSV included): name, samples, rate, unit."""
    p = str(path)
    if not is_other_format(p):
        from pmdcid.io.formats.csvfile import csv_channels

        return csv_channels(p)
    sig = load(p)
    out = []
    for name, s in sig.series.items():
        t = s.t
        if t is None and sig.table:
            from pmdcid.io.formats.assemble import table_time

            t = table_time(sig, name)
        out.append(Channel(name, len(s.x), rate_of(t), s.unit))
    return out


def format_channels(chans: list[Channel]) -> str:
    """The text table ``pmdcid channels`` prints."""
    rows = [("name", "samples", "rate [Hz]", "unit")]
    for c in chans:
        rate = "-" if c.rate is None else f"{c.rate:.6g}"
        rows.append((c.name, str(c.samples), rate, c.unit or "-"))
    width = [max(len(r[k]) for r in rows) for k in range(4)]
    lines = []
    for r in rows:
        lines.append("  ".join([r[0].ljust(width[0]), r[1].rjust(width[1]),
                                r[2].rjust(width[2]), r[3]]).rstrip())
    return "\n".join(lines)
