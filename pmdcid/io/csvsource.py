"""Opening a log as rigs and spreadsheets export it: encoding, pipes, separator, decimal mark.

- A UTF-8 byte-order mark is dropped (also before ``#`` comments); a UTF-16 file with its BOM is
  decoded as UTF-16 (Excel's "Unicode text"). A file whose head is not UTF-8 (a rig writing
  ``°`` or ``µ`` as one byte) is decoded as Windows-1252, a superset of Latin-1, with a warning.
- A pipe or process substitution (``<(zcat log.csv.gz)``) is read once, into memory: it cannot
  be read twice or sized.
- European exports (Excel with a comma decimal mark) separate fields with ``;`` and write
  ``0,001``: a header with ``;`` (or a tab) and no ``,``, whose first data rows have as many
  separators, is read with that separator, and with a decimal comma when the data show one.
- A header of names separated by spaces (no ``,``, ``;`` or tab), whose first data rows have as
  many whitespace-separated fields, is read as whitespace-separated (``t v i omega``).
"""

from __future__ import annotations

import codecs
import io
import os
import re
import stat
from dataclasses import dataclass

import numpy as np

from pmdcid.errors import LogError, short_list, warn
from pmdcid.io.formats import sniffed
from pmdcid.io.mapping import ColumnSpec, resolve
from pmdcid.io.text import BOMS_16, decode

HEAD_BYTES = 1 << 16
#: data rows looked at to recognise the separator and the decimal mark
SNIFF_ROWS = 20
#: the separator of a whitespace-separated file (pandas' regular expression)
WHITESPACE = r"\s+"


#: compressed files by their magic bytes: what they are, and how to get the CSV out
COMPRESSED = (
    (b"\x1f\x8b", ("gzip-compressed", "decompress it first (zcat FILE > log.csv), or read it "
                   "through a pipe: <(zcat FILE)")),
    (b"BZh", ("bzip2-compressed", "decompress it first (bzcat FILE > log.csv)")),
    (b"\xfd7zXZ\x00", ("xz-compressed", "decompress it first (xzcat FILE > log.csv)")),
    (b"\x28\xb5\x2f\xfd", ("zstd-compressed", "decompress it first (zstdcat FILE > log.csv)")),
    (b"PK\x03\x04", ("a zip archive (or an Excel workbook)", "extract the CSV from it (or save "
                      "the sheet as CSV)")),
)


@dataclass
class Source:
    """What pandas reads (a path or an in-memory buffer), the text head, the CSV dialect."""

    handle: object
    head: str
    sep: str = ","
    decimal: str = "."


#: bytes read at a time from a file's end, looking for NUL padding after the last row
TAIL_BYTES = 1 << 16
#: what may trail a log's last row: NUL padding, and line ends and blanks among it
_TRAILING = b"\x00\r\n\t "


def _padding(fh) -> tuple[int, int]:
    """(bytes before the padding, NUL bytes in it) of the open file ``fh``, the padding being the
    NUL bytes (with line ends and blanks among them) after its last row: a logger that
    pre-allocates its file or writes whole buffers leaves them. (size, 0) without NULs there."""
    size = end = fh.seek(0, os.SEEK_END)
    nuls = 0
    while end > 0:
        start = max(0, end - TAIL_BYTES)
        fh.seek(start)
        block = fh.read(end - start)
        kept = block.rstrip(_TRAILING)
        nuls += block.count(b"\x00", len(kept))
        end = start + len(kept)
        if kept:
            break
    return (end, nuls) if nuls else (size, 0)


def _read(p: str) -> tuple[bytes | None, bytes]:
    """The whole of log ``p`` (None for a regular file: read by path) and its head; a file
    padded with NUL bytes after its last row is read without them (one warning). UTF-16 text,
    whose line ends hold NUL bytes, is left as it is."""
    with open(p, "rb") as fh:
        if stat.S_ISREG(os.fstat(fh.fileno()).st_mode):
            data, head = None, fh.read(HEAD_BYTES)
            end, nuls = (0, 0) if head.startswith(BOMS_16) else _padding(fh)
            if nuls:
                fh.seek(0)
                data = fh.read(end)
        else:  # a pipe: read once
            data = fh.read()
            kept = b"" if data.startswith(BOMS_16) else data.rstrip(_TRAILING)
            end, nuls = len(kept), data.count(b"\x00", len(kept)) if kept else 0
    if nuls:
        data = data[:end] + b"\n"
        warn(f"ignored {nuls} NUL byte(s) after the last row (a logger's padding)", p)
    return data, (head if data is None else data[:HEAD_BYTES])


