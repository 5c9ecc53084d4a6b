"""Options shared by the commands: column mapping, model file."""

from __future__ import annotations

import functools

import click

from pmdcid.errors import LogError, MappingError

#: a file a command reads (a LOG, MODEL, a --map, --summary, --before or --limits file, a
#: MANIFEST): click checks nothing, the library opens it and says in one line what is wrong
#: (missing, a folder, not readable): a file problem is exit 1, never click's usage error (exit 2)
INPUT_FILE = click.Path(readable=False)


class FiniteFloat(click.ParamType):
    """A finite number (no nan/inf) not below ``min`` (or above it, when ``min_open``), nor
    below ``least`` or above ``max``, the smallest and largest values pmdcid accepts."""

    name = "number"

    def __init__(self, min: float = 0.0, min_open: bool = False,  # noqa: A002 - as click's
                 max: float = float("inf"), least: float = -float("inf")):  # noqa: A002
        self.min, self.min_open, self.max, self.least = min, min_open, max, least

    def convert(self, value, param, ctx):
        import math

        try:
            x = float(value)
        except (TypeError, ValueError):
            self.fail(f"{value!r} is not a number", param, ctx)
        if not math.isfinite(x) or x < self.min or (self.min_open and x == self.min):
            need = f"{'>' if self.min_open else '>='} {self.min:g}"
            self.fail(f"{value!r} is not a finite number {need}", param, ctx)
        if x < self.least:
            self.fail(f"{value!r} is below {self.least:g}, the smallest value pmdcid accepts "
                      "(check the unit: SI)", param, ctx)
        if x > self.max:
            self.fail(f"{value!r} is above {self.max:g}, the largest value pmdcid accepts "
                      "(check the unit: SI)", param, ctx)
        return x


def km_type() -> FiniteFloat:
    """``--km X``: a torque constant [N m/A] within the model's bounds for km (a value outside
    them is a usage error naming the bound, not a fit that fails on it)."""
    from pmdcid.model.spec import BASE_PARAMS

    km = BASE_PARAMS["km"]
    return FiniteFloat(min=0.0, min_open=True, least=km.lower, max=km.upper)


def log_options(f):
    """``-c/--column CANON=SOURCE*SCALE+OFFSET`` (repeatable), ``--map FILE``, ``--cutoff HZ``."""

    @click.option("-c", "--column", "columns", multiple=True, metavar="CANON=SRC[*K][+OFF]",
                  help="Map a log column to a canonical one, e.g. -c omega=speed_rpm*rpm "
                       "(repeatable; see docs/cli.md).")
    @click.option("--map", "map_file", type=INPUT_FILE, default=None,
                  help="File of column mappings, one CANON=SRC*K+OFF per line (or JSON).")
    @click.option("--cutoff", "cutoff_hz", type=FiniteFloat(min=0.0, min_open=True),
                  default=None, metavar="HZ",
                  help="Cut-off of the zero-phase low-pass used to derive speed from angle "
                       "(and acceleration) [Hz]; default min(rate/10, 100 Hz).")
    @functools.wraps(f)
    def wrapper(*args, columns=(), map_file=None, cutoff_hz=None, **kwargs):
        from pmdcid.io import parse_mapping

        try:
            mapping = parse_mapping(columns, map_file)
        except LogError as exc:
            if exc.path is not None:  # a problem in the --map file: exit 1, names the file
                raise
            raise _bad_column(exc) from None
        mapping.cutoff_hz = cutoff_hz
        kwargs["mapping"] = mapping
        guard_outputs()
        try:
            return f(*args, **kwargs)
        except MappingError as exc:  # a -c text that parses against no log's names: exit 2
            raise _bad_column(exc) from None

    return wrapper


def _bad_column(exc: LogError) -> click.BadParameter:
    """A malformed ``-c`` value as click's usage error (exit 2): the mapping's own words,
    without the log it was read against when it parsed only against a log's names."""
    from pmdcid.io.escape import terminal

    text = str(exc)
    if exc.path and text.startswith(f"{exc.path}: "):
        text = text[len(exc.path) + 2:]
    return click.BadParameter(terminal(text), param_hint="'-c' / '--column'")


