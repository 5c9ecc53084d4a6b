"""Model parameters and the model file (JSON, written atomically).

Base parameters (docs/model.md): ``R`` [ohm], ``L`` [H], ``km`` [N m/A], ``J`` [kg m^2],
``b`` [N m s/rad] (linear viscous from fit-mechanical), ``bv`` [N m s/rad], ``bc`` [N m],
``dz`` [N m] (torque break point of the hard dead zone). Effect parameters are declared by the
effects in :mod:`pmdcid.model.effects`.
"""

from __future__ import annotations

import hashlib
import json
import math
import os
from dataclasses import dataclass, field
from typing import Any

from pmdcid.errors import ModelError
from pmdcid.model.effects import EFFECTS, param_spec, stderr_words, unit_of, within_range

FORMAT_VERSION = 1


@dataclass
class Parameter:
    """One identified parameter: value, standard error (NaN if unknown), unit, producing stage.

    ``interval``: (low, high) [unit] when the logs only bound the parameter (the dead zone
    under the Coulomb friction, an L/R under the sample period): ``stderr`` is then NaN and
    ``value`` is the point inside that simulations use. ``caveat``: the words that go with the
    number where it is not a plain estimate ± standard error (why it is only bounded and what
    to record; a standard error that is only a lower bound). Both in the model file as
    ``interval`` and ``caveat`` (only when set)."""

    value: float
    stderr: float = math.nan
    unit: str = ""
    stage: str = ""
    interval: tuple[float, float] | None = None
    caveat: str = ""

    def to_json(self) -> dict[str, Any]:
        d: dict[str, Any] = {"value": self.value, "unit": self.unit, "stage": self.stage}
        d["stderr"] = self.stderr if math.isfinite(self.stderr) else None
        out = {k: d[k] for k in ("value", "stderr", "unit", "stage")}
        if self.interval is not None:
            out["interval"] = [float(self.interval[0]), float(self.interval[1])]
        if self.caveat:
            out["caveat"] = self.caveat
        return out

    @property
    def determined(self) -> bool:
        """Whether other data put this value (a stage's estimate or a given value), not a start
        value or a bound."""
        return self.interval is None and self.stage not in ("", "start")


