"""Options shared by the commands: column mapping, model file."""

from __future__ import annotations

import functools

import click


def log_options(f):
    """``-c/--column CANON=SOURCE*SCALE+OFFSET`` (repeatable), ``--map FILE``, ``--cutoff HZ``."""

    @click.option("-c", "--column", "columns", multiple=True, metavar="CANON=SRC[*K][+OFF]",
                  help="Map a log column to a canonical one, e.g. -c omega=speed_rpm*rpm "
                       "(repeatable; see docs/cli.md).")
    @click.option("--map", "map_file", type=click.Path(dir_okay=False), default=None,
                  help="File of column mappings, one CANON=SRC*K+OFF per line (or JSON).")
    @click.option("--cutoff", "cutoff_hz", type=click.FloatRange(min=0.0, min_open=True),
                  default=None, metavar="HZ",
                  help="Cut-off of the zero-phase low-pass used to derive speed from angle "
                       "(and acceleration) [Hz]; default min(rate/10, 100 Hz).")
    @functools.wraps(f)
    def wrapper(*args, columns=(), map_file=None, cutoff_hz=None, **kwargs):
        from pmdcid.errors import LogError
        from pmdcid.io import parse_mapping

        try:
            mapping = parse_mapping(columns, map_file)
        except LogError as exc:
            if exc.path is not None:  # a problem in the --map file: exit 1, names the file
                raise
            raise click.BadParameter(str(exc), param_hint="'-c' / '--column'") from None
        mapping.cutoff_hz = cutoff_hz
        kwargs["mapping"] = mapping
        return f(*args, **kwargs)

    return wrapper


def model_option(required: bool = True):
    return click.option("-m", "--model", "model_path", required=required,
                        type=click.Path(dir_okay=False), metavar="MODEL",
                        help="Model file (JSON), read and updated.")
