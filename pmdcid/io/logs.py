"""CSV logs: reading (with comments, metadata and column mappings), validating and writing.

A log is comma-separated text with one header row. ``#`` lines before the header are comments;
``# key: value`` comments are metadata. Canonical columns are SI: ``t`` [s], ``v`` [V],
``tau`` [N m or N], ``i`` [A], ``omega`` [rad/s or m/s], ``theta`` [rad or m].
"""

from __future__ import annotations

import io as _io
import os
from collections import Counter
from dataclasses import dataclass, field

import numpy as np

from pmdcid.errors import LogError, short_list, warn
from pmdcid.io.build import (
    as_mapping,
    frame_columns,
    log_from_arrays,
    log_from_frame,
    validated_log,
)
from pmdcid.io.clock import (
    JITTER_TOL,  # noqa: F401 - the one definition, re-exported here
    within_samples,
)
from pmdcid.io.kinds import is_blocked
from pmdcid.io.mapping import ColumnMap
from pmdcid.runtime.outputs import atomic_write

UNITS = {"t": "s", "v": "V", "tau": "N m", "i": "A", "omega": "rad/s", "theta": "rad"}

@dataclass
class Log:
    """A validated, uniformly sampled log in canonical SI columns.

    Attributes: ``path`` (for messages), ``t`` [s] starting where the file starts, ``dt`` [s] the
    sample period, ``data`` canonical column name -> float array, ``meta`` the ``# key: value``
    comments, ``extra`` the non-canonical numeric columns (unmapped), kept for reference,
    ``derived`` the canonical columns computed from others (speed from angle or the reverse, see
    :mod:`pmdcid.io.derive`), ``cutoff_hz`` the filter cut-off given by the user [Hz] or None.
    """

    path: str
    t: np.ndarray
    data: dict[str, np.ndarray]
    meta: dict[str, str] = field(default_factory=dict)
    extra: dict[str, np.ndarray] = field(default_factory=dict)
    derived: set[str] = field(default_factory=set)
    cutoff_hz: float | None = None
    #: the file's own time column [s], unchanged (``t`` starts at 0 on a uniform grid)
    t_file: np.ndarray | None = None
    #: canonical column -> why a mapping-file line for it was skipped (its source is absent)
    skipped: dict[str, str] = field(default_factory=dict)
    #: what the plausibility checks found (:func:`pmdcid.io.checks.check_log`), one line each
    issues: list[str] = field(default_factory=list)
    #: how the file's instants became the uniform ``t`` when they were not uniform (loop-timed
    #: samples, signals on several clocks): a :class:`pmdcid.io.clock.Resampling`, else None
    resampled: object | None = None
    #: what reading did to the data, one line each (also printed as warnings)
    notes: list[str] = field(default_factory=list)
    #: canonical column -> (source column, scale, offset) when the file logged it in its own
    #: unit (``-c omega=speed_rpm*rpm``: ``("speed_rpm", 0.1047, 0.0)``): SI = raw*scale+offset
    sources: dict[str, tuple[str, float, float]] = field(default_factory=dict)

    #: :meth:`input_within`'s last answer, keyed by the input array's identity and length
    _within: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def input_within(self) -> np.ndarray | None:
        """The input inside each sample of a loop-timed log (held from its own instants,
        :data:`pmdcid.io.clock.WITHIN_PARTS` means per sample), which the simulation steps
        instead of :attr:`u`; None when the samples are the input (a uniform log, or no logged
        instant inside a sample), see :func:`pmdcid.io.clock.within_samples`."""
        if self.resampled is None or not ({"v", "tau"} & self.data.keys()):
            return None
        u = self.u
        key = (id(u), len(u), self.t[0], len(self.t))
        if key not in self._within:
            self._within.clear()
            self._within[key] = within_samples(self.resampled, self.t, u)
        return self._within[key]

    @property
    def dt(self) -> float:
        """Sample period [s]."""
        return float((self.t[-1] - self.t[0]) / (len(self.t) - 1))

    @property
    def n(self) -> int:
        return len(self.t)

    @property
    def duration(self) -> float:
        """Length of the log [s]."""
        return float(self.t[-1] - self.t[0])

    def has(self, col: str) -> bool:
        return col in self.data

    def __getitem__(self, col: str) -> np.ndarray:
        return self.data[col]

    @property
    def drive(self) -> str:
        """The input column: ``'v'`` (voltage-driven) or ``'tau'`` (torque-driven)."""
        if "v" in self.data:
            return "v"
        if "tau" in self.data:
            return "tau"
        why = "".join(f"; {self.skipped[c]}" for c in ("v", "tau") if c in self.skipped)
        raise LogError("has no input column: it needs 'v' [V] or 'tau' [N m] "
                       f"(map one with e.g. -c v=SOURCE*SCALE){why}", self.path)

    @property
    def u(self) -> np.ndarray:
        """The input signal (voltage [V] or torque [N m]), zero-order held between samples."""
        return self.data[self.drive]

    def require(self, *cols: str, purpose: str = "") -> None:
        """Raise a one-line :class:`LogError` naming what is missing and how to map it."""
        missing = [c for c in cols if c not in self.data]
        if missing:
            have = short_list(list(self.data) + list(self.extra)) or "none"
            why = f" for {purpose}" if purpose else ""
            skip = "".join(f"; {self.skipped[c]}" for c in missing if c in self.skipped)
            raise LogError(
                f"needs column(s) {', '.join(missing)}{why}{skip}; it has {have} "
                f"(map one with e.g. -c {missing[0]}=SOURCE*SCALE)",
                self.path,
            )

    @property
    def kind(self) -> str | None:
        return self.meta.get("kind")

    #: the signals a model predicts, in the kernel's state order: current [A], speed [rad/s],
    #: angle [rad]
    MODEL_SIGNALS = ("i", "omega", "theta")

    def compares(self, signal: str) -> bool:
        """True when the log measures ``signal`` and a simulation predicts it: the current only
        on a voltage-driven log (a torque-driven simulation has none). The one rule every fit,
        diagnose and the report use to pick the signals they compare."""
        return self.has(signal) and not (signal == "i" and self.drive == "tau")

    def compared_signals(self) -> list[str]:
        """The :data:`MODEL_SIGNALS` this log :meth:`compares`."""
        return [s for s in self.MODEL_SIGNALS if self.compares(s)]

    @property
    def blocked(self) -> bool:
        """A blocked-rotor log: its ``# kind:`` says so (:mod:`pmdcid.io.kinds`), or it
        measures neither speed nor angle. The one rule every stage, diagnose and the report use."""
        return is_blocked(self.kind) or not (self.has("omega") or self.has("theta"))

    def __repr__(self) -> str:
        from pmdcid.io.plot import LABELS, describe

        cols = ", ".join(f"{c}{' (derived)' if c in self.derived else ''}"
                         f"{f' (as {self.sources[c][0]})' if c in self.sources else ''}"
                         for c in self.data if c in LABELS)
        kind = f", kind {self.kind}" if self.kind else ""
        return f"Log({self.path!r}{kind}: {describe(self.t)}; {cols})"

    def plot(self, columns=None):
        """The log's signals against time, the input on top (matplotlib Figure)."""
        from pmdcid.io.plot import plot_columns

        cols = {c: a for c, a in self.data.items() if columns is None or c in columns}
        units = {c: f" ({s[0]} as logged)" for c, s in self.sources.items()}
        return plot_columns(self.t, cols, str(self.path), units=units)

    @classmethod
    def from_csv(cls, path, *, columns=None, map_file=None, cutoff_hz=None) -> Log:
        """Read a CSV log as ``pmdcid`` commands do. ``columns``: mappings as a dict
        ``{"omega": "speed*rpm"}`` or a list of ``"omega=speed*rpm"`` (the ``-c`` option),
        ``map_file``: a mapping file (``--map``), ``cutoff_hz`` (``--cutoff``)."""
        return read_log(path, as_mapping(columns, map_file, cutoff_hz))

    @classmethod
    def from_file(cls, path, *, columns=None, map_file=None, cutoff_hz=None) -> Log:
        """Read a log file of any format pmdcid reads, by extension (docs/io.md): the same as
        :meth:`from_csv`, which also reads every format."""
        return cls.from_csv(path, columns=columns, map_file=map_file, cutoff_hz=cutoff_hz)

    @classmethod
    def from_dataframe(cls, df, *, columns=None, name: str = "dataframe", cutoff_hz=None,
                       meta: dict | None = None) -> Log:
        """A log from a pandas DataFrame, mapped and checked exactly as a CSV file is."""
        from pmdcid.io.args import frame_arg

        return log_from_frame(cls, frame_arg(df), as_mapping(columns, None, cutoff_hz), name, meta)

    @classmethod
    def from_arrays(cls, t, *, v=None, tau=None, i=None, omega=None, theta=None,
                    name: str = "arrays", cutoff_hz=None, meta: dict | None = None) -> Log:
        """A log from SI arrays: ``t`` [s], ``v`` [V] or ``tau`` [N m], ``i`` [A], ``omega``
        [rad/s], ``theta`` [rad]; checked as a CSV file is (uniform time, finite values, speed
        derived from the angle or the reverse)."""
        from pmdcid.io.args import array_arg

        cols = {k: None if a is None else array_arg(a, k)
                for k, a in dict(v=v, tau=tau, i=i, omega=omega, theta=theta).items()}
        return log_from_arrays(cls, array_arg(t, "t"), name, cutoff_hz, meta, **cols)


