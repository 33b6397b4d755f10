"""Warnings about the inputs (clipping, DC offset) come before the results they qualify, never after them."""

import os
import subprocess
import sys

from conftest import short_spec
from repo import REPO

from sysid.core.plants import appendix_a_model
from sysid.simulate import simulate_session, write_session


def test_clipping_and_offset_warnings_precede_the_results(tmp_path):
    session = simulate_session(short_spec("ff", seed=3), effects=["clipping:1.4,0.4", "dc-offset:0.01"])
    files = write_session(session, tmp_path / "rig")
    appendix_a_model("ff").save(tmp_path / "model.json")
    # Unbuffered and merged: the order the user sees on a terminal.
    done = subprocess.run([sys.executable, "-m", "helmet_anc.cli", "compare", str(tmp_path / "model.json"),
                           "--sweep", str(files["sweep1"]), "--sweep", str(files["sweep2"])],
                          stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True, cwd=tmp_path,
                          env={**os.environ, "PYTHONPATH": str(REPO), "PYTHONUNBUFFERED": "1"})
    assert done.returncode == 0, done.stdout
    lines = done.stdout.splitlines()
    warned = [k for k, line in enumerate(lines) if line.startswith("helmet-anc: warning:")]
    result = next(k for k, line in enumerate(lines) if "noise floor" in line)
    assert any("clipped" in lines[k] for k in warned) and any("DC offset" in lines[k] for k in warned), lines
    assert max(warned) < result, "\n".join(lines)
