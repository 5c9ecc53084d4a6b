"""The warnings and notes the report shows, and the rows they qualify.

They come from the model file (``"notes"``: what the stages said when they wrote it,
:mod:`pmdcid.notes`) and from the diagnose summary shown (its ``notes`` and ``warnings``).
Each is shown once in the page's "Warnings and notes" list and again beside what it qualifies:
the parameter rows it names (a note about an effect qualifies the effect's parameters: the
sensor-delay caveat sits on ``delay``), or the log it is about.
"""

from __future__ import annotations


def _params_of(names, effects: dict) -> list[str]:
    """The parameter rows ``names`` (parameters or effect names) qualify."""
    out: list[str] = []
    for n in names:
        for p in effects[n].param_names if n in effects else [n]:
            if p not in out:
                out.append(p)
    return out


def report_notes(model, summary: dict | None, logs, own=()) -> list[dict]:
    """Records (text, about, severity, stage, log, ``rows``: the parameter rows it qualifies,
    ``log_index``: the report's log it is about or None), warnings first, each text once.
    ``own``: the report's own warnings (what it found comparing the model with the logs)."""
    from pmdcid.fit.results import known_names
    from pmdcid.model import EFFECTS
    from pmdcid.notes import as_note

    names, paths = known_names(), [str(lg.path) for lg in logs]
    items = [as_note(r, names=names, logs=paths) for r in model.extra.get("notes", [])
             if isinstance(r, (dict, str))]
    items += [as_note(w, stage="report", names=names, logs=paths) for w in own]
    if summary:
        items += [as_note(w, stage="diagnose", names=names, logs=paths)
                  for w in summary.get("warnings", []) if isinstance(w, str)]
        items += [as_note(n, severity="note", stage="diagnose", names=names, logs=paths)
                  for n in summary.get("notes", []) if isinstance(n, str)]
    seen, out = set(), []
    for n in sorted(items, key=lambda n: n.severity != "warning"):
        if str(n) in seen:
            continue
        seen.add(str(n))
        rec = n.to_dict()
        rec["rows"] = [p for p in _params_of(n.about, EFFECTS) if p in model.parameters]
        rec["log_index"] = paths.index(n.log) if n.log in paths else None
        out.append(rec)
    return out


__all__ = ["report_notes"]
