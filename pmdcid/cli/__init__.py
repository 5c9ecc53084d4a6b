"""Command-line edge: parse, call one library function, write. Errors -> one line, exit 1.

Commands load lazily: ``pmdcid --help`` lists every command from :data:`COMMANDS` without
importing any command module (so no numpy, scipy or numba), and ``pmdcid simulate ...`` imports
only ``cmd_simulate`` and what that command needs.

Adding a command is one line in :data:`COMMANDS`: its name -> (the module of this package that
defines it with ``@main.command("name")``, the one-line help ``pmdcid --help`` shows), e.g.::

    "export": ("cmd_export", "Write MODEL as a python-control, C or MATLAB simulation."),

One module may define several commands (``cmd_fit`` defines the four ``fit-*`` stages).
``main.commands`` still answers ``name in main.commands`` for every listed command; reading a
command from it imports its module.
"""

from __future__ import annotations

import os
import sys
import warnings

import click

from pmdcid import __version__


class _Warnings:
    """A command's warnings (:class:`~pmdcid.errors.PmdcidWarning`), each once, printed when it
    succeeds and dropped when it fails: its one ``error:`` line says what to fix, and a warning
    on the way (a NaN filled, a resampled clock) would stand before it as a second, unrelated
    line. ``PMDCID_DEBUG=1`` prints every warning at once, other categories too."""

    def __init__(self, one_line):
        self.one_line = one_line
        self.debug = bool(os.environ.get("PMDCID_DEBUG"))
        self.pending: list[str] = []

    def show(self, message, category, filename, lineno, file=None, line=None) -> None:
        from pmdcid.errors import PmdcidWarning

        if issubclass(category, PmdcidWarning):
            text = f"warning: {self.one_line(message)}"
            if self.debug:
                echo(text, err=True)
            elif text not in self.pending:
                self.pending.append(text)
        elif self.debug:
            echo(f"warning: {category.__name__}: {message}", err=True)

    def flush(self, show: bool = True) -> None:
        for text in self.pending if show else ():
            echo(text, err=True)
        self.pending.clear()


class _Group(click.Group):
    """Turns the library's exception family into one line on stderr and exit status 1 (the
    command's warnings printed only when it succeeds: :class:`_Warnings`)."""

    def invoke(self, ctx):
        from pmdcid.runtime.blas import pin_blas_kernels

        pin_blas_kernels()  # before anything loads numpy
        from pmdcid.errors import MAX_MESSAGE, PmdcidError, PmdcidWarning
        from pmdcid.errors import one_line as _one_line
        from pmdcid.io.escape import terminal

        def one_line(text, limit=MAX_MESSAGE) -> str:  # shown safely, then at most limit chars
            return _one_line(terminal(str(text)), limit)

        from pmdcid.runtime.malloc import tune_malloc
        from pmdcid.runtime.outputs import transaction
        from pmdcid.runtime.signals import Terminated, install_sigterm

        with warnings.catch_warnings():  # click 8.2 deprecates protected_args (9: in args)
            warnings.simplefilter("ignore", DeprecationWarning)
            raw = [*getattr(ctx, "protected_args", []), *ctx.args]  # the command's own words
        shown = _Warnings(one_line)
        warnings.showwarning = shown.show
        warnings.simplefilter("always", PmdcidWarning)
        install_sigterm()
        tune_malloc()
        try:
            with transaction():  # a failing command leaves nothing new behind
                out = super().invoke(ctx)
            shown.flush()
            return out
        except click.exceptions.Exit as exc:
            shown.flush(exc.exit_code == 0)
            raise
        except Terminated as exc:
            click.echo(f"error: terminated ({exc.name}): nothing was written", err=True)
            sys.exit(128 + exc.signum)
        except PmdcidError as exc:
            echo("error: " + one_line(str(exc), exc.limit), err=True)  # always one line
            sys.exit(1)
        except (click.exceptions.Abort, click.ClickException):
            raise
        except KeyboardInterrupt:
            click.echo("error: interrupted", err=True)
            sys.exit(130)
        except OSError as exc:  # a file operation the library did not wrap: name the file
            if os.environ.get("PMDCID_DEBUG"):
                raise
            where = f"{exc.filename}: " if exc.filename else ""
            echo(one_line(f"error: {where}{exc.strerror or exc} (check the path and its "
                          "permissions)"), err=True)
            sys.exit(1)
        except MemoryError:
            big = largest_file(raw)
            echo(one_line(f"error: {big + ': ' if big else ''}out of memory: the log is too large "
                          "for this machine (keep one row in k, or a part of it)"), err=True)
            sys.exit(1)
        except Exception as exc:  # never a traceback at the edge; PMDCID_DEBUG=1 shows it
            if os.environ.get("PMDCID_DEBUG"):
                raise
            msg = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
            echo(one_line(f"error: internal error {type(exc).__name__}: {msg[:120]} "
                          "(please report it; PMDCID_DEBUG=1 shows the traceback)"), err=True)
            sys.exit(1)


def largest_file(raw) -> str | None:
    """The largest existing file among the command line's words (what an out-of-memory is
    about)."""
    files = [a for a in raw if isinstance(a, str) and os.path.isfile(a)]
    return max(files, key=os.path.getsize) if files else None


def echo(text="", err: bool = False) -> None:
    """Print a line (or a table) the way every command prints: user text in it (file, column,
    effect names) can not reach the terminal as a control sequence
    (:func:`pmdcid.io.escape.terminal`; newlines and tabs kept)."""
    from pmdcid.io.escape import terminal

    click.echo(terminal(text, keep_newlines=True), err=err)


