"""The noise to cancel: spectra at the chin reference and at the ear with ANC off.

A ``Disturbance`` holds, on a frequency grid in Hz, the one-sided power spectral
densities (FS^2/Hz) of the ear noise d (``ear_psd``) and, when there is a reference,
of the chin microphone x (``reference_psd``) and their cross spectrum
E[D X*] (``cross_psd``). Only these second-order statistics enter the designs
(Wiener filtering), so the same object comes from a recording with ANC off
(``from_recording``, Welch estimates) or from the documented default
(``default_disturbance``).

Default spectrum (``default_spectrum``): motorcycle helmet noise below 1 kHz is wind
and engine (issue 13). Wind: broadband turbulence, flat below 150 Hz and falling at
-6 dB/octave above it (a first-order shape), with a fourth-order high-pass at 20 Hz;
engine: lines at 90, 180, 270 and 360 Hz (a twin at 5400 rpm), each 10 dB above the wind
at 90 Hz and 3 dB lower per harmonic, 8 Hz wide (Lorentzian; the speed wanders). With a
feed-forward model P the chin microphone gets this spectrum and the ear gets
|P|^2 times it plus a part not coherent with the chin (other paths, the ear's own
flow noise) that sets the coherence to ``coherence`` (default 0.99, a 20 dB bound).
Outside the band the FF model is vouched for (``anc.uncertainty.stated_band``) P is an
extrapolation, so its gain there is capped at its largest gain inside the band (phase kept):
an identified FF model of random helmet 7 has a pole at z = -1 (radius 1 - 1e-9) and 6.7e6
times its in-band gain at fs/2, which made nearly all of the chin-coherent ear power sit at
fs/2 and the feed-forward design spend its filter there.

A recording and the FF model (``from_recording(..., ff_model=P)``): the ear noise not coherent
with the chin is then measured in the time domain, as the recording's residual through the model,
r = d - P_model x, and the coherent part is P_model x at any frequency (``ff_model``: ``at``
evaluates P there, its gain capped outside its band as above) plus what the residual still holds
of the chin: the path the model misses, E = w S_xr / S_xx (``model_error``, Welch), the H1
estimate shrunk where it is noise (Bendat & Piersol, "Random Data", 4th ed., sec. 9.2): with K
segments the residual's coherence with the chin, gamma^2 = |S_xr|^2 / (S_xx S_rr), reads 1 / K
where there is none, so g = (K gamma^2 - 1) / (K - 1) (at least 0) is its unbiased value and
w = K g / (K g + 1 - g) the Wiener weight of an estimate whose variance is (1 - g) / (K g) of
its power: w -> 1 where the missed path stands out, 0 where the residual is noise or the chin
silent. The ear power not coherent with the chin is the rest, S_rr - |E|^2 S_xx = S_rr (1 -
w^2 gamma^2) (``incoherent_psd``; ``residual_psd`` keeps S_rr, ``model_error_psd`` |E|^2 S_xx).
The predictions (``anc.design.predict``) use E: counted as incoherent it lost its phase, and a
filter that cancels P_model partly, leaving c, leaves |c + E|^2 S_xx, not |c|^2 + |E|^2 S_xx: the
prediction missed random pair 8/1012's 50 Hz band by 5.8 dB (a model error 27 dB down, judged
28.6 dB, predicted 22.8; with E 29.1). The ear power without control is then the recording's own
(|P_model|^2 + |E|^2 left out 2 Re(P_model E*): 0.9 dB for a model 10 % low). The design does
not (``modelled``: E back in the residual, the disturbance as the models see it): a filter is
realised from the paths' poles, and with E in its target W took on the detail of a 10 Hz Welch
estimate and lost 17-37 dB of its round-off SNR (random pairs 13 and 7: Q15 44.0 -> 26.6 and
23.3 -> -13.3 dB) for nothing at the ear (mean "both" up to 1.2 dB lower on 7 of 14 pairs, at
most 0.25 dB higher on the rest). Welch's own coherence cannot see a -40 dB incoherent floor
behind a delayed path: with 0.1 s segments a chin path 37 samples long (random helmet 1012)
reads as a 16-28 dB coherence bound, the window's bias, and its 10 Hz bins smear a mode of Q 50
at 30 Hz. The residual also holds what the model misses of the recorded path, which a filter
designed on the model cannot cancel either.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np
import scipy.signal

from sysid.core.errors import HelmetAncError
from sysid.core.model import Model

from .uncertainty import stated_band

__all__ = ["Disturbance", "default_spectrum", "default_disturbance", "from_recording", "synthesize", "vouched_response"]

DEFAULT_COHERENCE = 0.99
_WIND_CORNER_HZ = 150.0
_HIGHPASS_HZ = 20.0
_ENGINE_HZ = 90.0
_ENGINE_HARMONICS = 4
_LINE_WIDTH_HZ = 8.0


@dataclass(frozen=True)
class Disturbance:
    """Spectra of the noise to cancel on ``frequencies_hz`` (one-sided PSDs, FS^2/Hz)."""

    frequencies_hz: np.ndarray
    ear_psd: np.ndarray
    reference_psd: np.ndarray | None = None
    cross_psd: np.ndarray | None = None
    source: dict = field(default_factory=dict)
    # The ear PSD not coherent with the chin, measured directly (FS^2/Hz); None: ear - |cross|^2 / reference.
    residual_psd: np.ndarray | None = None
    # The chin-to-ear model the coherent part comes from (``from_recording`` with an FF model); None: the spectra.
    ff_model: Model | None = None
    # What the recording's chin-to-ear path has beyond ``ff_model`` (complex, on frequencies_hz) and its PSD at the
    # ear (FS^2/Hz), part of ``residual_psd`` (module docstring); None: nothing is known beyond the model.
    model_error: np.ndarray | None = None
    model_error_psd: np.ndarray | None = None

    def at(self, frequencies_hz) -> "Disturbance":
        """The same spectra linearly interpolated onto other frequencies (Hz); with an ``ff_model``, its
        coherent part P x evaluated there exactly (module docstring)."""
        f = np.asarray(frequencies_hz, dtype=float)

        def interp(values):
            if values is None:
                return None
            if np.iscomplexobj(values):
                return np.interp(f, self.frequencies_hz, values.real) + 1j * np.interp(f, self.frequencies_hz, values.imag)
            return np.interp(f, self.frequencies_hz, values)

        if self.ff_model is not None:
            reference, residual = interp(self.reference_psd), interp(self.residual_psd)
            error, error_psd = interp(self.model_error), interp(self.model_error_psd)
            P, incoherent = _vouched(self.ff_model, f), residual
            if error is not None:
                P, incoherent = P + error, residual - error_psd
            return Disturbance(f, np.abs(P) ** 2 * reference + incoherent, reference, P * reference, dict(self.source),
                               residual, self.ff_model, error, error_psd)
        return Disturbance(f, interp(self.ear_psd), interp(self.reference_psd), interp(self.cross_psd), dict(self.source),
                           interp(self.residual_psd))

    def modelled(self) -> "Disturbance":
        """The disturbance as the FF model sees it: what the recording's path has beyond the model counted as
        noise not coherent with the chin (module docstring); itself when nothing is known beyond the model."""
        if self.model_error is None:
            return self
        return replace(self, model_error=None, model_error_psd=None).at(self.frequencies_hz)

    @property
    def has_reference(self) -> bool:
        return self.reference_psd is not None and self.cross_psd is not None

    def coherent_response(self) -> np.ndarray:
        """H = E[D X*] / E[X X*]: the reference-to-ear response the data imply (P for the default)."""
        return self.cross_psd / np.maximum(self.reference_psd, 1e-300)

    def incoherent_psd(self) -> np.ndarray:
        """Ear PSD no causal or non-causal filter of x can remove: S_dd (1 - coherence^2)."""
        if not self.has_reference:
            return self.ear_psd
        if self.residual_psd is not None:
            return self.residual_psd if self.model_error_psd is None else self.residual_psd - self.model_error_psd
        coherent = np.abs(self.cross_psd) ** 2 / np.maximum(self.reference_psd, 1e-300)
        return np.maximum(self.ear_psd - coherent, 0.0)


def default_spectrum(frequencies_hz) -> np.ndarray:
    """Default wind-and-engine PSD (FS^2/Hz, about 0.05 FS RMS) at frequencies in Hz (module docstring)."""
    f = np.asarray(frequencies_hz, dtype=float)
    highpass = (f / _HIGHPASS_HZ) ** 4 / (1.0 + (f / _HIGHPASS_HZ) ** 4)
    wind = highpass / (1.0 + (f / _WIND_CORNER_HZ) ** 2)
    engine = np.zeros_like(f)
    half = _LINE_WIDTH_HZ / 2.0
    for h in range(1, _ENGINE_HARMONICS + 1):
        level = 10.0 ** ((10.0 - 3.0 * (h - 1)) / 10.0) / (1.0 + (_ENGINE_HZ / _WIND_CORNER_HZ) ** 2)
        engine += level * half**2 / ((f - h * _ENGINE_HZ) ** 2 + half**2)
    return 2.5e-6 * (wind + engine)


def _grid(fs: float) -> np.ndarray:
    return np.linspace(0.0, fs / 2.0, 8193)


def vouched_response(ff_model: Model, frequencies_hz) -> np.ndarray:
    """P at frequencies (Hz), its gain capped outside the stated band at the largest gain inside it."""
    return _vouched(ff_model, np.asarray(frequencies_hz, dtype=float))


def _vouched(ff_model: Model, frequencies_hz: np.ndarray) -> np.ndarray:
    """P at frequencies (Hz), its gain capped outside the stated band at the largest gain inside it."""
    P = ff_model.frequency_response(frequencies_hz)
    lo, hi = stated_band(ff_model)
    inside = (frequencies_hz >= lo) & (frequencies_hz <= hi)
    peak = float(np.max(np.abs(ff_model.frequency_response(np.geomspace(lo, hi, 2000)))))
    capped = P * np.minimum(1.0, peak / np.maximum(np.abs(P), 1e-300))
    return np.where(inside, P, capped)


def default_disturbance(fs: float, ff_model: Model | None = None, coherence: float = DEFAULT_COHERENCE) -> Disturbance:
    """The documented default (module docstring) at sample rate fs; with ff_model, chin and ear spectra."""
    if not 0.0 < coherence < 1.0:
        raise HelmetAncError(f"coherence must lie strictly between 0 and 1; found {coherence}")
    f = _grid(fs)
    spectrum = default_spectrum(f)
    source = {"kind": "default wind and engine spectrum", "coherence": coherence}
    if ff_model is None:
        return Disturbance(f, spectrum, source=source)
    P = _vouched(ff_model, f)
    coherent = np.abs(P) ** 2 * spectrum
    return Disturbance(f, coherent / coherence, spectrum, P * spectrum, source)


def from_recording(recording, fs_expected: float | None = None, segment_s: float = 0.1,
                   ff_model: Model | None = None) -> Disturbance:
    """Welch spectra of a recording with ANC off: input channel = chin microphone, output = ear.

    ``recording`` is a ``sysid.io.recordings.Recording`` (fields u = chin, y = ear, fs, path).
    Hann segments of ``segment_s`` seconds, half overlap. The cross spectrum is E[D X*]
    (scipy's ``csd(x, y)`` returns E[X* Y], i.e. E[Y X*] with y = ear). With ``ff_model`` (at the
    recording's rate) the residual d - P_model x after the model's start-up (five time constants of its
    slowest pole, at most a quarter of the recording) gives the incoherent part and the path the model
    misses, and the coherent part is the model's plus that (module docstring).
    """
    if fs_expected is not None and recording.fs != fs_expected:
        raise HelmetAncError(f"{recording.path}: sample rate {recording.fs:g} Hz differs from the model's "
                             f"{fs_expected:g} Hz; record at the model's rate")
    nperseg = int(round(segment_s * recording.fs))
    if recording.u.size < 4 * nperseg:
        raise HelmetAncError(f"{recording.path}: too short for a spectrum ({recording.u.size / recording.fs:.2f} s); "
                             f"record at least {4 * segment_s:g} s with ANC off")
    f, sxx = scipy.signal.welch(recording.u, recording.fs, nperseg=nperseg)
    _, syy = scipy.signal.welch(recording.y, recording.fs, nperseg=nperseg)
    _, sxy = scipy.signal.csd(recording.u, recording.y, recording.fs, nperseg=nperseg)
    source = {"kind": "recording with ANC off", "file": str(recording.path)}
    if ff_model is None:
        return Disturbance(f, syy, sxx, sxy, source)
    if ff_model.fs != recording.fs:
        raise HelmetAncError(f"{recording.path}: sample rate {recording.fs:g} Hz differs from the FF model's "
                             f"{ff_model.fs:g} Hz; record at the model's rate")
    residual = np.asarray(recording.y, dtype=float) - ff_model.simulate(np.asarray(recording.u, dtype=float))
    start = min(_settling_samples(ff_model), recording.u.size // 4)
    srr, error, error_psd = _model_error(np.asarray(recording.u, dtype=float)[start:], residual[start:],
                                         recording.fs, min(nperseg, residual.size - start), stated_band(ff_model))
    source["coherent part"] = ("the FF model and the chin-coherent part of the residual through it; incoherent part: "
                               "the rest of that residual")
    return Disturbance(f, syy, sxx, sxy, source, srr, ff_model, error, error_psd).at(f)


def _model_error(x: np.ndarray, residual: np.ndarray, fs: float, nperseg: int,
                 band_hz: tuple[float, float]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(S_rr, E, |E|^2 S_xx) of the residual r through the FF model (module docstring), E = w S_xr / S_xx, on the
    Welch grid of ``nperseg`` samples (Hann, half overlap). Outside ``band_hz``, where the model is vouched for
    (beyond it an extrapolation, capped in ``at``), E is 0 and r all incoherent: there the residual holds the
    model's own extrapolation, which E would put back uncapped."""
    f, sxx = scipy.signal.welch(x, fs, nperseg=nperseg)
    _, srr = scipy.signal.welch(residual, fs, nperseg=nperseg)
    _, sxr = scipy.signal.csd(x, residual, fs, nperseg=nperseg)
    segments = max(1 + (x.size - nperseg) // (nperseg // 2), 2)
    power = sxx * srr
    tiny = 1e-300 + 1e-24 * float(np.max(power, initial=0.0))
    coherence = np.minimum(np.divide(np.abs(sxr) ** 2, power, out=np.zeros_like(power), where=power > tiny), 1.0)
    unbiased = np.maximum(segments * coherence - 1.0, 0.0) / (segments - 1.0)
    weight = segments * unbiased / (segments * unbiased + 1.0 - unbiased)
    weight = np.where((f >= band_hz[0]) & (f <= band_hz[1]), weight, 0.0)
    error = np.divide(weight * sxr, sxx, out=np.zeros_like(sxr), where=power > tiny)
    return srr, error, srr * weight ** 2 * coherence


def _settling_samples(model: Model) -> int:
    """Five time constants of the model's slowest pole plus its delay (samples)."""
    radius = model.spectral_radius if model.order else 0.0
    tau = 1.0 / max(-np.log(min(radius, 1.0 - 1e-12)), 1e-12) if radius > 0.0 else 0.0
    return int(np.ceil(5.0 * tau)) + model.delay


def _shaped_noise(psd: np.ndarray, frequencies_hz: np.ndarray, n: int, fs: float, rng: np.random.Generator) -> np.ndarray:
    """White Gaussian noise shaped in the frequency domain to the one-sided PSD psd (FS^2/Hz)."""
    spectrum = np.fft.rfft(rng.standard_normal(n))
    f = np.fft.rfftfreq(n, 1.0 / fs)
    # Unit-variance white noise has one-sided PSD 2 / fs.
    gain = np.sqrt(np.maximum(np.interp(f, frequencies_hz, psd), 0.0) * fs / 2.0)
    return np.fft.irfft(spectrum * gain, n)


def synthesize(disturbance: Disturbance, n: int, fs: float, seed: int) -> tuple[np.ndarray | None, np.ndarray]:
    """Time signals (x, u) of n samples for a simulation: x the chin reference (None without one),
    u the ear noise not coherent with x (all of d without a reference). The caller forms
    d = P x + u with its own (true) P. Circular shaping of seeded white noise."""
    rng = np.random.default_rng(seed)
    f = disturbance.frequencies_hz
    if not disturbance.has_reference:
        return None, _shaped_noise(disturbance.ear_psd, f, n, fs, rng)
    x = _shaped_noise(disturbance.reference_psd, f, n, fs, rng)
    u = _shaped_noise(disturbance.incoherent_psd(), f, n, fs, rng)
    return x, u