#: options naming files or folders a command writes: every command's -o, and per command more
OUTPUT_OPTIONS = frozenset({"-o", "--output"})
OUTPUT_OPTIONS_OF = {"diagnose": frozenset({"--summary"})}
#: parameters (besides the arguments) naming files a command only reads
INPUT_PARAMS = frozenset({"map_file", "summary_path", "before_path"})
#: commands that write their -m MODEL (guarded like an output)
WRITES_MODEL = frozenset({"fit-electrical", "fit-mechanical", "fit-nonlinear",
                          "fit-inverse-dynamics", "identify"})


def guard_outputs(ctx: click.Context | None = None) -> None:
    """Refuse (exit 1) when an output option names an input: a LOG argument, the --map file,
    or another file the command only reads (report's ``--summary`` and ``--before``).

    Runs at the edge before the command does any work, so no command can overwrite a user's log;
    every output (and the model a stage writes) passes the one output guard first
    (:func:`pmdcid.runtime.outputs.check_target`: no FIFO, device or symlink loop).
    """
    from pmdcid.runtime.outputs import check_target, input_at, matched

    ctx = ctx or click.get_current_context(silent=True)
    if ctx is None:
        return
    inputs: list[str] = []
    outputs: list[tuple[str, str]] = []
    out_opts = OUTPUT_OPTIONS | OUTPUT_OPTIONS_OF.get(ctx.command.name, frozenset())
    for p in ctx.command.params:
        v = ctx.params.get(p.name)
        vals = [x for x in (v if isinstance(v, (tuple, list)) else [v]) if isinstance(x, str)]
        if out_opts & set(p.opts):
            outputs += [(x, p.opts[-1]) for x in vals]
        elif isinstance(p, click.Argument) or p.name in INPUT_PARAMS:
            inputs += vals
    if ctx.command.name in WRITES_MODEL and isinstance(ctx.params.get("model_path"), str):
        outputs.append((ctx.params["model_path"], "-m"))
    try:  # a LOG pattern the shell left as written: the files the command will read
        inputs = [str(x) for x in matched(inputs)]
    except LogError:
        pass  # nothing matches: the command says so, before any output is written
    for out, opt in outputs:
        check_target(out, option=opt)
        inp = input_at(out, inputs)
        if inp is not None:
            raise LogError(f"output would overwrite the input {inp}; choose another {opt}", out)


def model_option(required: bool = True, updated: bool = True):
    """``-m MODEL``; ``updated``: the command writes its results into MODEL (the fits,
    identify), else it only reads it (simulate, export, report, diagnose)."""
    return click.option("-m", "--model", "model_path", required=required,
                        type=INPUT_FILE, metavar="MODEL",
                        help="Model file (JSON), read and updated." if updated
                        else "Model file (JSON), read only (never written).")


def parse_x0(ctx, param, value):
    """``measured`` or ``name=VAL,...`` with names among i, omega, theta (finite numbers)."""
    import math

    if value is None or value.strip() == "measured":
        return None if value is None else "measured"
    out = {}
    for part in value.split(","):
        name, sep, num = part.partition("=")
        name = name.strip()
        if not sep or name not in ("i", "omega", "theta"):
            raise click.BadParameter(f"{part.strip()!r}: give 'measured' or name=VALUE with "
                                     "names among omega, i, theta")
        try:
            x = float(num)
        except ValueError:
            x = math.nan
        if not math.isfinite(x):
            raise click.BadParameter(f"{part.strip()!r}: the value must be a finite number")
        if name in out:
            raise click.BadParameter(f"{name} is given twice")
        out[name] = x
    return out


def controller_option(help_text: str):
    """``--controller SPEC``: a P/PI/PID spec, a JSON file or inline (``type=PI,kp=..``;
    :mod:`pmdcid.simulate.controller`). A bad file is exit 1 naming it; bad text exit 2."""

    def parse(ctx, param, value):
        if value is None:
            return None
        from pmdcid.simulate.controller import ControllerError, parse_controller

        try:
            return parse_controller(value)
        except ControllerError as exc:
            if exc.path is not None:
                raise
            raise click.BadParameter(str(exc)) from None

    return click.option("--controller", callback=parse, default=None, metavar="SPEC",
                        help=help_text)
