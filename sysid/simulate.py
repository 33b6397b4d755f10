"""Synthetic recording sessions like the seed's experiment, with a known true plant.

A session is one low-passed white-noise recording (identification; its first
``transient_s`` seconds are the filter's start-up) and two identical swept sines
20 Hz - 4 kHz with silence around them (validation), 44.1 kHz stereo, sensor noise
on both channels and 16-bit quantisation (``SessionSpec.fs`` and ``bits`` change the rate
and the sample format: 24 or 32-bit PCM, or float). The true plant is a seed appendix-A model
(or any Model). Levels are set so the ear channel peaks at ``peak_level`` of full
scale: nothing clips.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import scipy.interpolate
import scipy.signal

from . import effects as registry
from .core.effect_spec import EffectSpec, ParameterSpec, parse_effect
from .core.errors import HelmetAncError
from .core.files import atomic_write, atomic_write_text
from .core.measured import FirPlant, measured_response
from .core.model import Model
from .core.plants import appendix_a_model
from .core.structures import series, tf_to_statespace
from .core.thresholds import TRANSIENT_S
from .io.data_quality import clipped_samples
from .io.recordings import Recording
from .io.wav import quantise, write_wav

__all__ = ["SessionSpec", "Session", "simulate_session", "measured_session", "write_session", "sweep_signal", "TRUTH_FORMAT",
           "SIMULATED_EFFECTS", "random_effect"]

TRUTH_FORMAT = "helmet-anc/truth@1"

class _SimulatedEffects(Mapping):
    """Hidden effects of a synthetic session and their parameters, read live from the registry
    (``sysid.effects``: each effect's ``simulate_params``; typical values: effects.md)."""

    def _table(self) -> dict:
        return {e.name: e.simulate_params for e in registry.effects() if e.simulated}

    def __getitem__(self, name):
        return self._table()[name]

    def __iter__(self):
        return iter(self._table())

    def __len__(self):
        return len(self._table())


SIMULATED_EFFECTS = _SimulatedEffects()


@dataclass(frozen=True)
class SessionSpec:
    """What a synthetic session contains. Durations in s, levels in full-scale units."""

    path: str = "fb"
    seed: int = 0
    fs: float = 44100.0
    noise_duration: float = 20.0
    transient_s: float = TRANSIENT_S
    noise_cutoff: float = 5000.0
    sweep_duration: float = 5.0
    sweep_silence: float = 0.5
    sweep_f0: float = 20.0
    sweep_f1: float = 4000.0
    sweep_method: str = "logarithmic"
    peak_level: float = 0.5
    output_noise: float = 2e-4
    input_noise: float = 2e-5
    # Sample format of the recordings (sysid.io.wav.SAMPLE_FORMATS): 16, 24 or 32-bit PCM, or float.
    bits: str = "16"


@dataclass
class Session:
    """A simulated session: the three recordings (quantised) and the truth behind them."""

    spec: SessionSpec
    plant: Model | FirPlant
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



def simulate_session(spec: SessionSpec | None = None, plant: Model | FirPlant | None = None, effects=()) -> Session:
    """Simulate a session of the given spec; the plant defaults to the appendix-A model of spec.path.

    A ``FirPlant`` (a measured impulse response, ``sysid.core.measured``) is simulated by convolution, the
    hidden series factors and delay applied to its taps.

    ``effects`` are ``EffectSpec`` objects or strings such as ``"delay:23"`` (see
    ``SIMULATED_EFFECTS`` for each kind's parameters); ``truth["effects"]`` records them
    with the derived values (input-polynomial coefficients, disturbance lines, ...).
    """
    spec = spec or SessionSpec()
    if spec.path not in ("fb", "ff"):
        raise HelmetAncError(f"path must be 'fb' or 'ff'; found {spec.path!r}")
    base = plant or appendix_a_model(spec.path)
    if base.fs != spec.fs:
        raise HelmetAncError(f"plant sample rate {base.fs:g} Hz differs from the session's {spec.fs:g} Hz")
    hidden = _parse_effects(effects, spec.fs)
    plant = _effective_plant(base, hidden)
    rng = np.random.default_rng(spec.seed)
    # Effects draw from their own stream so a session without effects is unchanged.
    effect_rng = np.random.default_rng([spec.seed, 7])

    drift = hidden["clock-drift"]["ppm"] * 1e-6 if "clock-drift" in hidden else 0.0
    margin = int(np.ceil(abs(drift) * spec.noise_duration * spec.fs)) + 8
    lowpass = scipy.signal.butter(8, spec.noise_cutoff, fs=spec.fs, output="sos")
    noise_in = scipy.signal.sosfilt(lowpass, rng.standard_normal(int(round(spec.noise_duration * spec.fs))))
    noise_in /= np.std(noise_in[int(spec.transient_s * spec.fs):])
    sweep_in = sweep_signal(spec)

    # Scale each excitation so the clean ear signal of the linear plant peaks at peak_level.
    if isinstance(plant, FirPlant):
        linear = plant.linear()
    else:
        linear = Model(path=plant.path, fs=plant.fs, A=plant.A, B=plant.B, C=plant.C, D=plant.D, delay=plant.delay)
    noise_gain = spec.peak_level / np.max(np.abs(linear.simulate(noise_in)))
    sweep_gain = spec.peak_level / np.max(np.abs(linear.simulate(sweep_in)))
    noise_gain = min(noise_gain, spec.peak_level / np.max(np.abs(noise_in)))
    sweep_gain = min(sweep_gain, spec.peak_level / np.max(np.abs(sweep_in)))
    ear_peak = max(noise_gain * np.max(np.abs(linear.simulate(noise_in))), sweep_gain * np.max(np.abs(linear.simulate(sweep_in))))
    records = _effect_records(hidden, spec, noise_gain, max(sweep_gain, noise_gain * float(np.max(np.abs(noise_in)))),
                              float(ear_peak))
    if hidden.get("input-nonlinearity", {}).get("tanh"):
        # A saturating driver (sysid.effects.input_nonlinearity.saturation): levels at the sweeps' amplitude.
        from .effects.input_nonlinearity import saturation

        records["input-nonlinearity"] = saturation(hidden["input-nonlinearity"], sweep_gain)
        if isinstance(plant, FirPlant):
            raise HelmetAncError("--effect input-nonlinearity with tanh=1 needs a state-space plant")
        plant.input_nonlinearity_form = records["input-nonlinearity"]["form"]
    elif "input-nonlinearity" in hidden:
        if isinstance(plant, FirPlant):
            plant = replace(plant, input_nonlinearity=records["input-nonlinearity"]["coefficients"])
        else:
            plant.input_nonlinearity = records["input-nonlinearity"]["coefficients"]
    if hidden.get("input-nonlinearity", {}).get("prefilter_hz"):
        # A Wiener-Hammerstein driver: a coupling high-pass in front of the part that distorts
        # (sysid.core.model: the form's prefilter), the form an identity when the map is a polynomial.
        if isinstance(plant, FirPlant):
            raise HelmetAncError("--effect input-nonlinearity with prefilter_hz needs a state-space plant")
        p = hidden["input-nonlinearity"]
        prefilter = {"kind": "highpass", "order": int(p["prefilter_order"]), "corner_hz": float(p["prefilter_hz"])}
        plant.input_nonlinearity_form = {**(plant.input_nonlinearity_form or {"kind": "identity"}), "prefilter": prefilter}
        records["input-nonlinearity"]["prefilter"] = prefilter

    lengths = [noise_in.size, sweep_in.size, sweep_in.size]
    timeline = np.cumsum([0] + lengths)
    input_noise = spec.input_noise
    if "input-noise" in hidden:
        input_noise = float(np.hypot(spec.input_noise, _input_noise_rms(hidden, spec, noise_gain)))

    def record(index, u_clean):
        # The plant sees the clean input; a tail of input lets a slow ear clock read past the end.
        u_long = np.concatenate((u_clean, np.zeros(margin)))
        if index == 0:
            u_long[u_clean.size:] = noise_gain * scipy.signal.sosfilt(lowpass, effect_rng.standard_normal(margin))
        y_long = plant.simulate(u_long)
        y_clean = _hidden_output_effects(hidden, y_long, u_clean.size, timeline[index], timeline[-1], spec.fs,
                                         records, effect_rng, index)
        u = quantise(u_clean + input_noise * rng.standard_normal(u_clean.size) + _dc(hidden, 0), spec.bits)
        y = quantise(y_clean + spec.output_noise * rng.standard_normal(y_clean.size) + _dc(hidden, 1), spec.bits)
        return u, y

    u, y = record(0, noise_gain * noise_in)
    noise = _recording(u, y, spec.fs, "noise.wav")
    sweeps = []
    for k in (1, 2):
        u, y = record(k, sweep_gain * sweep_in)
        sweeps.append(_recording(u, y, spec.fs, f"sweep{k}.wav"))

    truth = {
        "format": TRUTH_FORMAT,
        "spec": {key: getattr(spec, key) for key in spec.__dataclass_fields__},
        "plant": plant.to_dict(),
        "noise_input_rms": float(noise_gain),
        "sweep_amplitude": float(sweep_gain),
        "effects": [dict(EffectSpec(kind, params).to_dict(), **records.get(kind, {})) for kind, params in hidden.items()],
    }
    if hidden:
        truth["base_plant"] = base.to_dict()
    if "clipping" in hidden:
        # What the ear channel records is the plant times the too-high preamp gain.
        gain = records["clipping"]["ear_gain"]
        if isinstance(plant, FirPlant):
            truth["plant"].update(taps=(plant.taps * gain).tolist())
        else:
            truth["plant"].update(C=(plant.C * gain).tolist(), D=(plant.D * gain).tolist())
    return Session(spec, plant, noise, sweeps, truth)


def measured_session(name: str, path: str = "fb", seed: int = 0, effects=(), **spec_overrides) -> Session:
    """A session through one of the measured responses (``sysid.core.measured.MEASURED_RESPONSES``) at its own
    sample rate; ``spec_overrides`` change the other ``SessionSpec`` fields (durations, noise levels)."""
    plant = measured_response(name, path)
    spec = SessionSpec(path=path, seed=seed, **{"fs": plant.fs, **spec_overrides})
    return simulate_session(spec, plant, effects)


def _recording(u: np.ndarray, y: np.ndarray, fs: float, name: str) -> Recording:
    """A Recording with the data-quality fields a loaded file would have."""
    clipped = tuple(clipped_samples(x).fraction for x in (u, y))
    return Recording(u, y, fs, name, clipped, (0.0, 0.0))


def _parse_effects(effects, fs: float) -> dict[str, dict]:
    hidden: dict[str, dict] = {}
    for effect in effects:
        parsed = effect if isinstance(effect, EffectSpec) else parse_effect(effect, SIMULATED_EFFECTS)
        if parsed.kind in hidden:
            raise HelmetAncError(f"--effect {parsed.kind} given twice")
        for name in ("f0_hz", "corner_hz", "frequency_hz", "prefilter_hz"):
            if name in parsed.params and parsed.params[name] >= fs / 2:
                raise HelmetAncError(f"--effect {parsed.kind}: {name} must be below fs/2 = {fs / 2:g} Hz")
        hidden[parsed.kind] = dict(parsed.params)
    return hidden


def _effective_plant(base: Model | FirPlant, hidden: dict[str, dict]) -> Model | FirPlant:
    """The base plant with the hidden linear effects in series: the delay, and every effect that is
    a factor (``Effect.factor``: resonance, high-/low-pass, a user's own)."""
    if isinstance(base, FirPlant):
        for kind, params in hidden.items():
            factor = registry.get(kind).factor
            if factor is not None:
                base = base.with_factor(*factor(params, base.fs))
        return base.delayed(hidden["delay"]["samples"]) if "delay" in hidden else base
    system = (base.A, base.B, base.C, base.D)
    for kind, params in hidden.items():
        factor = registry.get(kind).factor
        if factor is not None:
            system = series(system, tf_to_statespace(*factor(params, base.fs)))
    delay = base.delay + (hidden["delay"]["samples"] if "delay" in hidden else 0)
    A, B, C, D = system
    return Model(path=base.path, fs=base.fs, A=A, B=B, C=C, D=D, delay=delay,
                 input_nonlinearity=base.input_nonlinearity, input_nonlinearity_form=base.input_nonlinearity_form,
                 identification={"source": "simulated plant with hidden effects"})


def _effect_records(hidden: dict[str, dict], spec: SessionSpec, noise_gain: float, peak_input: float,
                    ear_peak: float) -> dict[str, dict]:
    """Derived values of the hidden effects, recorded in the truth file."""
    records: dict[str, dict] = {}
    if "input-nonlinearity" in hidden:
        # Harmonic levels hold for a sine at the session's largest input amplitude A:
        # for u = A sin, a2 u^2 puts a2 A/2 at 2f and a3 u^3 puts a3 A^2/4 at 3f (relative to A).
        p = hidden["input-nonlinearity"]
        amplitude = peak_input
        a2 = 2.0 * 10.0 ** (p["h2_db"] / 20.0) / amplitude
        # compressive=1: u - |a3| u^3, the map a hardening suspension or a saturating amplifier gives.
        a3 = (-1.0 if p.get("compressive") else 1.0) * 4.0 * 10.0 ** (p["h3_db"] / 20.0) / amplitude**2
        records["input-nonlinearity"] = {"coefficients": [1.0, float(a2), float(a3)], "reference_amplitude": float(amplitude)}
    if "periodic-disturbance" in hidden:
        p = hidden["periodic-disturbance"]
        lines = [k * p["frequency_hz"] for k in range(1, p["harmonics"] + 1) if k * p["frequency_hz"] < spec.fs / 2]
        # Harmonic k at level/k: mains hum and engine orders fall off with order.
        records["periodic-disturbance"] = {"frequencies": lines, "levels": [p["level"] / k for k in range(1, len(lines) + 1)]}
    if "input-noise" in hidden:
        records["input-noise"] = {"input_noise_rms": _input_noise_rms(hidden, spec, noise_gain)}
    if "clipping" in hidden:
        p = hidden["clipping"]
        records["clipping"] = {"ear_gain": float(p["peak"] * p["level"] / ear_peak), "level": float(p["level"])}
    return records


def _input_noise_rms(hidden: dict[str, dict], spec: SessionSpec, noise_gain: float) -> float:
    """White input-channel noise RMS (full band) giving snr_db inside the excitation's band.

    The excitation's density is about noise_gain^2 / noise_cutoff, white noise's
    2 sigma^2 / fs (both one-sided, FS^2/Hz).
    """
    snr = 10.0 ** (hidden["input-noise"]["snr_db"] / 10.0)
    return float(noise_gain * np.sqrt(spec.fs / (2.0 * spec.noise_cutoff * snr)))


def _dc(hidden: dict[str, dict], channel: int) -> float:
    p = hidden.get("dc-offset")
    return p["level"] if p is not None and p["channel"] == channel else 0.0


def _hidden_output_effects(hidden, y_long, n, start, total, fs, records, rng, index: int = 0) -> np.ndarray:
    """The ear signal of recording ``index`` (0 noise, 1 and 2 the sweeps; n samples from session sample
    ``start``) with the output-side effects."""
    if "clock-drift" in hidden:
        # The ear channel's clock runs ppm fast: it takes 1 + eps samples per input sample, so its
        # sample k is taken at input time k / (1 + eps) (a slow clock, ppm < 0, reads past the end).
        eps = hidden["clock-drift"]["ppm"] * 1e-6
        spline = scipy.interpolate.CubicSpline(np.arange(y_long.size), y_long)
        y = spline(np.arange(n) / (1.0 + eps))
    else:
        y = y_long[:n].copy()
    if "time-variation" in hidden:
        # The leak changes the gain below corner_hz linearly over the whole session.
        p = hidden["time-variation"]
        depth = 10.0 ** (p["change_db"] / 20.0) - 1.0
        if p["step"]:
            ramp = depth * float(index >= p["step"])
        else:
            ramp = depth * ((start + np.arange(n)) / total - 0.5)
        low = scipy.signal.sosfilt(scipy.signal.butter(2, p["corner_hz"], fs=fs, output="sos"), y)
        y = y + ramp * low
    if "clipping" in hidden:
        y = y * records["clipping"]["ear_gain"]
        level = records["clipping"]["level"]
        if level < 1.0:
            y = np.clip(y, -level, level)
    if "periodic-disturbance" in hidden:
        t = np.arange(n) / fs
        lines = records["periodic-disturbance"]
        for f, level in zip(lines["frequencies"], lines["levels"]):
            y = y + np.sqrt(2.0) * level * np.sin(2 * np.pi * f * t + rng.uniform(0, 2 * np.pi))
    return y


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
        atomic_write(files[key], lambda tmp, r=recording: write_wav(tmp, r.u, r.y, r.fs, session.spec.bits))
    atomic_write_text(files["truth"], json.dumps(session.truth, indent=2) + "\n")
    return files


def random_effect(kind: str, rng: np.random.Generator) -> tuple[str, str | None, float | None]:
    """A hidden effect with random parameters in effects.md's ranges: (spec for ``simulate_session``,
    the diagnosis parameter that estimates it or None, its true value in that parameter's units);
    the effect's own ``random`` (``sysid.effects``)."""
    effect = registry.get(kind)
    if effect.random is None:
        raise HelmetAncError(f"effect {kind} has no random parameters")
    return effect.random(rng)
