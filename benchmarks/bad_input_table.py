"""The "Bad input" table of BENCHMARKS.md: every case of tests/bad_inputs.py run as a real command.

A short FF session is simulated and identified, the bad inputs are derived from it, and each
case runs ``python -m helmet_anc.cli ...`` (this tree's command line) in a subprocess. For
each: exit status, the one stderr line, the number of stderr lines, and the files touched
(every file of the folder compared before/after). Prints a Markdown table.

    python benchmarks/bad_input_table.py
"""

from __future__ import annotations

import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))
sys.path.insert(0, str(ROOT))

from bad_inputs import CASES, argv_of, prepare, snapshot  # noqa: E402
from sysid.identify import IdentificationOptions, identify  # noqa: E402
from sysid.simulate import SessionSpec, simulate_session, write_session  # noqa: E402


def _touched(before: dict, after: dict) -> str:
    changed = sorted(set(before) ^ set(after) | {k for k in before.keys() & after.keys() if before[k] != after[k]})
    return "none" if not changed else ", ".join(changed)


def main() -> int:
    with tempfile.TemporaryDirectory() as scratch:
        scratch = Path(scratch)
        session = simulate_session(SessionSpec(path="ff", seed=11, noise_duration=8.0, sweep_duration=2.0))
        files = write_session(session, scratch / "session")
        model = identify(session.noise, session.sweeps, "ff", IdentificationOptions(gammas=tuple(range(10, 1001, 30))))
        model.model.save(scratch / "model.json")
        folder = scratch / "inputs"
        inputs = prepare(folder, files, scratch / "model.json")
        print("| input tried | command | exit | message (stderr, one line) | stderr lines | seconds | files touched |")
        print("|---|---|---|---|---|---|---|")
        for case in CASES:
            argv = argv_of(case, inputs)
            before = snapshot(folder)
            started = time.perf_counter()
            # This tree's command line (python -m), whatever helmet-anc is installed.
            result = subprocess.run([sys.executable, "-m", "helmet_anc.cli", *argv], capture_output=True, text=True,
                                    env={**os.environ, "COLUMNS": "200", "PYTHONPATH": str(ROOT)})
            seconds = time.perf_counter() - started
            lines = result.stderr.splitlines()
            message = (lines[-1] if lines else "").replace(str(folder) + "/", "").replace("|", "\\|")
            print(f"| {case.label} | {case.argv[0]} | {result.returncode} | {message} | {len(lines)} | "
                  f"{seconds:.1f} | {_touched(before, snapshot(folder))} |")
    return 0


if __name__ == "__main__":
    sys.exit(main())
