"""Column mappings: rename, scale and offset any column of a log into canonical SI columns.

Syntax of one mapping (command line ``-c/--column``, or one line of a mapping file)::

    CANON=[-]SOURCE[*FACTOR...][/DIVISOR...][+OFFSET|-OFFSET]

``value_SI = raw * factors / divisors + offset`` (a leading ``-`` negates ``raw``). Factors may
be numbers, ``pi`` or unit names (``rpm``, ``deg``, ``rev``, ``ms``, ``us``, ``mA``, ``mV``,
``mNm``, ``mm``, ``krpm``) that stand for the factor converting that unit to SI. Examples::

    omega=speed_rpm*rpm            # rpm -> rad/s
    theta=encoder*2*pi/4096        # encoder counts (4096 per revolution) -> rad
    v=pwm_counts*12/1023           # 10-bit PWM on a 12 V supply -> V
    omega=tacho_V*150*rpm          # tachometer at 1 V per 150 rpm -> rad/s
    omega=-speed_rpm*rpm           # a sensor counting the other way (a leading minus)
    t=time_ms*ms                   # milliseconds -> s
    i=current_mA*mA-0.002          # mA -> A, minus a 2 mA sensor offset
    theta=angle                    # plain rename

When the right-hand side holds quotes or parentheses it is read by the expression grammar of
:mod:`pmdcid.io.expr`: quoted column names that may hold anything, ``+ - * /``, parentheses and
``sign()``/``abs()``::

    omega="speed [rad/s]"                # a column name with spaces and a '/'
    v=pwm*sign(dir)*12/255               # sign-magnitude PWM: a pwm and a direction column
    v=(pwm-128)*12/128                   # offset-binary PWM

A mapping file holds one mapping per line (``#`` starts a comment), or a JSON object
``{"omega": "speed_rpm*rpm", ...}``. Command-line mappings override the file's; a column mapped
twice by the command line, or twice by one file, is an error naming both (the last would
silently win). A file line whose source column(s) a log lacks is skipped for that log, so one
file serves logs with different columns; a command that then misses the column names the
skipped line.
"""

from __future__ import annotations

import json
import math
import re
from dataclasses import dataclass, field
from pathlib import Path

from pmdcid.errors import LogError, MappingError
from pmdcid.io.expr import evaluate, parse_expr, refs

#: the canonical column names of a log (docs/units.md): time [s], voltage [V], torque [N m],
#: current [A], speed [rad/s], angle [rad]
CANONICAL: tuple[str, ...] = ("t", "v", "tau", "i", "omega", "theta")
#: a controller's set-points [rad/s, rad]: mapped like a canonical column (``-c
#: omega_ref=target_rpm*rpm``), kept in ``Log.extra``; they mark a log as closed loop
SETPOINTS: tuple[str, ...] = ("omega_ref", "theta_ref")
#: the words that name a set-point column in a log's own header (``targetSpeed``, ``speed_sp``,
#: ``setpoint``, ``w_ref``, ``desired_rpm``)
SETPOINT_WORDS = frozenset({"ref", "reference", "setpoint", "sp", "target", "desired", "demand",
                            "goal"})


def is_setpoint(name: str) -> bool:
    """True when a column's name says it holds a controller's set-point: one of
    :data:`SETPOINTS`, or a word of :data:`SETPOINT_WORDS` in it (words split at
    non-letters and at camelCase: ``targetSpeed`` -> target, speed)."""
    spaced = re.sub(r"([a-z0-9])([A-Z])", r"\1 \2", str(name))
    words = {w.lower() for w in re.split(r"[^A-Za-z]+", spaced) if w}
    return name in SETPOINTS or bool(words & SETPOINT_WORDS) or "setpoint" in name.lower()

UNITS: dict[str, float] = {
    "pi": math.pi,
    "rpm": 2 * math.pi / 60.0,
    "krpm": 2000 * math.pi / 60.0,
    "rps": 2 * math.pi,
    "rev": 2 * math.pi,
    "deg": math.pi / 180.0,
    "ms": 1e-3,
    "us": 1e-6,
    "mA": 1e-3,
    "mV": 1e-3,
    "mNm": 1e-3,
    "mm": 1e-3,
}

_MAP_RE = re.compile(r"^\s*([A-Za-z_][A-Za-z0-9_]*)\s*=\s*(.+?)\s*$")