def open_source(p: str) -> Source:
    """Read the head of log ``p`` (all of it when it is not a regular file); see module doc."""
    try:
        data, head = _read(p)
    except OSError as exc:
        raise LogError(f"cannot read log ({exc.strerror})", p) from None
    if head.startswith(BOMS_16):
        if data is None:
            with open(p, "rb") as fh:
                data = fh.read()
        try:
            text = decode(data)
        except UnicodeDecodeError:
            raise LogError("starts like UTF-16 text but is not: export the log as UTF-8 CSV",
                           p) from None
        return Source(io.StringIO(text), text[:HEAD_BYTES])
    packed = next(((magic, *how) for magic, how in COMPRESSED if head.startswith(magic)), None)
    if packed:
        raise LogError(f"is {packed[1]} (its first bytes are {packed[0].hex(' ')}), not CSV "
                       f"text: {packed[2]}", p)
    if b"\x00" in head or sniffed(head):
        kind = sniffed(head)
        if kind is not None:  # a log of a format pmdcid reads, under another name
            raise LogError(f"is {kind[0]} (its first bytes say so), not CSV text: name it "
                           f"{kind[1]} to read it", p)
        raise LogError("is not a text CSV file (binary content): export the log as CSV", p)
    legacy = _not_utf8(p, data, head)
    if legacy is not None:
        return legacy
    text = head.decode("utf-8", errors="replace").lstrip("\ufeff")
    return Source(p if data is None else io.BytesIO(data), text)


def _not_utf8(p: str, data: bytes | None, head: bytes) -> Source | None:
    """Log ``p`` decoded as Windows-1252 (Latin-1 where a byte is undefined in it: every byte
    is a character there) when its head is not UTF-8, with one warning naming the byte and the
    line it makes (none when only ``#`` comments are not UTF-8: they are no data); None for
    UTF-8 (read as before). A rig on Windows writes ``°`` and ``µ`` as one byte: read as UTF-8
    they became replacement characters, and a header's unit (``time [µs]``) or a mapped name
    was lost, the refusal never naming the encoding."""
    if _bad_byte(head) is None:
        return None
    if data is None:
        with open(p, "rb") as fh:
            data = fh.read()
    text = _windows_1252(data)
    lines = head.split(b"\n")
    bad = ((k, _bad_byte(ln)) for k, ln in enumerate(lines) if not ln.lstrip().startswith(b"#"))
    k, byte = next(((k, b) for k, b in bad if b is not None), (None, None))
    if k is not None:
        warn(f"is not UTF-8 text (byte 0x{byte:02x} in line {k + 1}): read as Windows-1252 "
             f"(Latin-1), which makes line {k + 1} {_windows_1252(lines[k]).strip()[:60]!r}; save "
             "the log as UTF-8 to read it without this warning", p)
    return Source(io.StringIO(text), text[:HEAD_BYTES])


def _windows_1252(raw: bytes) -> str:
    """``raw`` decoded as Windows-1252, or Latin-1 where a byte is undefined in it."""
    try:
        return raw.decode("cp1252")
    except UnicodeDecodeError:
        return raw.decode("latin-1")


def _bad_byte(raw: bytes) -> int | None:
    """The first byte of ``raw`` that makes it no UTF-8, None where it is UTF-8 (a character
    cut at its end is no error: a head is cut)."""
    try:
        codecs.getincrementaldecoder("utf-8")().decode(raw)
    except UnicodeDecodeError as exc:
        return raw[exc.start]
    return None


#: bytes read from a log's end to find its last line
TAIL_BYTES = 4096


def cut_inside_last_row(src: Source) -> bool:
    """Whether the log ends inside a data row: its last line, not blank, has no line end after
    it (NUL padding after the last line end, a logger's, is no row). A logger stopped or a copy
    interrupted while the file was being written leaves such a row, perhaps cut inside its last
    number (``2.03712649`` read as ``2.03712``): nothing in the row itself tells."""
    h = src.handle
    if isinstance(h, str):
        with open(h, "rb") as fh:
            size = fh.seek(0, os.SEEK_END)
            fh.seek(max(0, size - TAIL_BYTES))
            tail = fh.read()
    elif hasattr(h, "getbuffer"):  # a pipe's bytes in memory: no copy of the whole
        with h.getbuffer() as view:
            tail = bytes(view[-TAIL_BYTES:])
    else:
        tail = h.getvalue()[-TAIL_BYTES:]
    if isinstance(tail, str):
        tail = tail.encode("utf-8", errors="replace")
    tail = tail.rstrip(b"\x00 \t")
    return bool(tail) and not tail.endswith((b"\n", b"\r"))


