"""``export --to c``: dependency-free C99 source and header stepping the kernel's exact model,
with a friction and dead-zone compensator (feed-forward, see docs/export.md).

The source is a line-by-line port of the kernel: the same 20-term scaling-and-squaring expm
(plain loops, so the discretisation agrees to rounding), the same substep rule, stick-slip
events and LuGre loop; a late input keeps its past inputs in a fixed line inside the model
struct (no allocation). The sensor delay is not applied (the state is the rotor's); omega0 is
added by ``pmdc_measured_omega``.
"""

from __future__ import annotations

import re
from pathlib import Path

from pmdcid.export import MARKER, ExportError, ExportSpec, fill, number, template
from pmdcid.io.escape import c_comment, c_include

_DRIVE_CHAR = {"v": "v", "tau": "t", "lumped": "l"}


def header_path(source: Path) -> Path:
    """The header beside ``source``: FILE.c -> FILE.h (FILE -> FILE.h)."""
    if source.suffix == ".h":
        raise ExportError("give the C source file to -o (e.g. motor.c); its header is written "
                          "beside it", str(source))
    return source.with_suffix(".h") if source.suffix else source.with_name(source.name + ".h")


def render(spec: ExportSpec, header_name: str) -> tuple[str, str]:
    """(source text, header text)."""
    values = dict(spec.values, omega0=spec.omega0, delay=spec.delay)
    params = "\n".join(f"    p->{n} = {number(v, 'INFINITY')};" for n, v in values.items())
    guard = "PMDC_" + re.sub(r"[^A-Za-z0-9]", "_", header_name).upper()
    common = {"MARKER": MARKER.capitalize(), "SOURCE": c_comment(spec.source)}
    header = fill(template("model.h.tmpl"), dict(
        common, GUARD=guard, DRIVE_CHAR=_DRIVE_CHAR[spec.drive],
        TORQUE_PATH="1" if spec.torque_path else "0"))
    source = fill(template("model.c.tmpl"), dict(
        common, HEADER=c_include(header_name), CNAME=c_comment(Path(header_name).stem + ".c"),
        PARAMS=params))
    return source, header