def _split_comments(text: str, path: str) -> tuple[dict[str, str], int]:
    """Metadata from leading ``#`` lines and the number of such lines."""
    meta: dict[str, str] = {}
    n = 0
    for line in text.splitlines():
        s = line.strip()
        if s.startswith("#"):
            body = s.lstrip("#").strip()
            if ":" in body:
                k, v = body.split(":", 1)
                if k.strip():
                    meta[k.strip()] = v.strip()
            n += 1
        elif s == "" and n >= 0:
            n += 1
        else:
            break
    return meta, n


def read_log(path: str | os.PathLike, mapping: ColumnMap | None = None,
             defer: bool = False) -> Log:
    """Read and validate one log. Raises :class:`LogError` with one clear line.

    The format follows the extension: ``.mcap``, ``.wpilog``, ``.mf4``/``.mdf``, ``.tdms``,
    ``.mat``, ``.parquet`` through :mod:`pmdcid.io.formats`, anything else as CSV. What the
    plausibility checks find (:mod:`pmdcid.io.checks`) is in ``log.issues``; it is also warned
    about unless ``defer`` (a stage about to write a model refuses instead).
    """
    from pmdcid.io.formats import is_other_format

    if is_other_format(path):
        from pmdcid.io.formats import read

        return read(Log, path, mapping, defer)
    p = str(path)
    df, meta = read_table(p)
    mapping = mapping or ColumnMap()
    data, extra, skipped = frame_columns(df, mapping, p)
    del df  # the table is no longer needed: freed before the checks' temporaries
    log = validated_log(Log, p, data, extra, meta, mapping.cutoff_hz, skipped=skipped, defer=defer)
    log.sources = mapping.sources(data)
    return log


