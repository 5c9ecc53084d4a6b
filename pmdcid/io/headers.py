"""Headers that say what they hold: ``omega [rad/s]``, ``Speed (rpm)``, ``Time (ms)``.

Rigs and spreadsheets export a column's quantity and unit in its header. When a log lacks a
canonical column by name and no mapping names it, a header of the form ``QUANTITY [UNIT]`` or
``QUANTITY (UNIT)`` is taken as that canonical column, converted to SI, provided

- QUANTITY is the canonical name or a plain word for it (:data:`WORDS`, any case; English,
  and the words German, French and Spanish lab software writes: ``Drehzahl [U/min]``,
  ``Vitesse (tr/min)``), and
- UNIT is a unit of that quantity (:data:`UNIT_TABLE`: its SI factor and its dimension, or a
  spelling of one, :data:`ALIASES` and :data:`NAMES`: :func:`unit_of`).

Only one header may claim a column (two speed columns: neither is taken; the user maps one), and
the rule never overrides a column of the canonical name or a ``-c``/``--map`` mapping. A bare word
without a unit (``speed``) is not taken: its unit is unknown, and a wrong guess would be a silently
wrong number. Why not a guess from the values: a speed in rpm and one in rad/s differ by a factor
of 9.5, which a motor's data cannot tell.
"""

from __future__ import annotations

import math
import re

#: plain words for each canonical column (compared in lower case)
WORDS: dict[str, tuple[str, ...]] = {
    "t": ("t", "time", "zeit", "temps", "tiempo"),
    "v": ("v", "u", "voltage", "volt", "armature voltage", "supply voltage", "applied voltage",
          "spannung", "ankerspannung", "motorspannung", "tension", "voltaje", "tensión"),
    "tau": ("tau", "torque", "force", "drehmoment", "moment", "kraft", "couple", "par"),
    "i": ("i", "current", "armature current", "strom", "ankerstrom", "motorstrom", "courant",
          "corriente"),
    "omega": ("omega", "w", "speed", "velocity", "angular speed", "angular velocity",
              "rotor speed", "motor speed", "drehzahl", "geschwindigkeit",
              "winkelgeschwindigkeit", "vitesse", "velocidad"),
    "theta": ("theta", "angle", "position", "rotor angle", "motor angle", "pos", "winkel",
              "drehwinkel", "ángulo", "angulo", "posición", "posicion"),
}

#: what each canonical column measures
DIMENSION = {"t": ("time",), "v": ("voltage",), "tau": ("torque", "force"), "i": ("current",),
             "omega": ("angular speed", "linear speed"), "theta": ("angle", "length")}

_RPM = 2 * math.pi / 60.0
#: unit as written (case-sensitive, spaces removed) -> (SI factor, dimension)
UNIT_TABLE: dict[str, tuple[float, str]] = {
    "s": (1.0, "time"), "sec": (1.0, "time"), "ms": (1e-3, "time"), "us": (1e-6, "time"),
    "µs": (1e-6, "time"), "min": (60.0, "time"),
    "V": (1.0, "voltage"), "mV": (1e-3, "voltage"),
    "A": (1.0, "current"), "mA": (1e-3, "current"),
    "Nm": (1.0, "torque"), "N.m": (1.0, "torque"), "N*m": (1.0, "torque"),
    "N·m": (1.0, "torque"), "mNm": (1e-3, "torque"), "mN.m": (1e-3, "torque"),
    "N": (1.0, "force"),
    "rad/s": (1.0, "angular speed"), "rpm": (_RPM, "angular speed"),
    "RPM": (_RPM, "angular speed"), "r/min": (_RPM, "angular speed"),
    "krpm": (1000 * _RPM, "angular speed"), "rps": (2 * math.pi, "angular speed"),
    "deg/s": (math.pi / 180.0, "angular speed"), "°/s": (math.pi / 180.0, "angular speed"),
    "m/s": (1.0, "linear speed"), "mm/s": (1e-3, "linear speed"),
    "rad": (1.0, "angle"), "deg": (math.pi / 180.0, "angle"), "°": (math.pi / 180.0, "angle"),
    "rev": (2 * math.pi, "angle"), "turns": (2 * math.pi, "angle"),
    "m": (1.0, "length"), "mm": (1e-3, "length"),
}

