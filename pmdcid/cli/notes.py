"""The stages' warnings and notes (:class:`~pmdcid.notes.Note`) on the terminal."""

from __future__ import annotations

import click

from pmdcid.errors import one_line


def echo_notes(notes, warnings_only: bool = False) -> None:
    """Each warning as one ``warning: ...`` line on stderr, each note as ``note: ...`` on
    stdout (a note says how a number was obtained: part of the result, not a problem);
    ``warnings_only`` when the command's table printed the notes already."""
    for n in notes:
        if getattr(n, "severity", "warning") == "warning":
            click.echo(f"warning: {one_line(n)}", err=True)
        elif not warnings_only:
            click.echo(f"note: {one_line(n)}")