@dataclass(frozen=True)
class ColumnSpec:
    """One canonical column taken from a source column: ``canon = source * scale + offset``."""

    canon: str
    source: str
    scale: float = 1.0
    offset: float = 0.0
    #: parsed expression (:mod:`pmdcid.io.expr`) when the mapping is more than source*k+offset
    expr: tuple | None = None
    #: where a mapping-file line came from, e.g. ``rig.map line 3`` (None: command line)
    origin: str | None = None
    text: str = ""
    #: a mapping whose right-hand side holds a ``/`` and did not parse as a scale: a signal name
    #: such as an MCAP topic or a TDMS ``group/channel``, resolved against the file's names
    #: (:func:`resolve`); this is the parse error to raise when no name matches
    pending: str | None = None

    @property
    def refs(self) -> list[str]:
        """Every column the mapping reads."""
        return refs(self.expr) if self.expr is not None else [self.source]

    def evaluate(self, get):
        """The canonical column, ``get(name)`` giving a source column as a float array."""
        if self.expr is not None:
            return evaluate(self.expr, get)
        return get(self.source) * self.scale + self.offset


@dataclass
class ColumnMap:
    """A set of column specs keyed by canonical name."""

    specs: dict[str, ColumnSpec] = field(default_factory=dict)
    #: cut-off [Hz] of the zero-phase filter deriving speed from angle (None: default)
    cutoff_hz: float | None = None

    def merged(self, other: ColumnMap) -> ColumnMap:
        """Return a map where ``other``'s specs (and cut-off, if set) override this one's."""
        fc = other.cutoff_hz if other.cutoff_hz is not None else self.cutoff_hz
        return ColumnMap({**self.specs, **other.specs}, fc)

    def __bool__(self) -> bool:
        return bool(self.specs) or self.cutoff_hz is not None

    def sources(self, present) -> dict[str, tuple[str, float, float]]:
        """Canonical column -> (source, scale, offset) of each linear mapping of a column in
        ``present`` that changes its unit (``Log.sources``: the log's own unit, for display)."""
        return {c: (s.source, s.scale, s.offset) for c, s in self.specs.items()
                if c in present and c != "t" and s.expr is None
                and (s.scale, s.offset) != (1.0, 0.0)}


def _number(token: str, text: str) -> float:
    token = token.strip()
    if token in UNITS:
        return UNITS[token]
    try:
        value = float(token)
    except ValueError:
        known = ", ".join(sorted(UNITS))
        raise LogError(
            f"column mapping '{text}': '{token}' is neither a number nor a unit ({known})"
        ) from None
    if not math.isfinite(value):
        raise LogError(f"column mapping '{text}': '{token}' is not a finite number")
    return value


def parse_spec(text: str) -> ColumnSpec:
    """Parse one mapping ``CANON=SOURCE*FACTOR/DIVISOR+OFFSET`` (see module docstring).

    A source name may hold ``/`` (an MCAP topic ``/motor/state.velocity``, a TDMS or MDF
    ``group/channel``): such a mapping is kept whole and read against the file's own names
    (:func:`resolve`), the longest name the right-hand side starts with being the source."""
    try:
        return _parse_spec(text)
    except LogError as exc:
        m = _MAP_RE.match(text)
        if (m is None or "/" not in m.group(2) or m.group(1) not in CANONICAL + SETPOINTS
                or any(c in m.group(2) for c in "\"'()")):  # the expression grammar's own error
            raise
        rhs = m.group(2).strip()
        return ColumnSpec(m.group(1), rhs, text=text.strip(), pending=str(exc))


def resolve(spec: ColumnSpec, names) -> ColumnSpec:
    """``spec`` read against a file's signal or column ``names``: when its right-hand side starts
    with a name holding ``/`` (longer than the source parsed), that name is the source and the
    rest is its scale and offset. A pending spec no name matches is, in a file whose names hold
    ``/``, a name of that kind the file lacks when it reads as one (the source then names it:
    the reader says the file has no such signal and lists its names); else its parse error, a
    :class:`~pmdcid.errors.MappingError` (a usage error), as is a scale that does not parse."""
    if spec.expr is not None:
        return spec
    rhs = spec.text.split("=", 1)[1].strip() if "=" in spec.text else spec.source
    best = max((n for n in names if "/" in n and (rhs == n or (
        rhs.startswith(n) and rhs[len(n)] in "*/+-"))), key=len, default=None)
    if best is None or best == spec.source:
        if spec.pending is None or spec.source in names:
            return spec
        absent = _slashed_name(spec, rhs) if any("/" in n for n in names) else None
        if absent is None:
            raise MappingError(spec.pending)
        return absent
    tail = _tail(spec, rhs[len(best):])
    if tail is None:
        raise MappingError(f"column mapping '{spec.text}': '{rhs[len(best):]}' after "
                           f"'{best}' is not a scale or an offset (*K, /K, +K, -K; K a "
                           f"number or a unit: {', '.join(sorted(UNITS))})")
    return ColumnSpec(spec.canon, best, tail.scale, tail.offset, None, spec.origin, spec.text)


