"""Peak memory and time of identify on long noise recordings, in memory and read from the file in blocks.

For noise recordings of 1, 5, 10 and 20 minutes (16-bit stereo WAV at 44.1 kHz, written
block by block by ``tests/long_sessions.py``) of the FF appendix-A plant, with the two
9 s sweeps of the same simulated session, each identification (default options) runs in
a fresh child process: its peak resident memory (``ru_maxrss``, which includes the
interpreter and libraries, printed as "baseline"), wall and CPU time. "in memory" loads
the noise with ``load_recording`` (the path before bounded memory, still the API's
in-memory loader); "streamed" opens it with ``open_recording``. Both run side by side.

Run:  python benchmarks/bench_memory.py [--minutes 1 5 10 20] [--in-memory-up-to 20]
(prints a Markdown table)
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

from long_sessions import measure_identify, write_long_noise  # noqa: E402
from sysid.simulate import SessionSpec, simulate_session, write_session  # noqa: E402

SPEC = SessionSpec(path="ff", seed=11, noise_duration=23.0, sweep_duration=9.0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, nargs="+", default=[1, 5, 10, 20])
    parser.add_argument("--in-memory-up-to", type=float, default=20.0,
                        help="longest recording (minutes) also identified in memory")
    args = parser.parse_args()
    session = simulate_session(SPEC)
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        files = write_session(session, folder)
        sweeps = [files["sweep1"], files["sweep2"]]
        for minutes in args.minutes:
            noise = write_long_noise(Path(folder) / f"noise_{minutes:g}min.wav", session, 60.0 * minutes)
            size_mb = noise.stat().st_size / 2**20
            for streamed in (False, True):
                if not streamed and minutes > args.in_memory_up_to:
                    continue
                m = measure_identify(noise, sweeps, "ff", streamed, options={})
                rows.append((minutes, size_mb, "streamed" if streamed else "in memory", m))
                print(f"{minutes:g} min {'streamed' if streamed else 'in memory'}: {m['peak_mb']:.0f} MB, "
                      f"{m['wall_s']:.1f} s wall, {m['cpu_s']:.1f} s CPU", file=sys.stderr, flush=True)
            noise.unlink()
    print(f"Machine: {platform.machine()}, {os.cpu_count()} cores, Python {platform.python_version()}; "
          f"{datetime.date.today().isoformat()}; default IdentificationOptions, FF appendix-A plant.\n")
    print("| noise | WAV | identify | peak memory | baseline | wall | CPU | order | rms / floor |")
    print("|---|---|---|---|---|---|---|---|---|")
    for minutes, size_mb, mode, m in rows:
        print(f"| {minutes:g} min | {size_mb:.0f} MB | {mode} | {m['peak_mb']:.0f} MB | {m['baseline_mb']:.0f} MB | "
              f"{m['wall_s']:.1f} s | {m['cpu_s']:.1f} s | {m['order']} | {m['rms'] / m['noise_floor']:.3f} |")


if __name__ == "__main__":
    main()