def sniff(src: Source, nskip: int) -> Source:
    """Set ``src.sep`` and ``src.decimal`` from the header and the first data rows."""
    lines = [ln for ln in src.head.splitlines()[nskip:] if ln.strip()]
    if len(lines) < 2:
        return src
    header, rows = lines[0], lines[1:1 + SNIFF_ROWS]
    if len(rows) > 1 and len(src.head.encode()) >= HEAD_BYTES:
        rows = rows[:-1]  # the last line of the head may be cut
    for sep in (";", "\t", WHITESPACE):
        k = _fields(header, sep) - 1
        if k and "," not in header and all(_fields(r, sep) == k + 1 for r in rows):
            src.sep = sep
            if any(re.search(r"\d,\d", r) for r in rows):
                src.decimal = ","
            break
    return src


def separator_hint(src: Source, nskip: int) -> str:
    """Why a file that looks ``;``- or tab-separated was not read as such ('' if it does not)."""
    header = next((ln for ln in src.head.splitlines()[nskip:] if ln.strip()), "")
    for sep, word in ((";", "semicolon"), ("\t", "tab")):
        if sep in header and "," not in header:
            return (f"; it looks {word}-separated, but its rows do not all have as many fields "
                    "as the header")
    return ""


def _fields(line: str, sep: str) -> int:
    return len(line.split() if sep == WHITESPACE else line.split(sep))


def _numbers(line: str, sep: str) -> bool:
    """True when every field of ``line`` is a number (a data row, not a header)."""
    try:
        [float(c.strip().strip('"')) for c in (line.split() if sep == WHITESPACE
                                              else line.split(sep)) if c.strip()]
    except ValueError:
        return False
    return True


def check_header(src: Source, nskip: int, p: str) -> None:
    """Refuse a first line that is no header: a title or note written without ``#`` (``Logged by
    rig 3 on ...``) has fewer fields than the rows below, and a later line with as many fields
    as the rows, not numbers, above a row of numbers, is the header. The message names both
    lines and the fix."""
    lines = [(k, ln) for k, ln in enumerate(src.head.splitlines()) if k >= nskip and ln.strip()]
    counts = [_fields(ln, src.sep) for _, ln in lines[:SNIFF_ROWS + 1]]
    if len(counts) < 3:
        return
    width = max(set(counts[1:]), key=counts[1:].count)  # the rows' number of fields
    j = next((j for j, c in enumerate(counts) if c == width), 0)
    if (counts[0] >= width or j == 0 or j + 1 >= len(lines) or _numbers(lines[j][1], src.sep)
            or not _numbers(lines[j + 1][1], src.sep)  # the header must head rows of numbers
            or any(ln.count('"') % 2 for _, ln in lines[:j + 1])):  # a quoted name across lines
        return
    (k0, first), (kj, header) = lines[0], lines[j]
    raise LogError(f"line {k0 + 1} ({first.strip()[:40]!r}) is no header ({counts[0]} field(s), "
                   f"the rows {width}); line {kj + 1} ({header.strip()[:40]!r}) is: start the "
                   "lines above it with '#' or delete them", p)


def header_names(src: Source, nskip: int) -> list[str]:
    """The raw header's names (stripped, unquoted), for the duplicate-name check."""
    lines = src.head.splitlines()[nskip:]
    k = next((j for j, ln in enumerate(lines) if ln.strip()), None)
    if k is None:
        return []
    cells = lines[k].split() if src.sep == WHITESPACE else lines[k].split(src.sep)
    names = [c.strip().strip('"') for c in cells]
    if k == len(lines) - 1:  # the header runs past the head: its last name may be cut
        names = names[:-1]
    return names


#: an ISO 8601 date and time (``2024-03-01 12:00:00.000``, ``2024-03-01T12:00:00Z``, with an
#: offset ``+01:00``): a time column a logger wrote as wall-clock time
_DATETIME = re.compile(r"^\d{4}-\d{2}-\d{2}[T ]\d{2}:\d{2}(:\d{2}([.,]\d+)?)?\s*"
                       r"(Z|[+-]\d{2}(:?\d{2})?)?$")


