"""Options shared by the commands: column mapping, model file."""

from __future__ import annotations

import functools

import click


def log_options(f):
    """``-c/--column CANON=SOURCE*SCALE+OFFSET`` (repeatable) and ``--map FILE``."""

    @click.option("-c", "--column", "columns", multiple=True, metavar="CANON=SRC[*K][+OFF]",
                  help="Map a log column to a canonical one, e.g. -c omega=speed_rpm*rpm "
                       "(repeatable; see docs/cli.md).")
    @click.option("--map", "map_file", type=click.Path(dir_okay=False), default=None,
                  help="File of column mappings, one CANON=SRC*K+OFF per line (or JSON).")
    @functools.wraps(f)
    def wrapper(*args, columns=(), map_file=None, **kwargs):
        from pmdcid.io import parse_mapping

        kwargs["mapping"] = parse_mapping(columns, map_file)
        return f(*args, **kwargs)

    return wrapper


def model_option(required: bool = True):
    return click.option("-m", "--model", "model_path", required=required,
                        type=click.Path(dir_okay=False), metavar="MODEL",
                        help="Model file (JSON), read and updated.")