def progress_lines():
    """The commands' progress callback: :func:`pmdcid.runtime.progress.stage_lines`, its messages
    passed through :func:`pmdcid.io.escape.terminal`."""
    from pmdcid.io.escape import terminal
    from pmdcid.runtime.progress import stage_lines

    lines = stage_lines()
    return lambda msg: lines(terminal(msg))


#: every command: name -> (module of pmdcid.cli defining it, one-line help for ``pmdcid --help``).
#: Adding a command is one line here (see the module docstring).
COMMANDS: dict[str, tuple[str, str]] = {
    "fit-electrical": ("cmd_fit", "Blocked-rotor current steps -> R, L (the model file is "
                                  "created if missing)."),
    "fit-mechanical": ("cmd_fit", "Free-speed speed steps -> Kmot, tau_mot -> b, J (paper) and "
                                  "bv, bc (steady-speed line)."),
    "fit-nonlinear": ("cmd_fit", "Triangular-input (or any rich) logs -> bc, bv, dz, J refined, "
                                 "by simulation error."),
    "fit-inverse-dynamics": ("cmd_fit", "Any logs with torque (or current) and angle or speed "
                                        "-> J, bv, bc, tau0 by inverse dynamics."),
    "report": ("cmd_report", "Compare MODEL with measured LOGs: DIR/report.html, "
                             "DIR/metrics.json, DIR/*.png."),
    "simulate": ("cmd_simulate", "Predict what the sensors read for INPUT's t and v (or tau), "
                                 "from rest unless --x0."),
    "diagnose": ("cmd_diagnose", "Find the catalogue effects MODEL lacks on LOGs, add them, "
                                 "refit, report before/after."),
    "demo": ("cmd_demo", "Run the whole pipeline on the bundled example logs and write a "
                         "report."),
    "identify": ("cmd_identify", "A whole rig: sort the logs, run every stage that applies, a "
                                 "joint fit, diagnose, and the report into DIR."),
    "export": ("cmd_export", "Write code that steps MODEL exactly as `pmdcid simulate` does "
                             "(python-control, C, MATLAB)."),
    "plan": ("cmd_plan", "Input profiles to record, and the standard error each parameter will "
                         "have."),
    "channels": ("cmd_channels", "List the signals FILE holds (any format pmdcid reads): name, "
                                 "samples, rate, unit."),
    "fleet": ("cmd_fleet", "Identify every unit of a fleet on a Dask cluster: units.parquet, "
                           "outliers, drift, fleet.html."),
}


def short_help(text: str, limit: int = 45) -> str:
    """``text`` shortened as click shortens a command's help for the command list."""
    return click.Command(None, help=text).get_short_help_str(limit)


class _LazyCommands(dict):
    """``Group.commands`` that knows every name of :data:`COMMANDS` and imports a command's
    module the first time the command itself is read (the module registers it here)."""

    def _load(self, name) -> None:
        if not dict.__contains__(self, name) and name in COMMANDS:
            import importlib

            importlib.import_module(f"pmdcid.cli.{COMMANDS[name][0]}")

    def __contains__(self, name) -> bool:
        return dict.__contains__(self, name) or name in COMMANDS

    def __getitem__(self, name):
        self._load(name)
        return dict.__getitem__(self, name)

    def get(self, name, default=None):
        self._load(name)
        return dict.get(self, name, default)

    def keys(self):
        return list(dict.fromkeys([*COMMANDS, *dict.keys(self)]))

    def __iter__(self):
        return iter(self.keys())

    def __len__(self) -> int:
        return len(self.keys())

    def values(self):
        return [self[k] for k in self.keys()]

    def items(self):
        return [(k, self[k]) for k in self.keys()]


class _LazyGroup(_Group):
    """A group listing :data:`COMMANDS` without importing them."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.commands = _LazyCommands(self.commands)

    def format_commands(self, ctx, formatter):
        """The ``Commands:`` section from the one-line helps of :data:`COMMANDS` (a command
        already loaded, or not in the table, shows its own short help)."""
        names = self.list_commands(ctx)
        if not names:
            return
        limit = formatter.width - 6 - max(len(n) for n in names)
        rows = []
        for name in names:
            if name in COMMANDS and not dict.__contains__(self.commands, name):
                rows.append((name, short_help(COMMANDS[name][1], limit)))
                continue
            cmd = self.get_command(ctx, name)
            if cmd is not None and not cmd.hidden:
                rows.append((name, cmd.get_short_help_str(limit)))
        with formatter.section("Commands"):
            formatter.write_dl(rows)


@click.group(cls=_LazyGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="pmdcid")
def main():
    """Identify a non-linear PMDC motor model (dead zone, stick-slip friction) from logs."""


def _register() -> None:
    """Import, now, the command modules of :data:`COMMAND_MODULES` that :data:`COMMANDS` does not
    name (a command registered the old way still works, at the cost of a slower start-up)."""
    import importlib

    listed = {mod for mod, _ in COMMANDS.values()}
    for mod in COMMAND_MODULES:
        if mod not in listed:
            importlib.import_module(f"pmdcid.cli.{mod}")


#: command modules, each registering its command(s) on ``main`` at import
COMMAND_MODULES = ["cmd_simulate", "cmd_fit", "cmd_report", "cmd_demo", "cmd_diagnose",
                   "cmd_identify", "cmd_export", "cmd_plan", "cmd_channels", "cmd_fleet"]
_register()