def is_datetime_column(df, name: str) -> bool:
    """True when column ``name`` of ``df`` holds times as such: text whose first cell is an ISO
    8601 date-time, or pandas date-times or durations (``datetime64``, ``timedelta64``)."""
    raw = df[name]
    if isinstance(raw, np.ndarray):
        return False
    if raw.dtype.kind in "mM":
        return True
    if raw.dtype.kind in "biufc":
        return False
    k = raw.first_valid_index()
    return k is not None and bool(_DATETIME.match(str(raw.loc[k]).strip()))


def _seconds(stamps, first: str, src: str, p: str) -> np.ndarray:
    """Date-times (a tz-aware pandas Series, NaT where a cell is none; ``first``: the first cell
    as written) as seconds from the first; a warning says so."""
    ns = stamps.dt.tz_convert(None).to_numpy(dtype="datetime64[ns]").astype(np.int64)
    nat = stamps.isna().to_numpy()
    out = (ns - (ns[~nat][0] if (~nat).any() else 0)).astype(float) * 1e-9
    out[nat] = np.nan  # a cell that is no date-time: the time check names its row
    warn(f"column '{src}' holds date-times (the first {first[:40]!r}): read as t, in seconds "
         "from the first", p)
    return out


def numeric_column(df, src: str, p: str, strict: bool = True, times: bool = False) -> np.ndarray:
    """Column ``src`` as floats; a text cell that is not a number is an error naming its row
    (``strict``) or NaN. ``df`` is a DataFrame or a :class:`pmdcid.io.plain.PlainFrame`.
    ``times``: a column of ISO 8601 date-times (:func:`is_datetime_column`) is read as seconds
    from its first (with a warning)."""
    raw = df[src]
    if isinstance(raw, np.ndarray):  # a PlainFrame's column: plain float64 numbers
        if raw.base is None and raw.dtype == float:  # a column stored alone (chunked read)
            return raw
        return np.array(raw, dtype=float)  # a copy: no view keeps the whole table alive
    import pandas as pd

    if times and raw.dtype.kind == "m":  # durations: elapsed seconds as they stand
        return raw.dt.total_seconds().to_numpy(dtype=float)
    if times and is_datetime_column(df, src):
        text = raw.dtype.kind != "M"
        stamps = pd.to_datetime(raw, format="ISO8601" if text else None, utc=True,
                                errors="coerce")
        first = raw.loc[raw.first_valid_index()] if raw.first_valid_index() is not None else ""
        return _seconds(stamps, str(first).strip(), src, p)
    col = pd.to_numeric(raw, errors="coerce").to_numpy(dtype=float)
    if strict and not pd.api.types.is_numeric_dtype(raw.dtype):  # text cells (object or str)
        cells = raw.astype(str).str.strip()
        blank = raw.isna().to_numpy() | cells.str.lower().isin(["nan", "", "na", "null"]).to_numpy()
        notnum = np.isnan(col) & ~blank
        if notnum.any():
            comma = pd.to_numeric(cells.str.replace(",", ".", regex=False), errors="coerce")
            row, why = _bad_cell(cells, notnum, blank, comma.notna().to_numpy())
            raise LogError(f"column '{src}' holds non-numeric value {_shown(cells.iloc[row])} "
                           f"(data row {row + 1}): {why}; fix or remove that row (or map another "
                           "column)", p)
    return col


def _shown(cell: str) -> str:
    """A cell for a message: its first 30 characters quoted, NUL bytes counted, not printed."""
    if "\x00" not in cell:
        return repr(cell[:30])
    return f"{cell.replace(chr(0), '')[:30]!r} with {cell.count(chr(0))} NUL byte(s)"


#: a number grouped in thousands: ``1.234,5`` (decimal comma) or ``1,234.5`` (decimal point)
_GROUPED = {",": re.compile(r"^[+-]?\d{1,3}(\.\d{3})+(,\d*)?$"),
            ".": re.compile(r"^[+-]?\d{1,3}(,\d{3})+(\.\d*)?$")}


def _bad_cell(cells, notnum: np.ndarray, blank: np.ndarray,
              comma: np.ndarray) -> tuple[int, str]:
    """The first cell of text column ``cells`` that is no number in the column's own decimal
    mark (the mark most of its cells are numbers in: ``comma`` flags those that are numbers with
    a decimal comma), and what is wrong with it."""
    mark = "," if comma.sum() > (~notnum & ~blank).sum() else "."
    bad = ~comma & ~blank if mark == "," else notnum
    row = int(np.flatnonzero(bad)[0]) if bad.any() else int(np.flatnonzero(notnum)[0])
    if _GROUPED[mark].match(cells.iloc[row]):
        sep = "." if mark == "," else ","
        return row, (f"a thousands separator ('{sep}') in a number with '{mark}' decimals: "
                     "export numbers without digit grouping")
    return row, f"numbers only, with '{mark}' decimals"


