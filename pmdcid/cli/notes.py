"""The stages' warnings and notes (:class:`~pmdcid.notes.Note`) on the terminal."""

from __future__ import annotations

from pmdcid.cli import echo
from pmdcid.errors import one_line


def echo_notes(notes, in_table=()) -> None:
    """Each warning as one ``warning: ...`` line on stderr, each note as ``note: ...`` on
    stdout (a note says how a number was obtained: part of the result, not a problem), but
    the notes of the stages ``in_table`` (the command's table printed them already)."""
    for n in notes:
        if getattr(n, "severity", "warning") == "warning":
            echo(f"warning: {one_line(n)}", err=True)
        elif getattr(n, "stage", "") not in in_table:
            echo(f"note: {one_line(n)}")
