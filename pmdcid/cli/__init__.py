"""Command-line edge: parse, call one library function, write. Errors -> one line, exit 1.

Each command lives in its own module of this package and registers itself on :data:`main`.
"""

from __future__ import annotations

import os
import sys
import warnings

import click

from pmdcid import __version__


class _Group(click.Group):
    """Turns the library's exception family into one line on stderr and exit status 1."""

    def invoke(self, ctx):
        from pmdcid.errors import PmdcidError, PmdcidWarning, one_line

        def _show(message, category, filename, lineno, file=None, line=None):
            if issubclass(category, PmdcidWarning):
                click.echo(f"warning: {one_line(message)}", err=True)
            elif os.environ.get("PMDCID_DEBUG"):
                click.echo(f"warning: {category.__name__}: {message}", err=True)

        from pmdcid.io.outputs import Terminated, install_sigterm, transaction

        warnings.showwarning = _show
        warnings.simplefilter("always", PmdcidWarning)
        install_sigterm()
        try:
            with transaction():  # a failing command leaves nothing new behind
                return super().invoke(ctx)
        except Terminated:
            click.echo("error: terminated (SIGTERM): nothing was written", err=True)
            sys.exit(143)
        except PmdcidError as exc:
            click.echo("error: " + one_line(str(exc)), err=True)  # always one short line
            sys.exit(1)
        except (click.exceptions.Exit, click.exceptions.Abort, click.ClickException):
            raise
        except KeyboardInterrupt:
            click.echo("error: interrupted", err=True)
            sys.exit(130)
        except OSError as exc:  # a file operation the library did not wrap: name the file
            if os.environ.get("PMDCID_DEBUG"):
                raise
            where = f"{exc.filename}: " if exc.filename else ""
            click.echo(one_line(f"error: {where}{exc.strerror or exc} (check the path and its "
                                "permissions)"), err=True)
            sys.exit(1)
        except MemoryError:
            click.echo("error: out of memory: the log is too large for this machine", err=True)
            sys.exit(1)
        except Exception as exc:  # never a traceback at the edge; PMDCID_DEBUG=1 shows it
            if os.environ.get("PMDCID_DEBUG"):
                raise
            msg = str(exc).strip().splitlines()[0] if str(exc).strip() else ""
            click.echo(one_line(f"error: internal error {type(exc).__name__}: {msg[:120]} "
                                "(please report it; PMDCID_DEBUG=1 shows the traceback)"),
                       err=True)
            sys.exit(1)


@click.group(cls=_Group, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(__version__, prog_name="pmdcid")
def main():
    """Identify a non-linear PMDC motor model (dead zone, stick-slip friction) from logs."""


def _register() -> None:
    import importlib

    for mod in COMMAND_MODULES:
        importlib.import_module(f"pmdcid.cli.{mod}")


#: command modules, each registering its command(s) on ``main`` at import
COMMAND_MODULES = ["cmd_simulate", "cmd_fit", "cmd_report", "cmd_demo", "cmd_diagnose"]
_register()
