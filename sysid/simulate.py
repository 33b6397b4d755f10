"""Synthetic recording sessions like the seed's experiment, with a known true plant.

A session is one low-passed white-noise recording (identification; its first
``transient_s`` seconds are the filter's start-up) and two identical swept sines
20 Hz - 4 kHz with silence around them (validation), 44.1 kHz stereo, sensor noise
on both channels and 16-bit quantisation. The true plant is a seed appendix-A model
(or any Model). Levels are set so the ear channel peaks at ``peak_level`` of full
scale: nothing clips.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import scipy.signal

from .errors import HelmetAncError
from .model import Model, atomic_write_text
from .plants import appendix_a_model
from .recordings import Recording, write_wav16

__all__ = ["SessionSpec", "Session", "simulate_session", "write_session", "sweep_signal", "TRUTH_FORMAT"]

TRUTH_FORMAT = "helmet-anc/truth@1"


@dataclass(frozen=True)
class SessionSpec:
    """What a synthetic session contains. Durations in s, levels in full-scale units."""

    path: str = "fb"
    seed: int = 0
    fs: float = 44100.0
    noise_duration: float = 20.0
    transient_s: float = 3.0
    noise_cutoff: float = 5000.0
    sweep_duration: float = 5.0
    sweep_silence: float = 0.5
    sweep_f0: float = 20.0
    sweep_f1: float = 4000.0
    sweep_method: str = "logarithmic"
    peak_level: float = 0.5
    output_noise: float = 2e-4
    input_noise: float = 2e-5


@dataclass
class Session:
    """A simulated session: the three recordings (quantised) and the truth behind them."""

    spec: SessionSpec
    plant: Model
    noise: Recording
    sweeps: list[Recording]
    truth: dict = field(default_factory=dict)


def sweep_signal(spec: SessionSpec) -> np.ndarray:
    """Unit-amplitude swept sine with 10 ms half-Hann fades and silence on both sides."""
    n = int(round(spec.sweep_duration * spec.fs))
    t = np.arange(n) / spec.fs
    sweep = scipy.signal.chirp(t, spec.sweep_f0, spec.sweep_duration, spec.sweep_f1, method=spec.sweep_method, phi=-90)
    fade = int(0.01 * spec.fs)
    ramp = 0.5 - 0.5 * np.cos(np.pi * np.arange(fade) / fade)
    sweep[:fade] *= ramp
    sweep[-fade:] *= ramp[::-1]
    silence = np.zeros(int(round(spec.sweep_silence * spec.fs)))
    return np.concatenate((silence, sweep, silence))


def _quantise16(x: np.ndarray) -> np.ndarray:
    return np.clip(np.round(x * 32768.0), -32768, 32767) / 32768.0


def simulate_session(spec: SessionSpec | None = None, plant: Model | None = None) -> Session:
    """Simulate a session of the given spec; the plant defaults to the appendix-A model of spec.path."""
    spec = spec or SessionSpec()
    if spec.path not in ("fb", "ff"):
        raise HelmetAncError(f"path must be 'fb' or 'ff'; found {spec.path!r}")
    plant = plant or appendix_a_model(spec.path)
    if plant.fs != spec.fs:
        raise HelmetAncError(f"plant sample rate {plant.fs:g} Hz differs from the session's {spec.fs:g} Hz")
    rng = np.random.default_rng(spec.seed)

    lowpass = scipy.signal.butter(8, spec.noise_cutoff, fs=spec.fs, output="sos")
    noise_in = scipy.signal.sosfilt(lowpass, rng.standard_normal(int(round(spec.noise_duration * spec.fs))))
    noise_in /= np.std(noise_in[int(spec.transient_s * spec.fs):])
    sweep_in = sweep_signal(spec)

    # Scale each excitation so the clean ear signal peaks at peak_level.
    noise_out = plant.simulate(noise_in)
    sweep_out = plant.simulate(sweep_in)
    noise_gain = spec.peak_level / np.max(np.abs(noise_out))
    sweep_gain = spec.peak_level / np.max(np.abs(sweep_out))
    noise_gain = min(noise_gain, spec.peak_level / np.max(np.abs(noise_in)))
    sweep_gain = min(sweep_gain, spec.peak_level / np.max(np.abs(sweep_in)))

    def record(u_clean, y_clean):
        u = _quantise16(u_clean + spec.input_noise * rng.standard_normal(u_clean.size))
        y = _quantise16(y_clean + spec.output_noise * rng.standard_normal(y_clean.size))
        return u, y

    u, y = record(noise_gain * noise_in, noise_gain * noise_out)
    noise = Recording(u, y, spec.fs, "noise.wav")
    sweeps = []
    for k in (1, 2):
        u, y = record(sweep_gain * sweep_in, sweep_gain * sweep_out)
        sweeps.append(Recording(u, y, spec.fs, f"sweep{k}.wav"))

    truth = {
        "format": TRUTH_FORMAT,
        "spec": {key: getattr(spec, key) for key in spec.__dataclass_fields__},
        "plant": plant.to_dict(),
        "noise_input_rms": float(noise_gain),
        "sweep_amplitude": float(sweep_gain),
        "effects": [],
    }
    return Session(spec, plant, noise, sweeps, truth)


def write_session(session: Session, outdir) -> dict[str, Path]:
    """Write noise.wav, sweep1.wav, sweep2.wav and truth.json into outdir (created if needed)."""
    outdir = Path(outdir)
    try:
        outdir.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise HelmetAncError(f"{outdir}: cannot create output folder ({exc.strerror})") from None
    files = {"noise": outdir / "noise.wav", "sweep1": outdir / "sweep1.wav", "sweep2": outdir / "sweep2.wav", "truth": outdir / "truth.json"}
    # Write each file beside its final name and rename, so a failure leaves no partial session file.
    recordings = {"noise": session.noise, "sweep1": session.sweeps[0], "sweep2": session.sweeps[1]}
    for key, recording in recordings.items():
        tmp = files[key].with_name(f".{files[key].name}.partial")
        try:
            write_wav16(tmp, recording.u, recording.y, recording.fs)
            tmp.replace(files[key])
        except OSError as exc:
            tmp.unlink(missing_ok=True)
            raise HelmetAncError(f"{files[key]}: cannot write ({exc.strerror})") from None
    atomic_write_text(files["truth"], json.dumps(session.truth, indent=2) + "\n")
    return files
