"""Property: whatever text a log file holds, read_log returns a valid Log or raises PmdcidError.

Never any other exception (pandas, numpy, UnicodeError, IndexError ...): the CLI edge would turn
those into an "internal error", which is a defect.
"""

from __future__ import annotations

import warnings

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pmdcid.errors import PmdcidError, PmdcidWarning
from pmdcid.io import ColumnMap, Log, read_log
from pmdcid.io.mapping import parse_spec

SETTINGS = settings(max_examples=int(__import__("os").environ.get("HYP_N", 150)), deadline=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture,
                                           HealthCheck.too_slow])

NAMES = st.sampled_from(["t", "v", "i", "omega", "theta", "tau", "x", "speed_rpm", "", "t ",
                         '"t"', "v.1", "Unnamed: 0", "t;v", "\ufefft",
                         '"a\nb"', '"t\r"'])
CELLS = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(-10**30, 10**30).map(str),
    st.sampled_from(["", " ", "nan", "NaN", "inf", "-inf", "1e999", "abc", '"', '""', "1,5",
                     "0x10", "1_000", "True", "#", "null", "NA", "\t", "é", "0.001", "1e-3"]),
    st.text(max_size=6),
)


@st.composite
def csv_texts(draw):
    """Plausible-looking CSV with random damage: comments, header, ragged rows, odd cells."""
    lines = []
    for _ in range(draw(st.integers(0, 3))):
        lines.append("# " + draw(st.sampled_from(["kind: blocked-rotor", "x", ":", "a: b: c", ""])))
    ncol = draw(st.integers(1, 5))
    header = [draw(NAMES) for _ in range(ncol)]
    if draw(st.booleans()):
        header[0] = "t"
    lines.append(",".join(header))
    nrow = draw(st.integers(0, 12))
    regular = draw(st.booleans())
    t0, dt = draw(st.floats(-1e3, 1e3)), draw(st.sampled_from([1e-3, 0.5, 1.0, 0.0, -1e-3]))
    for k in range(nrow):
        width = ncol if regular else draw(st.integers(0, ncol + 2))
        row = [repr(t0 + k * dt) if (j == 0 and regular) else draw(CELLS) for j in range(width)]
        lines.append(",".join(row))
    sep = draw(st.sampled_from(["\n", "\r\n", "\r"]))
    return sep.join(lines) + draw(st.sampled_from(["", sep]))


def _check(path, mapping=None):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PmdcidWarning)
        try:
            log = read_log(path, mapping)
        except PmdcidError as exc:
            msg = str(exc)
            assert msg and "\n" not in msg, repr(msg)
            return None
    assert isinstance(log, Log)
    assert log.n >= 3 and np.all(np.isfinite(log.t)) and np.all(np.diff(log.t) > 0)
    for name, col in log.data.items():
        assert len(col) == log.n, name
        assert np.all(np.isfinite(col)), name
    return log


@SETTINGS
@given(text=csv_texts())
def test_random_csv_text(tmp_path_factory, text):
    p = tmp_path_factory.mktemp("h") / "log.csv"
    p.write_text(text, encoding="utf-8", newline="")
    _check(p)


@SETTINGS
@given(text=st.text(max_size=300))
def test_arbitrary_text(tmp_path_factory, text):
    p = tmp_path_factory.mktemp("h") / "log.csv"
    p.write_text(text, encoding="utf-8", errors="surrogatepass", newline="")
    _check(p)


@SETTINGS
@given(data=st.binary(max_size=300))
def test_arbitrary_bytes(tmp_path_factory, data):
    p = tmp_path_factory.mktemp("h") / "log.csv"
    p.write_bytes(b"t,v\n" + data)
    _check(p)


@SETTINGS
@given(text=csv_texts(), spec=st.sampled_from(["t=x*ms", "omega=speed_rpm*rpm", "v=v*2+1",
                                               "theta=x/4096*2*pi", "i=i*mA-0.5", "t=t*1e-3"]))
def test_random_csv_with_mapping(tmp_path_factory, text, spec):
    p = tmp_path_factory.mktemp("h") / "log.csv"
    p.write_text(text, encoding="utf-8", newline="")
    s = parse_spec(spec)
    _check(p, ColumnMap({s.canon: s}))


@SETTINGS
@given(spec=st.one_of(st.text(max_size=40),
                      st.from_regex(r"[a-z]{1,6}=[a-z_]{0,8}([*/]([0-9.e+-]{1,6}|rpm|pi|ms|x)){0,3}"
                                    r"([+-][0-9.e]{1,5})?", fullmatch=True)))
def test_random_mapping_text(spec):
    """A column mapping either parses to a finite scale and offset or raises the tool's error."""
    try:
        s = parse_spec(spec)
    except PmdcidError as exc:
        assert "\n" not in str(exc)
        return
    assert np.isfinite(s.scale) and np.isfinite(s.offset) and s.source


JSON = st.recursive(
    st.none() | st.booleans() | st.floats(allow_nan=True) | st.integers(-10**20, 10**20)
    | st.text(max_size=8),
    lambda kids: st.lists(kids, max_size=4) | st.dictionaries(st.text(max_size=6), kids,
                                                               max_size=4),
    max_leaves=12)
PARAM_NAMES = st.sampled_from(["R", "L", "km", "J", "bv", "bc", "dz", "fs", "ws", "x", ""])


@st.composite
def model_objects(draw):
    """Model-file-like JSON: parameters with odd entries, effects with odd names."""
    params = draw(st.dictionaries(PARAM_NAMES, st.one_of(
        JSON, st.fixed_dictionaries({"value": JSON}, optional={"stderr": JSON, "unit": JSON,
                                                               "stage": JSON})), max_size=5))
    obj = {"parameters": params}
    if draw(st.booleans()):
        obj["effects"] = draw(st.one_of(JSON, st.lists(st.sampled_from(
            ["stribeck", "cogging", "nope", ""]), max_size=3)))
    return draw(st.one_of(st.just(obj), JSON))


@SETTINGS
@given(obj=model_objects())
def test_random_model_files(tmp_path_factory, obj):
    """load_model returns a valid Model or raises the tool's error, whatever the JSON holds."""
    import json
    import math

    from pmdcid.model import Model, load_model

    p = tmp_path_factory.mktemp("m") / "model.json"
    p.write_text(json.dumps(obj))
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PmdcidWarning)
        try:
            m = load_model(p)
        except PmdcidError as exc:
            assert "\n" not in str(exc)
            return
    assert isinstance(m, Model)
    assert all(math.isfinite(par.value) for par in m.parameters.values())
