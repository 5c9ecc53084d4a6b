"""The MDF reader (pmdcid/io/formats/mdf.py) on files asammdf itself wrote."""

import os
import subprocess
import sys

import numpy as np
from repo_paths import REPO

CLI = "import sys; from pmdcid.cli import main; sys.exit(main())"


def test_truncated_file_is_one_line_and_nothing_else(tmp_path):
    """asammdf fails half-way through building its object on a truncated file; that object's
    ``__del__`` then fails too, which Python printed ('Exception ignored in ... MDF4.__del__')
    after the one-line error. A user's terminal shows the one line only."""
    from asammdf import MDF, Signal

    t = np.arange(2000) * 1e-3
    whole, cut = tmp_path / "whole.mf4", tmp_path / "log.mf4"
    m = MDF(version="4.10")
    m.append([Signal(np.sin(t), t, name="u_arm", unit="V")], acq_name="motor")
    m.save(whole, overwrite=True)
    m.close()
    data = whole.read_bytes()
    cut.write_bytes(data[:len(data) // 2])
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    env.pop("PMDCID_DEBUG", None)
    proc = subprocess.run([sys.executable, "-c", CLI, "channels", str(cut)], cwd=tmp_path,
                          capture_output=True, text=True, env=env, timeout=60)
    assert proc.returncode == 1, proc.stderr
    assert proc.stderr.startswith(f"error: {cut}: is not a readable MDF file"), proc.stderr
    assert proc.stderr.count("\n") == 1, proc.stderr
    assert "Traceback" not in proc.stderr and "Exception ignored" not in proc.stderr
