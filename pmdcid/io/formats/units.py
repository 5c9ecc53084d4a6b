"""Units a log file stores beside its signals (MDF channel units, TDMS ``unit_string``, Parquet
field metadata ``unit``, wpilog metadata ``{"unit": ...}``), applied where the mapping leaves a
signal's unit to the file.

A canonical column read from a signal as it stands (``-c omega=speed``, or a signal named
``omega``) whose stored unit is one of :data:`pmdcid.io.headers.UNIT_TABLE` (or a spelling
of one: :func:`pmdcid.io.headers.unit_of`) is converted to SI, with one warning naming the
conversion: an MDF speed channel in ``rpm`` was read as rad/s, a J 9.5 times too small with no
word. A stored unit of another quantity (a tachometer's ``V`` mapped to omega) is refused: the
mapping must give its scale. A stored unit the tool does not know is read as it stands, and a
warning says so. A mapping with a scale, an offset or an expression (``-c omega=speed*rpm``)
is the whole conversion: the stored unit is not applied on top of it.
"""

from __future__ import annotations

from dataclasses import replace

from pmdcid.errors import LogError, warn
from pmdcid.io.headers import DIMENSION, unit_of

#: stored units that say "no unit"
NO_UNIT = {"", "-", "1", "none", "n/a", "na"}
#: canonical column -> its SI unit and what it is, for messages
SI = {"t": ("s", "time"), "v": ("V", "voltage"), "tau": ("N m", "torque"),
      "i": ("A", "current"), "omega": ("rad/s", "speed"), "theta": ("rad", "angle")}


def _bare(spec) -> bool:
    """The mapping reads its signal as it stands (a rename, perhaps negated)."""
    if spec.expr is not None or spec.offset != 0.0 or abs(spec.scale) != 1.0:
        return False
    rhs = spec.text.split("=", 1)[1] if "=" in spec.text else spec.source
    return rhs.strip().lstrip("-").strip().strip('"') == spec.source


def apply_stored_units(specs: dict, units: dict, p: str) -> dict:
    """``specs`` (canonical column -> :class:`~pmdcid.io.mapping.ColumnSpec`) with the file's
    stored ``units`` (signal -> unit or None) applied where the mapping is bare (module doc)."""
    out, done, unknown = dict(specs), [], []
    for canon, spec in specs.items():
        base = canon.removesuffix("_ref")
        unit = units.get(spec.source)
        if base not in SI or unit is None or unit.strip().lower() in NO_UNIT or not _bare(spec):
            continue
        si, what = SI[base]
        hit = unit_of(unit)
        if hit is None:
            unknown.append(f"'{spec.source}' is stored in '{unit}'")
            continue
        factor, dim = hit
        if dim not in DIMENSION[base]:
            raise LogError(f"'{spec.source}' is stored in {unit} (the file says so), which is no "
                           f"{what}: give {canon} its scale to {si} (-c {canon}="
                           f"{spec.source}*SCALE)", p)
        if factor != 1.0:
            out[canon] = replace(spec, scale=spec.scale * factor)
            done.append(f"'{spec.source}' from {unit} to {si} (x {factor:.6g}) as {canon}")
    if done:
        warn(f"converted by the unit the file stores: {', '.join(done)} (a -c mapping with a "
             "scale replaces it)", p)
    if unknown:
        warn(f"{', '.join(unknown)}, a unit pmdcid does not convert: read as it stands (give "
             "its scale with -c CANON=SIGNAL*SCALE)", p)
    return out