def read_table(p: str):
    """A CSV log's table (a DataFrame or :class:`~pmdcid.io.plain.PlainFrame`, one-line unique
    column names) and its ``# key: value`` metadata, unchecked."""
    from pmdcid.io.csvsource import (
        check_header,
        cut_inside_last_row,
        header_names,
        open_source,
        sniff,
    )

    if not os.path.exists(p):
        raise LogError("no such log file (check the path)", p)
    if os.path.isdir(p):
        raise LogError("is a folder, not a log file", p)
    src = open_source(p)
    from pmdcid.io.bounds import check_lines

    check_lines(src.handle, p)  # before any parsing: a 50 MB line fails at once
    meta, nskip = _split_comments(src.head, p)
    sniff(src, nskip)
    check_header(src, nskip, p)
    df = None
    if isinstance(src.handle, str) and (src.sep, src.decimal) == (",", "."):
        from pmdcid.io.plain import read_plain  # plain numbers: no pandas import

        df = read_plain(p, nskip)
    if df is None:
        df = _read_frame(src, nskip, p)
    cols = [" ".join(str(c).splitlines()).strip() for c in df.columns]  # one-line names
    # pandas renames duplicates to 'x.1'; check the raw header too (one pass: linear)
    counts = Counter(c for c in header_names(src, nskip) if c)
    counts_stripped = Counter(cols)
    dups = sorted({c for c, k in counts.items() if k > 1}
                  | {c for c, k in counts_stripped.items() if k > 1})  # also equal once stripped
    if dups:
        raise LogError(f"header names column(s) {short_list(dups)} more than once: rename one",
                       p)
    df.columns = cols
    if len(df) == 0:
        raise LogError("has a header but no data rows: was the recording saved?", p)
    if len(df) > 1 and cut_inside_last_row(src):
        warn("its last row has no line end after it, as in a file cut while it was written: that "
             "row is not used (end the file with a newline to use it)", p)
        df = df.head(len(df) - 1)
    return df, meta


