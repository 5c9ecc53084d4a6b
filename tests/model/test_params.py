"""Round three, families 3 and 5 (issue 29): the strict model reader (duplicate keys, non-finite
tokens, units honoured, effect parameters plausible for the motor) and optimistic locking of the
model file (a command writes back the model it read only if the file has not changed)."""

from __future__ import annotations

import json
import shutil
from pathlib import Path
from types import SimpleNamespace

import pytest
from click.testing import CliRunner
from repo_paths import FIXTURES

from pmdcid.cli import main
from pmdcid.errors import ModelError
from pmdcid.model import load_model, save_model

FIX = FIXTURES
PAPER = '"R": 2.3724, "L": 0.0177933, "km": 0.0502, "J": 0.00310442, "bv": 0.0314, "bc": 0.005'


def _obj(params: str, effects: str = "") -> str:
    """A model file's text from the inside of its ``parameters`` object."""
    tail = f', "effects": [{effects}]' if effects else ""
    return '{"parameters": {' + params + "}" + tail + "}"


def _load(tmp_path, text: str):
    p = tmp_path / "m.json"
    p.write_text(text)
    return load_model(p)


@pytest.mark.parametrize("text", [
    '{"parameters": {"R": 1.0, "R": 2.0}}',
    '{"parameters": {"R": {"value": 1.0, "value": 2.0}}}',
    '{"parameters": {"R": 1.0}, "parameters": {"R": 2.0}}',
], ids=["param", "value", "top"])
def test_a_key_given_twice_is_refused(tmp_path, text):
    with pytest.raises(ModelError, match="given twice"):
        _load(tmp_path, text)


def test_non_finite_tokens_are_never_written_back(tmp_path):
    with pytest.raises(ModelError, match="not finite"):
        _load(tmp_path, '{"parameters": {"R": {"value": NaN}}}')
    m = _load(tmp_path, '{"parameters": {"R": 1.0}, "note": NaN, "x": [Infinity, 1]}')
    save_model(m, tmp_path / "m.json")
    back = json.loads((tmp_path / "m.json").read_text(),
                      parse_constant=lambda token: pytest.fail(f"{token} written back"))
    assert back["note"] is None and back["x"] == [None, 1]


@pytest.mark.parametrize("entry, value", [
    ('"R": {"value": 2370, "units": "mohm"}', ("R", 2.37)),
    ('"J": {"value": 31044.2, "unit": "g cm^2"}', ("J", 0.00310442)),
    ('"J": {"value": 31.0442, "unit": "kg cm^2"}', ("J", 0.00310442)),
], ids=["units-key", "g-cm2", "kg-cm2"])
def test_units_are_honoured(tmp_path, entry, value):
    m = _load(tmp_path, _obj(entry))
    assert m.value(value[0]) == pytest.approx(value[1], rel=1e-12)


def test_two_different_units_are_refused(tmp_path):
    with pytest.raises(ModelError, match="two units"):
        _load(tmp_path, '{"parameters": {"R": {"value": 2370, "unit": "ohm", "units": "mohm"}}}')


@pytest.mark.parametrize("extra", ['"ca": 1e6, "cn": 4', '"fs": 5e3', '"tau0": -300'],
                         ids=["cogging", "stribeck", "offset"])
def test_effect_torques_must_be_plausible_for_the_motor(tmp_path, extra):
    with pytest.raises(ModelError, match="implausible for this motor"):
        _load(tmp_path, _obj(f"{PAPER}, {extra}"))
    m = _load(tmp_path, _obj(f'{PAPER}, "ca": 0.01, "cn": 4, "cphi": 0', '"cogging"'))
    assert m.value("ca") == 0.01