def _tail(spec: ColumnSpec, rest: str) -> ColumnSpec | None:
    """``rest`` (what follows a source name) read as a scale and offset, or None."""
    try:
        tail = _parse_spec(f"{spec.canon}=x{rest}")
    except LogError:
        return None
    return tail if tail.source == "x" and tail.expr is None else None


def _slashed_name(spec: ColumnSpec, rhs: str) -> ColumnSpec | None:
    """``rhs`` read as a signal name holding ``/`` (the shortest that a scale and offset
    follow) that the file lacks, or None when it does not read so."""
    for k in [k for k, c in enumerate(rhs) if c in "*/+-"] + [len(rhs)]:
        name = rhs[:k].strip()
        tail = _tail(spec, rhs[k:]) if "/" in name and "*" not in name else None
        if tail is not None:
            return ColumnSpec(spec.canon, name, tail.scale, tail.offset, None, spec.origin,
                              spec.text)
    return None


def _parse_spec(text: str) -> ColumnSpec:
    if any(not c.isprintable() for c in text):
        raise LogError(f"column mapping {text!r} holds control characters")
    m = _MAP_RE.match(text)
    if not m:
        raise LogError(f"column mapping '{text}' is not of the form CANON=SOURCE[*SCALE][+OFFSET]")
    canon, expr = m.group(1), m.group(2)
    if canon not in CANONICAL + SETPOINTS:
        raise LogError(
            f"column mapping '{text}': '{canon}' is not a canonical column "
            f"({', '.join(CANONICAL)}) or a set-point ({', '.join(SETPOINTS)})"
        )
    if any(c in expr for c in "\"'()"):  # quoted names, parentheses, functions: the grammar
        tree = parse_expr(expr, text, UNITS)
        return ColumnSpec(canon, refs(tree)[0], expr=tree, text=text.strip())
    # offset: a trailing +number or -number (not part of an exponent)
    offset = 0.0
    om = re.search(r"(?<![eE*/])([+-])\s*([0-9.][0-9.eE+-]*|pi)\s*$", expr)
    if om and om.start() > 0:
        offset = _number(om.group(2), text) * (1.0 if om.group(1) == "+" else -1.0)
        expr = expr[: om.start()].strip()
    tokens = re.split(r"([*/])", expr)
    source = tokens[0].strip().strip('"')
    scale = 1.0
    if source.startswith("-"):  # a sensor counting the other way: -speed*rpm
        source, scale = source[1:].strip(), -1.0
    if not source:
        raise LogError(f"column mapping '{text}' names no source column")
    for op, tok in zip(tokens[1::2], tokens[2::2], strict=True):
        val = _number(tok, text)
        if op == "*":
            scale *= val
        else:
            if val == 0:
                raise LogError(f"column mapping '{text}' divides by zero")
            scale /= val
    return ColumnSpec(canon, source, scale, offset, text=text.strip())


def _strip_comment(line: str) -> str:
    """A mapping-file line without its ``#`` comment (a ``#`` inside quotes is kept)."""
    quote = None
    for k, c in enumerate(line):
        if c in "\"'":
            quote = None if quote == c else (quote or c)
        elif c == "#" and quote is None:
            return line[:k].strip()
    return line.strip()