def column_specs(cols: list[str], mapping, canonical, p: str):
    """Spec of each canonical column, and the mapping-file lines skipped for this log."""
    have = set(cols)
    specs = {c: ColumnSpec(c, c) for c in canonical if c in have}
    skipped: dict[str, str] = {}
    slashed = [c for c in cols if "/" in c]
    for canon, spec in mapping.specs.items():
        if slashed or spec.pending is not None:
            try:
                spec = resolve(spec, slashed)
            except LogError as exc:
                if spec.origin is not None:  # a mapping-file line naming a signal not here
                    skipped[canon] = f"{spec.origin} ({spec.text}) was skipped: no such signal"
                    continue
                raise type(exc)(str(exc), p) from None  # a MappingError stays one
        missing = [r for r in spec.refs if r not in have]
        if missing and spec.origin is not None and len(missing) == len(spec.refs):
            skipped[canon] = f"{spec.origin} ({spec.text}) was skipped: no column '{missing[0]}'"
            continue
        if missing:
            raise LogError(f"column mapping {canon}={missing[0]}: no column '{missing[0]}' "
                           f"(columns are {short_list(cols)})", p)
        specs[canon] = spec
    _annotated_specs(cols, specs, p)
    specs.update(_any_case(cols, canonical, specs))
    return one_input(specs, set(mapping.specs), p), skipped


def one_input(specs: dict, mapped: set, p: str) -> dict:
    """``specs`` with one input column: where a log holds both ``v`` and ``tau``, the one the
    mapping names (``mapped``: the canonical names of ``-c``/``--map``), else ``v`` as before,
    the other left out with a warning (its source stays among the extra columns). Both mapped
    is refused: a log drives the motor by one of them. (Fuzzing: ``-c tau=COLUMN`` on a log
    with a ``v`` column fitted the voltage and never said the torque went unused.)"""
    if not {"v", "tau"} <= set(specs):
        return specs
    named = [c for c in ("v", "tau") if c in mapped]
    if len(named) == 2:
        raise LogError("both 'v' and 'tau' are mapped: a log has one input, the voltage or the "
                       "torque; map only the one that drives the motor", p)
    keep = named[0] if named else "v"
    drop = "tau" if keep == "v" else "v"
    why = "mapped" if named else "the voltage, as a log with both is read"
    hint = "" if named else "; map -c tau=tau to drive it by the torque"
    warn(f"holds both 'v' and 'tau': '{keep}' is the input ({why}), '{drop}' (column "
         f"'{specs[drop].source}') is not used{hint}", p)
    return {c: s for c, s in specs.items() if c != drop}


def _any_case(cols: list[str], canonical, specs: dict) -> dict:
    """Specs of the canonical columns a header names in another case (``T``, ``OMEGA``,
    ``Omega``): last, for a signal nothing else gives (no column of the exact name, no
    mapping, no header naming its quantity and unit: ``Time (s),v,omega,T`` reads ``Time (s)`` as
    t and leaves the temperature ``T`` alone; beside a column named ``time...``, ``T`` is never
    t), where exactly one column matches and nothing reads it."""
    used = {r for spec in specs.values() for r in spec.refs}
    timed = any(h.lower().startswith("time") for h in cols)  # then T is a temperature or torque
    out = {}
    for c in canonical:
        hits = [h for h in cols if h.lower() == c and h not in used]
        if c not in specs and len(hits) == 1 and not (c == "t" and timed):
            out[c] = ColumnSpec(c, hits[0], text=f"{c}={hits[0]}")
    return out


def _annotated_specs(cols: list[str], specs: dict, p: str) -> None:
    """Add the canonical columns whose headers say quantity and unit (:mod:`.headers`), with a
    note naming the conversion, where neither a column of that name nor a mapping gives them."""
    from pmdcid.io.headers import claimed

    used = {r for spec in specs.values() for r in spec.refs}
    said = []
    for canon, (col, factor) in claimed([c for c in cols if c not in used], specs).items():
        specs[canon] = ColumnSpec(canon, col, factor, text=f"{canon}={col}")
        said.append(f"'{col}' as {canon}" + ("" if factor == 1.0 else f" x {factor:.6g}"))
    if said:
        warn(f"column(s) read by the quantity and unit their headers name: {', '.join(said)} "
             "(map a column with -c to read it otherwise)", p)
