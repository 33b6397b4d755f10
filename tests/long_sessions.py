"""Long noise recordings (minutes) of a simulated session's plant, written to WAV block by block.

Shared by the memory tests and ``benchmarks/bench_memory.py``: neither the writer nor
the reader ever holds the whole recording. The noise is made like the session's own
(``sysid.simulate.simulate_session``): white noise through the 8th-order Butterworth
low-pass at the spec's cutoff, at the session's input level, through the plant (as
second-order sections with their state carried from block to block, the pure delay as
poles at z = 0), plus the spec's input and output noise, quantised to 16 bits.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import scipy.signal

from sysid.core import lti
from sysid.io.recordings import write_wav16_blocks
from sysid.simulate import Session

BLOCK_SECONDS = 10.0


def plant_sections(session: Session) -> tuple[np.ndarray, int]:
    """The session's plant as second-order sections and a delay in samples.

    Poles and invariant zeros from the state space (never through the polynomial, which
    loses the lightly damped modes), the gain matched to the response at 1 kHz. Sections
    from ``zpk2sos`` are biproper, so the relative degree joins the pure delay.
    """
    plant = session.plant
    poles = np.linalg.eigvals(plant.A)
    zeros = lti.invariant_zeros(plant.A, plant.B, plant.C, plant.D)
    z0 = np.exp(2j * np.pi * 1000.0 / plant.fs)
    gain = plant.frequency_response([1000.0])[0] * z0 ** plant.delay * np.prod(z0 - poles) / np.prod(z0 - zeros)
    return scipy.signal.zpk2sos(zeros, poles, gain.real), plant.delay + poles.size - zeros.size


def noise_blocks(session: Session, seconds: float, seed: int = 0, block_seconds: float = BLOCK_SECONDS):
    """(u, y) blocks of a noise recording of ``seconds`` (full-scale units, before quantisation)."""
    spec = session.spec
    rng = np.random.default_rng(seed)
    lowpass = scipy.signal.butter(8, spec.noise_cutoff, fs=spec.fs, output="sos")
    plant, delay = plant_sections(session)
    # Unit-variance white noise through the low-pass has this rms; the session scales it to noise_input_rms.
    level = session.truth["noise_input_rms"] / np.sqrt(np.sum(scipy.signal.sosfilt(lowpass, np.r_[1.0, np.zeros(4095)]) ** 2))
    zi_low = np.zeros((lowpass.shape[0], 2))
    zi_plant = np.zeros((plant.shape[0], 2))
    pending = np.zeros(delay)  # the ear signal's last samples, heard in the next block
    total = int(round(seconds * spec.fs))
    step = int(round(block_seconds * spec.fs))
    for start in range(0, total, step):
        n = min(step, total - start)
        clean, zi_low = scipy.signal.sosfilt(lowpass, level * rng.standard_normal(n), zi=zi_low)
        ear, zi_plant = scipy.signal.sosfilt(plant, clean, zi=zi_plant)
        ear = np.concatenate((pending, ear))
        ear, pending = ear[:n], ear[n:]
        yield (clean + spec.input_noise * rng.standard_normal(n), ear + spec.output_noise * rng.standard_normal(n))


def write_long_noise(path, session: Session, seconds: float, seed: int = 0) -> Path:
    """Write a 16-bit stereo noise recording of ``seconds`` of the session's plant to ``path``."""
    write_wav16_blocks(path, noise_blocks(session, seconds, seed), session.spec.fs)
    return Path(path)


# Runs in a fresh interpreter so that its peak resident memory (ru_maxrss) is identify's alone.
_CHILD = r"""
import json, resource, sys, time
job = json.loads(sys.argv[1])
from sysid.identify import IdentificationOptions, identify
from sysid.io.recordings import load_recording, open_recording
baseline = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
wall, cpu = time.perf_counter(), time.process_time()
noise = (open_recording if job["streamed"] else load_recording)(job["noise"])
sweeps = [load_recording(p) for p in job["sweeps"]]
options = IdentificationOptions(**{k: tuple(v) if isinstance(v, list) else v for k, v in job["options"].items()})
result = identify(noise, sweeps, job["path"], options)
print(json.dumps({"peak_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, "baseline_mb": baseline / 1024,
                  "wall_s": time.perf_counter() - wall, "cpu_s": time.process_time() - cpu,
                  "order": result.model.order, "delay": result.model.delay, "rms": result.model.identification["rms"],
                  "noise_floor": result.noise_floor, "A": result.model.A.tolist(), "B": result.model.B.tolist(),
                  "C": result.model.C.tolist(), "D": result.model.D.tolist()}))
"""


def measure_identify(noise, sweeps, path: str, streamed: bool, options: dict, timeout: float = 1800.0) -> dict:
    """Identify in a child process: its peak resident memory (MB), wall and CPU seconds, and the model.

    ``streamed`` opens the noise recording with ``open_recording`` (read in blocks), else
    ``load_recording`` (in memory). ``options`` are ``IdentificationOptions`` fields. The
    child imports this source tree (PYTHONPATH), as the tests do.
    """
    import json
    import os
    import subprocess
    import sys

    job = {"noise": str(noise), "sweeps": [str(s) for s in sweeps], "path": path, "streamed": streamed,
           "options": {k: list(v) if isinstance(v, tuple) else v for k, v in options.items()}}
    root = str(Path(__file__).resolve().parent.parent)
    env = dict(os.environ, PYTHONPATH=os.pathsep.join(filter(None, [root, os.environ.get("PYTHONPATH")])))
    done = subprocess.run([sys.executable, "-c", _CHILD, json.dumps(job)], capture_output=True, text=True, env=env,
                          timeout=timeout, check=False)
    if done.returncode != 0:
        raise RuntimeError(f"identify in a child process failed:\n{done.stderr[-3000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])