def parse_mapping(items: list[str] | tuple[str, ...] = (),
                  path: str | Path | None = None) -> ColumnMap:
    """Build a :class:`ColumnMap` from a mapping file (optional) and command-line items."""
    specs: dict[str, ColumnSpec] = {}
    if path is not None:
        from pmdcid.io.text import read_text

        p = Path(path)
        try:
            text = read_text(p)
        except OSError as exc:
            raise LogError(f"cannot read column-mapping file ({exc.strerror})", p) from None
        except UnicodeDecodeError:
            raise LogError("column-mapping file is not UTF-8 text: save it as plain text",
                           p) from None
        lines: list[str]
        if text.lstrip().startswith("{"):
            try:
                obj = json.loads(text, object_pairs_hook=_Pairs)
            except json.JSONDecodeError as exc:
                raise LogError(f"mapping file is not valid JSON ({exc.msg})", p) from None
            except (ValueError, RecursionError) as exc:
                raise LogError(f"mapping file is not usable JSON ({str(exc)[:60]})", p) from None
            if not isinstance(obj, _Pairs):
                raise LogError("mapping file must hold a JSON object {\"omega\": \"...\"}", p)
            lines = [f"{k}={v}" for k, v in obj]
        else:
            lines = [_strip_comment(ln) for ln in text.splitlines()]
        for k, ln in enumerate(lines):
            if ln:
                try:
                    spec = parse_spec(ln)
                except LogError as exc:
                    raise LogError(str(exc), p) from None
                where = f"{p.name} {'entry' if text.lstrip().startswith('{') else 'line'} {k + 1}"
                spec = ColumnSpec(spec.canon, spec.source, spec.scale, spec.offset, spec.expr,
                                  where, spec.text)
                _add_once(specs, spec, p)
    given: dict[str, ColumnSpec] = {}
    for item in items:
        _add_once(given, parse_spec(item))
    return ColumnMap({**specs, **given})


def _add_once(specs: dict[str, ColumnSpec], spec: ColumnSpec, path=None) -> None:
    """Add ``spec`` to ``specs``; a second, different mapping of the same canonical column (two
    ``-c omega=...``, or two lines of one mapping file) is refused: the last would silently win.
    The same mapping given twice is harmless and kept once."""
    first = specs.get(spec.canon)
    if first is not None and _meaning(first) != _meaning(spec):
        raise LogError(f"{spec.canon} is mapped twice, by {_said(first)} and by {_said(spec)}: "
                       "keep one", path)
    specs[spec.canon] = spec


def _meaning(spec: ColumnSpec) -> tuple:
    """What a mapping computes, however it is spelt (blanks, ``*1``)."""
    return spec.source, spec.scale, spec.offset, spec.expr, spec.pending


def _said(spec: ColumnSpec) -> str:
    """Where a mapping was given, for messages: ``-c omega=x`` or ``rig.map line 2 (omega=x)``."""
    return f"{spec.origin} ({spec.text})" if spec.origin else f"-c {spec.text}"


class _Pairs(list):
    """A JSON object as its (key, value) pairs, in order: a key given twice stays visible."""


#: what the front door's ``mapping=`` takes, for its one-line refusal
MAPPING_FORMS = ("a ColumnMap, a 'CANON=SRC*K+OFF' string as -c takes it, a list of them, a dict "
                 "{'omega': 'speed_rpm*rpm'}, or a mapping file's path (as --map)")


def as_mapping(mapping) -> ColumnMap | None:
    """``mapping`` as the library's :class:`ColumnMap`, from every form the command line takes:
    None; a ColumnMap (as is); a ``"CANON=SRC*K+OFF"`` string (one ``-c``); a list or tuple of
    them (repeated ``-c``); a dict ``{CANON: "SRC*K+OFF"}`` (as a JSON mapping file); a mapping
    file's path (a :class:`~pathlib.Path`, or a string without ``=``: ``--map``). Anything else,
    or an item that is not a mapping, is one :class:`LogError` line naming what is accepted."""
    if mapping is None or isinstance(mapping, ColumnMap):
        return mapping
    if isinstance(mapping, str) and "=" in mapping:
        return parse_mapping([mapping])
    if isinstance(mapping, (str, Path)) or hasattr(mapping, "__fspath__"):
        return parse_mapping(path=Path(mapping))
    if isinstance(mapping, dict):
        bad = [k for k, v in mapping.items()
               if not isinstance(k, str) or not isinstance(v, (str, int, float))
               or isinstance(v, bool)]
        if bad:
            raise LogError(f"mapping: entry {str(bad[0])[:40]!r} must map a column name to "
                           f"'SRC*K+OFF' (a string); mapping takes {MAPPING_FORMS}")
        return parse_mapping([f"{k}={v}" for k, v in mapping.items()])
    if isinstance(mapping, (list, tuple)):
        bad = [x for x in mapping if not isinstance(x, str)]
        if bad:
            raise LogError(f"mapping: item {str(bad[0])[:40]!r} ({type(bad[0]).__name__}) is "
                           f"not a 'CANON=SRC*K+OFF' string; mapping takes {MAPPING_FORMS}")
        return parse_mapping(list(mapping))
    raise LogError(f"mapping: a {type(mapping).__name__} is not a column mapping; mapping takes "
                   f"{MAPPING_FORMS}")