#: spellings loggers write for units of UNIT_TABLE (spaces removed); not "1/s", which one
#: logger writes for rad/s and another (a rotational frequency, DIN 1301) for rev/s
ALIASES = {"rad/sec": "rad/s", "U/min": "rpm", "1/min": "rpm", "min^-1": "rpm",
           "min-1": "rpm", "rev/min": "rpm", "tr/min": "rpm", "rev/s": "rps", "U/s": "rps",
           "tr/s": "rps", "volt": "V", "volts": "V", "amp": "A", "amps": "A",
           "seconds": "s", "degree": "deg", "degrees": "deg"}
#: units written by name (WPILib's units library: ``Volts.name()`` is "Volt",
#: ``RotationsPerSecond.name()`` "Rotation per Second"; SysIdRoutineLog stores these in its
#: entries' metadata), compared in lower case with single spaces, a plural "s" allowed
NAMES = {"volt": "V", "millivolt": "mV", "amp": "A", "ampere": "A", "milliamp": "mA",
         "milliampere": "mA", "second": "s", "millisecond": "ms", "microsecond": "us",
         "radian": "rad", "rotation": "rev", "revolution": "rev", "turn": "rev", "degree": "deg",
         "radian per second": "rad/s", "rotation per second": "rps",
         "revolution per second": "rps", "rotation per minute": "rpm",
         "revolution per minute": "rpm", "degree per second": "deg/s", "meter": "m",
         "millimeter": "mm", "meter per second": "m/s", "newton meter": "Nm", "newton": "N"}


def _named(unit: str) -> str | None:
    """The UNIT_TABLE key of a unit written by name (:data:`NAMES`), or None."""
    words = " ".join(unit.lower().replace("-", " ").split()).split(" per ")
    singular = [w[:-1] if w.endswith("s") and w[:-1] in NAMES else w for w in words]
    return NAMES.get(" per ".join(singular))


def unit_of(unit: str) -> tuple[float, str] | None:
    """(SI factor, dimension) of a unit as a file writes it (``rpm``, ``U/min``, ``Rotation
    per Second``), or None when it is none the tool knows."""
    key = unit.replace(" ", "")
    hit = UNIT_TABLE.get(ALIASES.get(key, key))
    if hit is None and (name := _named(unit)) is not None:
        hit = UNIT_TABLE[name]
    return hit


_HEADER_RE = re.compile(r"^\s*([^\[\]()]+?)\s*[\[(]\s*([^\[\]()]+?)\s*[\])]\s*$")


def annotated(header: str) -> tuple[str, float] | None:
    """(canonical column, SI factor) for a header such as ``Speed (rpm)``, or None."""
    m = _HEADER_RE.match(header)
    if not m:
        return None
    word = " ".join(m.group(1).lower().replace("_", " ").split())
    hit = unit_of(m.group(2))
    if hit is None:
        return None
    factor, dim = hit
    for canon, words in WORDS.items():
        if word in words and dim in DIMENSION[canon]:
            return canon, factor
    return None


def claimed(cols: list[str], taken) -> dict[str, tuple[str, float]]:
    """canonical column -> (header, SI factor) for the columns :func:`annotated` names once,
    among the canonical columns not in ``taken``."""
    found: dict[str, list[tuple[str, float]]] = {}
    for c in cols:
        hit = annotated(c)
        if hit and hit[0] not in taken:
            found.setdefault(hit[0], []).append((c, hit[1]))
    return {canon: hits[0] for canon, hits in found.items() if len(hits) == 1}


__all__ = ["ALIASES", "NAMES", "UNIT_TABLE", "WORDS", "annotated", "claimed", "unit_of"]