@dataclass
class Model:
    """A motor model: parameters, extra effects (catalogue names), and free-form extra keys."""

    parameters: dict[str, Parameter] = field(default_factory=dict)
    effects: list[str] = field(default_factory=list)
    extra: dict[str, Any] = field(default_factory=dict)
    path: str | None = None
    #: (file, what it held) when the model was read or last saved (:func:`file_digest`; None:
    #: neither). Saving back to that file checks it first: optimistic locking, see
    #: :func:`save_model`
    digest: tuple[str, str] | None = field(default=None, repr=False, compare=False)

    def value(self, name: str, default: float | None = None) -> float:
        if name in self.parameters:
            return self.parameters[name].value
        if default is not None:
            return default
        raise ModelError(f"model has no parameter '{name}'", self.path)

    def has(self, name: str) -> bool:
        return name in self.parameters

    def set(self, name: str, value: float, stderr: float = math.nan, unit: str | None = None,
            stage: str = "", caveat: str = "") -> None:
        """Write ``name`` = ``value`` ± ``stderr`` [``unit``, default its declared one]. A
        standard error that spans the parameter's whole declared range
        (:func:`pmdcid.model.effects.range_only`: a bounded parameter whose value +-2 standard
        errors covers every value it may take) is written as none (NaN, null in the file) with
        the words saying so, before ``caveat``; one at a declared bound (the fit stopped there)
        as the interval from the bound two standard errors into the range, with the words
        (:func:`pmdcid.model.effects.stderr_words`)."""
        if unit is None:
            unit = unit_of(name)
        words, interval = stderr_words(name, float(value), float(stderr))
        if words:
            stderr, caveat = math.nan, "; ".join(c for c in (words, caveat) if c)
        self.parameters[name] = Parameter(float(value), float(stderr), unit, stage,
                                          interval=interval, caveat=caveat)

    def set_bounded(self, name: str, low: float, high: float, value: float | None = None, *,
                    unit: str | None = None, stage: str = "", caveat: str = "") -> bool:
        """Write ``name`` as known only to lie in [``low``, ``high``] (``value``: the point
        inside that simulations use, default the midpoint; no standard error). A value other
        data determined (:attr:`Parameter.determined`) that lies inside is kept: these logs
        agree with it and cannot refine it. The interval is cut to the parameter's range
        (:func:`pmdcid.model.effects.within_range`). Returns whether the model changed."""
        low, high = within_range(name, low, high)
        if kept_within(self.parameters.get(name), low, high):
            return False
        v = 0.5 * (low + high) if value is None else float(value)
        self.parameters[name] = Parameter(v, math.nan, unit_of(name) if unit is None else unit,
                                          stage, (float(low), float(high)), caveat)
        return True

    def require(self, *names: str, stage: str = "") -> None:
        missing = [n for n in names if n not in self.parameters]
        if missing:
            hint = {
                "R": "run fit-electrical first", "L": "run fit-electrical first",
                "km": "give --km (datasheet torque constant) or add it to the model",
                "J": "run fit-mechanical first", "b": "run fit-mechanical first",
            }.get(missing[0], "run the stage that identifies it first")
            what = f" for {stage}" if stage else ""
            raise ModelError(f"model lacks {', '.join(missing)}{what}: {hint}", self.path)

    def add_effect(self, name: str) -> None:
        if name not in self.effects:
            self.effects.append(name)

    def copy(self) -> Model:
        return Model({k: Parameter(**vars(v)) for k, v in self.parameters.items()},
                     list(self.effects), json.loads(json.dumps(self.extra)), self.path,
                     self.digest)

    @classmethod
    def load(cls, path: str | os.PathLike, must_exist: bool = True) -> Model:
        """Read a model file (see :func:`load_model`)."""
        return load_model(path, must_exist)

    def save(self, path: str | os.PathLike) -> None:
        """Write this model to ``path`` atomically (see :func:`save_model`)."""
        save_model(self, path)

    def to_si(self, *, km: float, R: float) -> Model:
        """An SI copy of a lumped (per-volt) model given km [N m/A] and R [ohm]
        (:func:`pmdcid.model.lumped.to_si`); raises ModelError for a model that is not lumped."""
        from pmdcid.model.lumped import is_lumped, to_si

        if not is_lumped(self):
            raise ModelError("to_si: the model is not lumped (its parameters are SI already)",
                             self.path)
        return to_si(self, km, R)

    def rows(self) -> list[tuple]:
        """(name, value, stderr, unit, interval, caveat) of every parameter
        (:class:`pmdcid.model.tables.Row`)."""
        return [(n, p.value, p.stderr, p.unit, p.interval, p.caveat)
                for n, p in self.parameters.items()]

    def __str__(self) -> str:
        from pmdcid.model.tables import text_table

        head = [f"effects: {', '.join(self.effects)}"] if self.effects else []
        if self.extra.get("lumped"):
            head.append("lumped model: per-volt parameters")
        return "\n".join([text_table(self.rows()), *head])

    def _repr_html_(self) -> str:
        from pmdcid.model.tables import html_table

        cap = "model" + (f" (effects: {', '.join(self.effects)})" if self.effects else "")
        return html_table(self.rows(), cap)

    def to_pandas(self):
        """A DataFrame of parameter, value, stderr, unit."""
        from pmdcid.model.tables import rows_frame

        return rows_frame(self.rows())

    def to_json(self) -> dict[str, Any]:
        params = {k: v.to_json() for k, v in self.parameters.items()}
        if self.extra.get("lumped") is True:  # the units a lumped model's values are in
            for k, d in params.items():
                if param_spec(k) is not None:
                    d["unit"] = _canonical_unit(k, True)
        out: dict[str, Any] = {"parameters": params, "effects": list(self.effects)}
        out.update(self.extra)
        out.setdefault("format", FORMAT_VERSION)
        return out


