"""`pmdcid simulate`: reproduces the fixtures' noise-free signals; makes seeded noisy logs."""

import json

import numpy as np
import pytest
from click.testing import CliRunner
from repo_paths import FIXTURES

from pmdcid.cli import main
from pmdcid.io import read_log
from pmdcid.synth import PAPER, PAPER_NOISE

FIX = FIXTURES


@pytest.fixture
def paper_model(tmp_path):
    p = tmp_path / "paper.json"
    p.write_text(json.dumps({"parameters": {k: {"value": v} for k, v in PAPER.items()},
                             "effects": []}))
    return p


@pytest.mark.parametrize("name", ["step_1.5V.csv", "triangle.csv"])
def test_simulate_reproduces_fixture(tmp_path, paper_model, name):
    out = tmp_path / "out.csv"
    res = CliRunner().invoke(main, ["simulate", str(FIX / "paper" / name), "-m", str(paper_model),
                                    "-o", str(out)])
    assert res.exit_code == 0, res.output
    sim, meas = read_log(out), read_log(FIX / "paper" / name)
    # the fixture is this simulation plus its stated noise: residual std = noise std
    r_om = meas["omega"] - sim["omega"]
    r_i = meas["i"] - sim["i"]
    assert np.std(r_om) == pytest.approx(PAPER_NOISE.omega, rel=0.05)
    assert np.std(r_i) == pytest.approx(PAPER_NOISE.i, rel=0.05)
    assert abs(np.mean(r_om)) < 4 * PAPER_NOISE.omega / np.sqrt(len(r_om))
    q = 2 * np.pi / PAPER_NOISE.encoder
    # within half a count, give or take the model file's rounding of the values (1e-8 rad
    # where a sample sits at half a count: the triangle's with the edge refined, session 18)
    assert np.max(np.abs(meas["theta"] - sim["theta"])) <= q / 2 + 1e-7


def test_simulate_noise_is_seeded(tmp_path, paper_model):
    args = ["simulate", str(FIX / "paper" / "step_1.0V.csv"), "-m", str(paper_model),
            "--noise-omega", "0.01", "--seed", "7", "-o"]
    r = CliRunner()
    assert r.invoke(main, args + [str(tmp_path / "a.csv")]).exit_code == 0
    assert r.invoke(main, args + [str(tmp_path / "b.csv")]).exit_code == 0
    a, b = read_log(tmp_path / "a.csv"), read_log(tmp_path / "b.csv")
    assert np.array_equal(a["omega"], b["omega"])


def test_simulate_torque_driven(tmp_path, paper_model):
    t = np.arange(2000) * 1e-3
    inp = tmp_path / "tau.csv"
    inp.write_text("t,tau\n" + "".join(f"{x:.6f},{0.02 if x > 0.2 else 0.0}\n" for x in t))
    out = tmp_path / "o.csv"
    res = CliRunner().invoke(main, ["simulate", str(inp), "-m", str(paper_model), "-o", str(out)])
    assert res.exit_code == 0, res.output
    header = [ln for ln in out.read_text().splitlines() if not ln.startswith("#")][0]
    assert header == "t,tau,omega,theta"
    log = read_log(out)
    expect = (0.02 - PAPER["bc"]) / PAPER["bv"]
    assert log["omega"][-1] == pytest.approx(expect, rel=1e-3)


def test_simulate_several_inputs_into_a_folder(tmp_path, paper_model):
    """One call over several INPUTs writes DIR/<input name> for each, byte for byte what the
    single-input form writes."""
    names = ["step_1.0V.csv", "step_2.0V.csv", "blocked_1.0V.csv"]
    ins = [str(FIX / "paper" / n) for n in names]
    r = CliRunner()
    res = r.invoke(main, ["simulate", *ins, "-m", str(paper_model), "-o", str(tmp_path / "sims"),
                          "--noise-omega", "0.01", "--seed", "3"])
    assert res.exit_code == 0, res.output
    assert sorted(p.name for p in (tmp_path / "sims").iterdir()) == sorted(names)
    for src, name in zip(ins, names, strict=True):
        one = tmp_path / f"one_{name}"
        res = r.invoke(main, ["simulate", src, "-m", str(paper_model), "-o", str(one),
                              "--noise-omega", "0.01", "--seed", "3"])
        assert res.exit_code == 0, res.output
        assert (tmp_path / "sims" / name).read_bytes() == one.read_bytes()


@pytest.mark.parametrize("case", ["same names", "one input, -o a folder", "-o a file"])
def test_simulate_several_inputs_refusals(tmp_path, paper_model, case):
    a = FIX / "paper" / "step_1.0V.csv"
    (tmp_path / "copy").mkdir()
    b = tmp_path / "copy" / "step_1.0V.csv"
    b.write_bytes(a.read_bytes())
    (tmp_path / "file.csv").write_text("not a folder\n")
    args, code = {
        "same names": ([str(a), str(b), "-o", str(tmp_path / "out")], 2),
        "one input, -o a folder": ([str(a), "-o", str(tmp_path / "copy")], 2),
        "-o a file": ([str(a), str(FIX / "paper" / "step_2.0V.csv"), "-o",
                       str(tmp_path / "file.csv")], 1),
    }[case]
    res = CliRunner().invoke(main, ["simulate", *args, "-m", str(paper_model)])
    assert res.exit_code == code, res.output
    assert not (tmp_path / "out").exists()
    assert (tmp_path / "file.csv").read_text() == "not a folder\n"


def test_simulate_keeps_input_t_to_the_last_digit(tmp_path, paper_model):
    """INPUT's t is kept unchanged (CONTRACT): Unix-epoch stamps with microseconds
    (1700000000.011166) were written with 15 significant digits (1700000000.01117)."""
    t = 1700000000.011166 + np.arange(300) * 0.001
    rows = [f"{x!r},{1.0 if k >= 50 else 0.0}" for k, x in enumerate(t.tolist())]
    (tmp_path / "in.csv").write_text("t,v\n" + "\n".join(rows) + "\n")
    out = tmp_path / "out.csv"
    res = CliRunner().invoke(main, ["simulate", str(tmp_path / "in.csv"), "-m", str(paper_model),
                                    "-o", str(out)])
    assert res.exit_code == 0, res.output
    data = [ln for ln in out.read_text().splitlines() if not ln.startswith("#")][1:]
    assert [ln.split(",")[0] for ln in data] == [r.split(",")[0] for r in rows]
    assert data[0].startswith("1700000000.011166,")
