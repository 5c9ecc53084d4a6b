"""Headers that name quantity and unit (``Speed (rpm)``, ``t [s]``) are read in SI units; a bare
word, an unknown unit or two headers claiming one column are not guessed."""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest

from pmdcid.errors import LogError
from pmdcid.io import parse_mapping, read_log
from pmdcid.io.headers import annotated

RPM = 60.0 / (2 * math.pi)  # rpm per rad/s
DEG = 180.0 / math.pi


def _si(rng):
    n = 400
    t = np.arange(n) * 1e-3
    return {"t": t, "v": rng.normal(0, 2, n), "i": rng.normal(0, 0.3, n),
            "omega": np.cumsum(rng.normal(0, 0.5, n)), "theta": np.cumsum(rng.normal(0, 1e-3, n))}


def _write(path, cols: dict[str, np.ndarray]):
    names = list(cols)
    rows = np.column_stack([cols[k] for k in names])
    lines = [",".join(f'"{n}"' if "," in n else n for n in names)]
    lines += [",".join(repr(float(x)) for x in row) for row in rows]
    path.write_text("\n".join(lines) + "\n")
    return path


CASES = {
    "brackets SI": {"t [s]": ("t", 1.0), "v [V]": ("v", 1.0), "i [A]": ("i", 1.0),
                    "omega [rad/s]": ("omega", 1.0), "theta [rad]": ("theta", 1.0)},
    "words, other units": {"Time (ms)": ("t", 1e3), "Voltage (mV)": ("v", 1e3),
                           "Current (mA)": ("i", 1e3), "Speed (rpm)": ("omega", RPM),
                           "Position (deg)": ("theta", DEG)},
    "mixed": {"t": ("t", 1.0), "v": ("v", 1.0), "motor_speed [krpm]": ("omega", RPM / 1000),
              "Angle (rev)": ("theta", 1 / (2 * math.pi))},
}


@pytest.mark.parametrize("case", list(CASES))
def test_annotated_headers_read_in_si(tmp_path, rng, case):
    """The same log written under annotated headers (values in the headers' units) reads back
    as the canonical SI log, to rounding, with one warning naming the conversions."""
    si = _si(rng)
    cols = {h: si[c] * k for h, (c, k) in CASES[case].items()}
    with warnings.catch_warnings(record=True) as got:
        warnings.simplefilter("always")
        log = read_log(_write(tmp_path / "a.csv", cols))
    for c, _ in CASES[case].values():
        ref = si[c] - si[c][0] if c == "t" else si[c]
        np.testing.assert_allclose(log.t if c == "t" else log[c], ref, rtol=1e-9, atol=1e-12)
    said = [str(w.message) for w in got if "headers name" in str(w.message)]
    assert len(said) == 1, said


def test_what_is_not_guessed(tmp_path, rng):
    """A bare word (unit unknown), an unknown unit and a unit of the wrong quantity are left
    alone: the command then says the column is missing."""
    for h in ("speed", "omega [counts/s]", "Speed (V)", "velocity (m)"):
        assert annotated(h) is None, h
    si = _si(rng)
    p = _write(tmp_path / "b.csv", {"t": si["t"], "v": si["v"], "speed": si["omega"]})
    log = read_log(p)
    assert not log.has("omega") and not log.has("theta")


def test_two_headers_claiming_one_column_are_both_left(tmp_path, rng):
    si = _si(rng)
    p = _write(tmp_path / "c.csv", {"t": si["t"], "v": si["v"], "Speed (rpm)": si["omega"] * RPM,
                                    "omega [rad/s]": si["omega"]})
    assert not read_log(p).has("omega")


def test_a_mapping_or_a_canonical_column_wins(tmp_path, rng):
    si = _si(rng)
    p = _write(tmp_path / "d.csv", {"t": si["t"], "v": si["v"], "omega": si["omega"],
                                    "Speed (rpm)": 2 * si["omega"] * RPM})
    np.testing.assert_allclose(read_log(p)["omega"], si["omega"])
    log = read_log(p, parse_mapping(['omega="Speed (rpm)"*0.5*rpm']))
    np.testing.assert_allclose(log["omega"], si["omega"], rtol=1e-12)
    with pytest.raises(LogError):
        read_log(_write(tmp_path / "e.csv", {"T (s)x": si["t"], "v": si["v"]}))


def test_a_german_lab_csv_reads_without_a_mapping(tmp_path, rng):
    """A lab CSV as German software writes it (semicolons, decimal commas, ``Zeit [ms]``,
    ``Strom [mA]``, ``Drehzahl [U/min]``) reads as the canonical SI log, to the printed digits;
    before, its words and ``U/min`` were unknown and the command asked for a mapping."""
    si = _si(rng)
    heads = {"Zeit [ms]": ("t", 1e3), "Spannung [V]": ("v", 1.0), "Strom [mA]": ("i", 1e3),
             "Drehzahl [U/min]": ("omega", RPM)}
    rows = np.column_stack([si[c] * k for c, k in heads.values()])
    lines = [";".join(heads)] + [";".join(f"{x:.6f}".replace(".", ",") for x in r) for r in rows]
    p = tmp_path / "messung.csv"
    p.write_text("\n".join(lines) + "\n")
    log = read_log(p)
    for c, k in heads.values():
        ref = si[c] - si[c][0] if c == "t" else si[c]
        np.testing.assert_allclose(log.t if c == "t" else log[c], ref, rtol=0, atol=1e-6 / k)


@pytest.mark.parametrize("header, canon, factor", [
    ("Vitesse (tr/min)", "omega", 2 * math.pi / 60), ("Temps (s)", "t", 1.0),
    ("Courant (mA)", "i", 1e-3), ("velocidad [1/min]", "omega", 2 * math.pi / 60),
    ("Drehwinkel [deg]", "theta", math.pi / 180), ("Drehmoment [Nm]", "tau", 1.0)])
def test_other_languages_words_and_unit_spellings(header, canon, factor):
    assert annotated(header) == (canon, pytest.approx(factor))


def test_a_foreign_word_with_a_unit_of_another_quantity_is_not_taken():
    for h in ("Drehzahl [V]", "Strom (U/min)", "vitesse (1/s)"):
        assert annotated(h) is None, h