def _read_frame(src, nskip: int, p: str):
    """The data rows of log ``p`` as a pandas DataFrame (any CSV pandas reads)."""
    import pandas as pd

    from pmdcid.io.chunked import CHUNKED_BYTES, read_chunked
    from pmdcid.io.csvsource import separator_hint

    if isinstance(src.handle, str) and os.path.getsize(src.handle) > CHUNKED_BYTES:
        df = read_chunked(src, nskip)  # a large log: the same numbers in bounded memory
        if df is not None:
            return df
    try:
        df = pd.read_csv(src.handle, skiprows=nskip, skipinitialspace=True, low_memory=False,
                         encoding="utf-8-sig", encoding_errors="replace", sep=src.sep,
                         decimal=src.decimal)
    except pd.errors.EmptyDataError:
        raise LogError("is empty: expected a header row naming the columns, then data rows",
                       p) from None
    except (pd.errors.ParserError, UnicodeDecodeError, ValueError) as exc:
        msg = str(exc).strip().splitlines()[-1] if str(exc).strip() else type(exc).__name__
        raise LogError(f"is not a readable CSV ({msg[:100]}): check quotes and the number of "
                       f"fields per row{separator_hint(src, nskip)}", p) from None
    return df


def read_logs(paths, mapping: ColumnMap | None = None, defer: bool = False) -> list[Log]:
    """Read several logs with the same mapping (``defer``: see :func:`read_log`)."""
    if not paths:
        raise LogError("no log files given")
    return [read_log(p, mapping, defer) for p in paths]


#: rows formatted per chunk when writing a log (bounds the memory of writing huge logs: one
#: chunk is formatted in one %-operation, ~15 MB of Python floats and text at 50 000 rows x 5)
WRITE_CHUNK = 50_000


#: the time column is written with full round-trip precision (the shortest text that reads
#: back as the same float, Python's repr; integral stamps as integers): a time stamp (seconds
#: since 1970 with microseconds, 1700000000.011166) is written back as it was read
TIME_FORMAT = "%r"


def _stamps(t: list) -> list:
    """The time column's values for :data:`TIME_FORMAT`: integral ones as ints (``12``, not
    ``12.0``), the others as they are."""
    return [int(x) if x.is_integer() and abs(x) < 2**53 else x for x in t]


def write_csv(fh, t: np.ndarray, columns: dict[str, np.ndarray],
              meta: dict[str, str] | None = None, precision: int = 9) -> None:
    """Write CSV to the open text file ``fh``: ``# key: value`` comments, header, values.

    Rows are formatted ``%.{precision}g`` in chunks of :data:`WRITE_CHUNK`, so a 10-million-row
    log never exists as one string in memory.
    """
    for k, v in (meta or {}).items():
        fh.write(f"# {k}: {v}\n")
    fh.write(",".join(["t", *columns]) + "\n")
    cols = [np.asarray(t, dtype=float), *(np.asarray(c, dtype=float) for c in columns.values())]
    row = ",".join([TIME_FORMAT] + [f"%.{precision}g"] * (len(cols) - 1)) + "\n"
    for a in range(0, len(cols[0]), WRITE_CHUNK):
        arr = np.column_stack([c[a:a + WRITE_CHUNK] for c in cols])
        # one %-format of the whole chunk: the text np.savetxt(fmt=..., delimiter=",") writes
        # row by row, in half the time (savetxt's per-row loop was a quarter of `simulate`)
        vals = arr.ravel().tolist()
        vals[::len(cols)] = _stamps(vals[::len(cols)])
        fh.write((row * len(arr)) % tuple(vals))


def format_csv(t: np.ndarray, columns: dict[str, np.ndarray], meta: dict[str, str] | None = None,
               precision: int = 9) -> str:
    """CSV text with ``# key: value`` comments, header ``t,...`` and ``%.{precision}g`` values."""
    buf = _io.StringIO()
    write_csv(buf, t, columns, meta, precision)
    return buf.getvalue()


def write_log(path, t, columns: dict[str, np.ndarray], meta: dict[str, str] | None = None) -> None:
    """Write a canonical log atomically, streaming it in chunks."""
    atomic_write(path, lambda fh: write_csv(fh, np.asarray(t), columns, meta))