def kept_within(par: Parameter | None, low: float, high: float) -> bool:
    """Whether ``par``, a value other data determined, lies in [``low``, ``high``]: logs that
    only bound the parameter there leave it as it is."""
    return par is not None and par.determined and low <= par.value <= high


def copy_model_into(src: Model, dst: Model) -> None:
    """Replace ``dst``'s parameters, effects and extra keys by copies of ``src``'s (in place;
    ``dst.path`` is kept)."""
    new = src.copy()
    dst.parameters, dst.effects, dst.extra = new.parameters, new.effects, new.extra


def check_bounds(name: str, v: float, path) -> float:
    """``v`` if it lies in the parameter's bounds, else the loader's one-line error."""
    spec = param_spec(name)
    if not math.isfinite(v):
        raise ModelError(f"parameter '{name}' is not finite ({v!r}): give a finite number or "
                         "remove it and rerun its stage", path)
    if spec is not None and not (spec.lower <= v <= spec.upper):
        raise ModelError(
            f"parameter '{name}' = {v:g} {spec.unit} is impossible "
            f"(must lie in [{spec.lower:g}, {spec.upper:g}])",
            path,
        )
    return v


def _check_value(name: str, value: Any, path: str, unit: Any = "", lumped: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ModelError(f"parameter '{name}' has non-numeric value {repr(value)[:30]}: "
                         "give a plain number in SI units", path)
    try:
        v = float(value)
    except OverflowError:  # an integer too large for a float
        v = math.inf
    if not math.isfinite(v):
        raise ModelError(f"parameter '{name}' is not finite ({repr(value)[:30]}): give a finite "
                         "number or remove it and rerun its stage", path)
    spec = param_spec(name)
    if spec is not None and unit not in (None, ""):
        from pmdcid.model.units import to_canonical

        if not isinstance(unit, str):
            raise ModelError(f"parameter '{name}' has unit {unit!r}: a unit is a text like "
                             f"{spec.unit!r}", path)
        v = to_canonical(name, v, unit, _canonical_unit(name, lumped), path)
    return check_bounds(name, v, path)


def _canonical_unit(name: str, lumped: bool) -> str:
    """The unit a parameter is held in: SI, or per volt in a lumped model (``"lumped": true``,
    :mod:`pmdcid.model.lumped`)."""
    unit = unit_of(name)
    if lumped:
        from pmdcid.model.lumped import ELECTRICAL, lumped_unit

        return unit if name in ELECTRICAL else lumped_unit(unit)
    return unit


def model_from_json(obj: Any, path: str = "<model>") -> Model:
    """Validate a parsed model file and build a :class:`Model`."""
    if not isinstance(obj, dict):
        raise ModelError("model file must hold a JSON object {\"parameters\": ..., "
                         "\"effects\": [...]}", path)
    params = obj.get("parameters", {})
    if not isinstance(params, dict):
        raise ModelError("'parameters' must be an object of name -> {value, stderr, unit}", path)
    model = Model(path=path)
    lumped = obj.get("lumped", False)
    if not isinstance(lumped, bool):
        raise ModelError(f"'lumped' is {repr(lumped)[:30]}: give true (per-volt parameters) or "
                         "false (SI)", path)
    for name, entry in params.items():
        if isinstance(entry, (int, float)) and not isinstance(entry, bool):
            entry = {"value": entry}
        if not isinstance(entry, dict) or "value" not in entry:
            raise ModelError(f"parameter '{name}' must be an object with a 'value'", path)
        unit = _unit_of_entry(name, entry, path)
        v = _check_value(name, entry["value"], path, unit, lumped)
        se = _stderr_of(name, entry, path)
        if math.isfinite(se) and entry["value"] and v != float(entry["value"]):
            se *= v / float(entry["value"])  # the same prefix scaling as the value
        interval = _interval_of(name, entry, v, path, unit, lumped)
        unit = _canonical_unit(name, lumped) if param_spec(name) is not None else str(unit or "")
        model.parameters[name] = Parameter(v, se, unit, _text_of(name, entry, "stage", path),
                                           interval, _caveat_of(name, entry, path))
    effects = obj.get("effects", [])
    if not isinstance(effects, list) or not all(isinstance(e, str) for e in effects):
        raise ModelError("'effects' must be a list of effect names", path)
    unknown = [e for e in effects if e not in EFFECTS]
    if unknown:
        raise ModelError(
            f"unknown effect(s) {', '.join(unknown)} (known: {', '.join(EFFECTS)})", path
        )
    model.effects = list(effects)
    for e in effects:
        lacking = [n for n in EFFECTS[e].param_names if n not in model.parameters]
        if lacking:
            from pmdcid.errors import warn

            warn(f"model lists effect '{e}' but lacks its parameter(s) {', '.join(lacking)}: "
                 "they are taken as neutral (effect off); run diagnose to identify them", path)
    model.extra = {k: v for k, v in obj.items() if k not in ("parameters", "effects")}
    from pmdcid.model.effects.torque_limit import check_plausible

    check_plausible({k: p.value for k, p in model.parameters.items()}, path, lumped)
    return model


def _interval_of(name: str, entry: dict, v: float, path, unit, lumped: bool):
    """A parameter's ``interval`` [low, high] (in its entry's unit, like the value), checked:
    two finite numbers, low <= value <= high, within the parameter's bounds (a positive one may
    reach down to 0), and no standard error beside it; None when the entry has none."""
    got = entry.get("interval")
    if got is None:
        return None
    if not (isinstance(got, list) and len(got) == 2 and all(
            isinstance(x, (int, float)) and not isinstance(x, bool) for x in got)):
        raise ModelError(f"parameter '{name}' has interval {repr(got)[:40]}: give two numbers "
                         "[low, high] in the value's unit", path)
    if entry.get("stderr") is not None:
        raise ModelError(f"parameter '{name}' gives both a stderr and an interval: a parameter "
                         "the logs only bound has no standard error; keep one", path)
    spec = param_spec(name)
    if spec is not None and unit not in (None, ""):
        from pmdcid.model.units import to_canonical

        got = [to_canonical(name, float(x), unit, _canonical_unit(name, lumped), path)
               for x in got]
    low, high = (float(x) for x in got)
    check_interval(name, low, high, v, path)
    return (low, high)


def check_interval(name: str, low: float, high: float, v: float, path) -> None:
    """The loader's (and the writer's) one-line error for an impossible interval."""
    spec = param_spec(name)
    floor = min(spec.lower, 0.0) if spec is not None else -math.inf
    ceiling = spec.upper if spec is not None else math.inf
    tol = 1e-9 * max(abs(low), abs(high))
    if not (math.isfinite(low) and math.isfinite(high) and floor <= low <= high <= ceiling):
        raise ModelError(f"parameter '{name}' has interval [{low:g}, {high:g}]: give finite "
                         f"[low, high] with low <= high within [{floor:g}, {ceiling:g}]", path)
    if not low - tol <= v <= high + tol:
        raise ModelError(f"parameter '{name}' = {v:g} lies outside its interval [{low:g}, "
                         f"{high:g}]: the value must be a point inside it", path)


def _caveat_of(name: str, entry: dict, path) -> str:
    return _text_of(name, entry, "caveat", path)


def _text_of(name: str, entry: dict, key: str, path) -> str:
    """A parameter's text field ``key`` (``stage``, ``caveat``): a text, or absent/null ("")."""
    got = entry.get(key, "")
    if got is None:
        return ""
    if not isinstance(got, str):
        raise ModelError(f"parameter '{name}' has {key} {repr(got)[:30]}: a {key} is a text",
                         path)
    return got


def _stderr_of(name: str, entry: dict, path) -> float:
    """A parameter's ``stderr`` in its entry's unit: a number >= 0, or absent/null (NaN: not
    known); anything else (a text, a negative number) is refused naming the parameter."""
    se = entry.get("stderr")
    if se is None:
        return math.nan
    if isinstance(se, bool) or not isinstance(se, (int, float)) or not se >= 0:
        raise ModelError(f"parameter '{name}' has stderr {repr(se)[:30]}: a standard error is a "
                         "number >= 0 in the value's unit (or null: not known)", path)
    try:
        return float(se)
    except OverflowError:  # an integer too large for a float
        return math.inf


def _unit_of_entry(name: str, entry: dict, path):
    """A parameter's unit: ``unit`` (or ``units``, ``Unit``: a unit is never ignored because
    of its key's spelling); two different ones are refused."""
    given = {k: entry[k] for k in entry if str(k).strip().lower() in ("unit", "units")}
    units = {str(u) for u in given.values() if u not in (None, "")}
    if len(units) > 1:
        raise ModelError(f"parameter '{name}' gives two units ({', '.join(sorted(units))}): "
                         "keep one", path)
    return next(iter(given.values()), None) if len(given) <= 1 else next(iter(units), None)


class _Duplicate(ValueError):
    pass


def _pairs(pairs):
    """JSON object from its key/value pairs: a key given twice is refused, never the last taken."""
    out = {}
    for k, v in pairs:
        if k in out:
            raise _Duplicate(f"key {k[:40]!r} is given twice in one object")
        out[k] = v
    return out


#: an integer literal longer than this is read as +-inf (refused as a value, naming its key)
#: rather than failing the whole file on Python's int-conversion limit (4300 digits)
MAX_INT_DIGITS = 400


def _json_int(text: str):
    if len(text) > MAX_INT_DIGITS:
        return -math.inf if text.startswith("-") else math.inf
    return int(text)


def _key_path(text: str, pos: int) -> list[str]:
    """The object keys enclosing ``text[pos]`` (outermost first): a scan of the strings and
    brackets before it."""
    stack: list = []
    k, last = 0, None
    while k < pos:
        c = text[k]
        if c == '"':
            end = k + 1
            while end < len(text) and text[end] != '"':
                end += 2 if text[end] == "\\" else 1
            last, k = text[k + 1:end], end + 1
            continue
        if c in "{[":
            stack.append(None)
        elif c in "}]" and stack:
            stack.pop()
        elif c == ":" and stack and last is not None:
            stack[-1] = last
        elif c == ",":
            last = None
        k += 1
    return [x for x in stack if x is not None]


def json_error_place(text: str, exc: json.JSONDecodeError) -> str:
    """Where a JSON syntax error is, in words: ``line L column C``, and the keys it lies under
    (``near parameters > L > value``) when there are any."""
    where = f"line {exc.lineno} column {exc.colno}"
    keys = _key_path(text, min(exc.pos, len(text)))
    return where + (f", near {' > '.join(x[:30] for x in keys[-4:])}" if keys else "")


def parse_model_json(text: str, path):
    """The model file's JSON, strictly: a key given twice (``R`` twice) refused with one line
    naming the file; ``NaN``/``Infinity`` (not JSON) are refused as a parameter's value, and
    elsewhere (an extra key) written back as ``null``, never as an invalid token."""
    try:
        return json.loads(text, object_pairs_hook=_pairs, parse_int=_json_int)
    except _Duplicate as exc:
        raise ModelError(f"model file is ambiguous: {exc}; repair it", path) from None


def load_model(path: str | os.PathLike, must_exist: bool = True) -> Model:
    """Read a model file. A missing file gives an empty model when ``must_exist`` is false."""
    from pmdcid.io.args import path_arg

    p = path_arg(path, "path")
    if os.path.islink(p) and not os.path.exists(p):
        from pmdcid.runtime.outputs import check_target

        check_target(p, option="-m")  # a symlink loop: one line (a dangling link: created)
    if not os.path.exists(p):
        if must_exist:
            raise ModelError("no such model file (run a fit stage first to create it)", p)
        return Model(path=p, digest=(p, ABSENT))
    if os.path.isdir(p):
        raise ModelError("is a folder, not a model file", p)
    from pmdcid.io.text import decode

    try:
        with open(p, "rb") as fh:
            data = fh.read()
        text = decode(data)
    except (OSError, UnicodeDecodeError) as exc:
        raise ModelError(f"cannot read model file ({getattr(exc, 'strerror', exc)})", p) from None
    if not text.strip():
        raise ModelError("model file is empty (delete it to start afresh)", p)
    try:
        obj = parse_model_json(text, p)
    except json.JSONDecodeError as exc:
        raise ModelError(f"model file is not valid JSON ({json_error_place(text, exc)}: "
                         f"{exc.msg}): repair it, or delete it to start afresh", p) from None
    except (ValueError, RecursionError) as exc:  # e.g. an integer of more than 4300 digits
        raise ModelError(f"model file is not usable JSON ({str(exc)[:60]}): repair it, or "
                         "delete it to start afresh", p) from None
    model = model_from_json(obj, p)
    model.digest = (p, hashlib.sha256(data).hexdigest())
    return model


#: the digest of a model file that did not exist when it was read
ABSENT = "absent"


def file_digest(path) -> str:
    """sha256 of the file's bytes (:data:`ABSENT` when there is none, or it cannot be read: the
    write that follows says why)."""
    try:
        with open(path, "rb") as fh:
            return hashlib.sha256(fh.read()).hexdigest()
    except OSError:
        return ABSENT


def check_unchanged(model: Model, path) -> None:
    """Optimistic locking: a model read from ``path`` is written back only if ``path`` still
    holds what was read (another command, e.g. a stage run meanwhile, would lose its results)."""
    from pmdcid.runtime.outputs import same_file

    if model.digest is None or not same_file(model.digest[0], path, planned=True):
        return
    if file_digest(path) != model.digest[1]:
        raise ModelError("the model file changed since this command read it (another pmdcid "
                         "command or an editor wrote it): nothing was written; rerun the command "
                         "to build on the new file", str(path))


def finite_json(x):
    """A copy of ``x`` with every non-finite float as None: what JSON can hold."""
    if isinstance(x, dict):
        return {k: finite_json(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [finite_json(v) for v in x]
    if isinstance(x, float) and not math.isfinite(x):
        return None
    return x


def save_model(model: Model, path: str | os.PathLike) -> None:
    """Write the model file atomically (temporary file in the same folder, then rename).

    Every value is checked against the bounds (and the plausibility rule) the loader applies
    first: the tool never writes a model it would then refuse to read. A model read from
    ``path`` is written back only if the file still holds what was read (:func:`check_unchanged`,
    optimistic locking; the stage runners call this under :func:`pmdcid.runtime.outputs.locked`).
    """
    from pmdcid.io.args import path_arg
    from pmdcid.runtime.outputs import atomic_write_text

    path_arg(path, "path")
    if not isinstance(model, Model):
        raise TypeError(f"model must be a Model, not {type(model).__name__}")
    for name, par in model.parameters.items():
        check_bounds(name, par.value, str(path))
        if par.interval is not None:
            check_interval(name, *par.interval, par.value, str(path))
    from pmdcid.model.effects.torque_limit import check_plausible

    check_plausible({k: p.value for k, p in model.parameters.items()}, str(path),
                    model.extra.get("lumped") is True)

    text = json.dumps(finite_json(model.to_json()), indent=2, allow_nan=False) + "\n"
    check_unchanged(model, path)  # under the caller's lock, just before the atomic replace
    try:
        atomic_write_text(path, text)
    except Exception as exc:
        from pmdcid.errors import PmdcidError

        if isinstance(exc, PmdcidError):
            raise ModelError(str(exc)) from None
        raise
    model.digest = (str(path), file_digest(path))