def test_simulate_refuses_an_absurd_cogging_amplitude(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    (tmp_path / "m.json").write_text(_obj(f'{PAPER}, "ca": 1e6, "cn": 4', '"cogging"'))
    shutil.copy(FIX / "paper" / "step_1.5V.csv", tmp_path / "step.csv")
    res = CliRunner().invoke(main, ["simulate", "step.csv", "-m", "m.json", "-o", "o.csv"],
                             catch_exceptions=False)
    assert res.exit_code == 1 and "'ca'" in res.stderr, res.stderr
    assert not (tmp_path / "o.csv").exists()


def test_diagnose_does_not_overwrite_a_concurrent_stage(tmp_path, monkeypatch):
    """diagnose reads MODEL, fit-electrical writes it meanwhile, diagnose writes MODEL back:
    the stage's results must not be lost (optimistic locking, one line, rerun)."""
    import pmdcid.diagnose.entry as files

    monkeypatch.chdir(tmp_path)
    shutil.copy(FIX / "paper" / "truth.json", tmp_path / "model.json")
    shutil.copy(FIX / "paper" / "step_1.5V.csv", tmp_path / "step.csv")

    def concurrent(logs, model, **kw):
        other = json.loads(Path("model.json").read_text())  # another process's stage
        other["parameters"]["R"] = 2.5
        Path("model.json").write_text(json.dumps(other))
        return SimpleNamespace(model=model.copy(), summary={"added": []}, table=lambda: "",
                               record_notes=lambda model: None)

    monkeypatch.setattr(files, "diagnose_logs", concurrent)
    res = CliRunner().invoke(main, ["diagnose", "step.csv", "-m", "model.json", "-o",
                                    "model.json"], catch_exceptions=False)
    assert res.exit_code == 1, res.output
    assert "changed since" in res.stderr and len(res.stderr.strip().splitlines()) == 1
    assert load_model("model.json").value("R") == 2.5


def test_a_model_saved_twice_by_its_reader_is_fine(tmp_path):
    p = tmp_path / "m.json"
    shutil.copy(FIX / "paper" / "truth.json", p)
    m = load_model(p)
    m.set("R", 3.0)
    save_model(m, p)
    m.set("R", 3.5)
    save_model(m, p)  # its own write is what it read now
    assert load_model(p).value("R") == 3.5
    p.write_text(p.read_text().replace("3.5", "4.5"))
    with pytest.raises(ModelError, match="changed since"):
        m.save(p)


@pytest.mark.parametrize("text, said", [
    (_obj('"R": {"value": 2.37, "stderr": "0.1"}'), r"parameter 'R' has stderr '0\.1'"),
    (_obj('"R": {"value": 2.37, "stderr": -0.1}'), r"parameter 'R' has stderr -0\.1"),
    (_obj('"R": {"value": 2.37, "stage": 5}'), r"parameter 'R' has stage 5"),
    ('{"parameters": {"R": 2.37}, "lumped": "yes"}', r"'lumped' is 'yes'"),
    (_obj('"R": {"value": 1' + "0" * 5000 + "}"), r"parameter 'R' is not finite"),
    (_obj('"R": {"value": 2.37}, "L": {"value": }'),
     r"not valid JSON \(line 1 column \d+, near parameters > L > value: Expecting value\)"),
    (_obj('"R": {"value": 2.3.4}'), r"near parameters > R > value: Expecting ','"),
], ids=["stderr-text", "stderr-negative", "stage-number", "lumped-text", "5000-digits",
        "missing-value", "two-points"])
def test_each_model_file_error_names_the_key(tmp_path, text, said):
    """A value of the wrong kind, where the JSON parses, is one line naming the file and the key
    (a stderr given as text or negative was silently dropped or kept, a 'lumped' that is not
    true/false silently read as SI); a syntax error says under which keys it lies."""
    with pytest.raises(ModelError, match=said) as exc:
        _load(tmp_path, text)
    assert str(exc.value).startswith(str(tmp_path / "m.json")) and "\n" not in str(exc.value)


def test_a_null_stderr_is_not_known(tmp_path):
    m = _load(tmp_path, _obj('"R": {"value": 2.37, "stderr": null, "stage": null}'))
    assert m.value("R") == 2.37 and m.parameters["R"].stderr != m.parameters["R"].stderr
