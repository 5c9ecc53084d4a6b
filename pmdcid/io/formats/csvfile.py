"""CSV logs as ``pmdcid channels`` lists them (reading them is :func:`pmdcid.io.logs.read_log`)."""

from __future__ import annotations

import re

from pmdcid.io.formats import Channel, rate_of

_UNIT_RE = re.compile(r"[\[(]\s*([^\[\]()]+?)\s*[\])]\s*$")


def csv_channels(p: str) -> list[Channel]:
    """A CSV log's columns: name, rows, the rate of its ``t`` column (when it has a numeric one),
    the unit a header such as ``speed [rpm]`` names (None otherwise)."""
    from pmdcid.errors import LogError
    from pmdcid.io.csvsource import numeric_column
    from pmdcid.io.logs import read_table

    df, _ = read_table(p)
    rate = None
    if "t" in df.columns:
        try:
            rate = rate_of(numeric_column(df, "t", p))
        except LogError:
            rate = None
    out = []
    for c in df.columns:
        m = _UNIT_RE.search(c)
        out.append(Channel(c, len(df), rate, m.group(1) if m else None))
    return out
