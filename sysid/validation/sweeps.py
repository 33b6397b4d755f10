"""Validation error of a model on the swept-sine recordings, and their noise floor.

``rms`` (design.md, "Compare"): the RMS of measured minus predicted ear signal
inside the validation band (default 20 Hz - 4 kHz, the sweeps' band), over each
whole sweep after its first 50 ms, in full-scale units. By Parseval, for a segment
of L samples with DFT E_k, the band-limited error energy is
    sum_t e_band(t)^2 = (2 / L) sum_{k in band} |E_k|^2,
and over both sweeps rms = sqrt((energy_1 + energy_2) / (L_1 + L_2)). This is the
seed's RMS (section 3.3.2) with the missing square restored.

The grid search evaluates thousands of candidate models on tens of thousands of
sweep bins. ``CompressedValidation`` makes that cheap without giving up the
definition: within narrow cells (2 Hz by default) a model's response is taken as
linear in frequency, so the error energy is a quadratic form in the response at
the cell edges whose coefficients (moments of |U|^2, conj(Y) U, |Y|^2) are summed
once. The approximation error is of order (cell width / mode bandwidth)^2; the
chosen candidates are re-evaluated exactly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.fft

from ..core.errors import IdentificationError
from ..core.thresholds import REPEAT_CORRELATION, REPEAT_FLOOR_INFLATION, SKIP_S, VALIDATION_BAND
from ..io.lines import find_lines, fit_sinusoids, without_lines
from ..io.recordings import Recording

__all__ = ["SweepSpectrum", "sweep_spectrum", "band_energy", "rms_from_responses", "CompressedValidation",
           "noise_floor", "repeat_lines", "without_repeat_lines", "repeat_lag", "check_repeats", "repeat_check", "RepeatCheck", "excitation_seconds", "band_rms", "simulated_rms", "rfft_pair", "validation_start",
           "aligned_ears", "SKIP_S", "VALIDATION_BAND"]

# ``SKIP_S`` and ``VALIDATION_BAND`` are defined in ``sysid.core.thresholds`` with the other bands, and
# importable from here as before.

# Above this largest prime factor of a length numpy's DFT is slow (long generic passes or Bluestein's
# algorithm), and one complex DFT costs about what one real one does (``rfft_pair``).
_SLOW_PRIME = 600


@dataclass
class SweepSpectrum:
    """DFT bins of one sweep recording (after its first ``SKIP_S``) inside the band."""

    frequencies: np.ndarray
    U: np.ndarray
    Y: np.ndarray
    length: int
    fs: float


def _largest_prime_factor(n: int) -> int:
    largest, p = 1, 2
    while p * p <= n:
        while n % p == 0:
            n //= p
            largest = p
        p += 1
    return max(largest, n)


def rfft_pair(u: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(rfft(u), rfft(y)) of two real signals of one length.

    A length with a large prime factor (a sweep shortened by a delay of d samples: 477561 =
    3 7 22741, 438738 = 2 3 83 881) is slow in numpy's DFT, and there one complex DFT of u + j y
    costs about what one real DFT does: U_k = (Z_k + conj(Z_{N-k})) / 2, Y_k = (Z_k - conj(Z_{N-k})) / 2j
    halves the time (0.29 -> 0.16 s of CPU for 9 s at 48 kHz). That complex DFT is scipy's, whose
    Bluestein path is faster on such lengths (429556 = 2^2 17 6317: 112 -> 61 ms a pair; 477561:
    135 -> 82 ms; the bins agree to 1e-15 of the largest). Other lengths keep numpy's real DFTs
    (477543 = 3 11 29 499: two real DFTs 0.06 s, one complex 0.08 s).
    """
    n = u.size
    if _largest_prime_factor(n) <= _SLOW_PRIME:
        return np.fft.rfft(u), np.fft.rfft(y)
    Z = scipy.fft.fft(u + 1j * y)
    half = Z[:n // 2 + 1]
    mirrored = np.conj(Z[-np.arange(n // 2 + 1) % n])
    return (half + mirrored) / 2, (half - mirrored) / 2j


def validation_start(sweep: Recording, skip_s: float = SKIP_S) -> int:
    """Index of a sweep's first validated sample: validation skips its first ``skip_s`` (the model
    starts from rest). IdentificationError when fewer than two samples are left after it."""
    first = int(round(skip_s * sweep.fs))
    if sweep.y.size < first + 2:
        raise IdentificationError(f"{sweep.path}: a sweep of {sweep.y.size} samples leaves nothing to validate "
                                  f"after its first {skip_s * 1000:g} ms; give the whole recorded sweep")
    return first


def sweep_spectrum(sweep: Recording, band=VALIDATION_BAND, skip_s: float = SKIP_S) -> SweepSpectrum:
    first = validation_start(sweep, skip_s)
    u, y = sweep.u[first:], sweep.y[first:]
    f = np.fft.rfftfreq(u.size, 1 / sweep.fs)
    inside = (f >= band[0]) & (f <= band[1])
    U, Y = rfft_pair(u, y)
    return SweepSpectrum(f[inside], U[inside], Y[inside], u.size, sweep.fs)


def band_energy(error_bins: np.ndarray, length: int) -> float:
    """sum_t e_band(t)^2 from the positive-frequency DFT bins inside the band (Parseval)."""
    return 2.0 / length * float(np.sum(np.abs(error_bins) ** 2))


def band_rms(x: np.ndarray, fs: float, band=VALIDATION_BAND) -> float:
    """RMS of x after band-limiting to band (Hz), via Parseval."""
    X = np.fft.rfft(x)
    f = np.fft.rfftfreq(x.size, 1 / fs)
    inside = (f >= band[0]) & (f <= band[1])
    return float(np.sqrt(band_energy(X[inside], x.size) / x.size))


def rms_from_responses(spectra: list[SweepSpectrum], responses: list[np.ndarray]) -> float:
    """Exact frequency-domain validation rms for model responses at each sweep's bins."""
    energy = sum(band_energy(s.Y - g * s.U, s.length) for s, g in zip(spectra, responses))
    return float(np.sqrt(energy / sum(s.length for s in spectra)))


class CompressedValidation:
    """Validation rms of many models from their responses on a coarse frequency grid."""

    def __init__(self, spectra: list[SweepSpectrum], cell_hz: float = 2.0):
        f_lo = min(s.frequencies[0] for s in spectra)
        f_hi = max(s.frequencies[-1] for s in spectra)
        cells = max(1, int(np.ceil((f_hi - f_lo) / cell_hz)))
        self.frequencies = np.linspace(f_lo, f_hi, cells + 1)
        self.fs = spectra[0].fs
        self.total_length = sum(s.length for s in spectra)
        a0 = np.zeros(cells)
        a1 = np.zeros(cells)
        a2 = np.zeros(cells)
        p0 = np.zeros(cells, complex)
        p1 = np.zeros(cells, complex)
        syy = 0.0
        step = (f_hi - f_lo) / cells
        for s in spectra:
            weight = 2.0 / s.length
            position = (s.frequencies - f_lo) / step
            cell = np.clip(position.astype(int), 0, cells - 1)
            t = position - cell
            uu = weight * np.abs(s.U) ** 2
            yu = weight * np.conj(s.Y) * s.U
            a0 += np.bincount(cell, uu * (1 - t) ** 2, cells)
            a1 += np.bincount(cell, uu * (1 - t) * t, cells)
            a2 += np.bincount(cell, uu * t**2, cells)
            p0 += np.bincount(cell, (yu * (1 - t)).real, cells) + 1j * np.bincount(cell, (yu * (1 - t)).imag, cells)
            p1 += np.bincount(cell, (yu * t).real, cells) + 1j * np.bincount(cell, (yu * t).imag, cells)
            syy += weight * float(np.sum(np.abs(s.Y) ** 2))
        self._moments = (a0, a1, a2, p0, p1, syy)

    def rms(self, responses: np.ndarray) -> np.ndarray:
        """rms for each row of responses (models x len(self.frequencies))."""
        g = np.atleast_2d(responses)
        ga, gb = g[:, :-1], g[:, 1:]
        a0, a1, a2, p0, p1, syy = self._moments
        cross = (ga * p0 + gb * p1).sum(axis=1).real
        power = (np.abs(ga) ** 2 * a0 + 2 * (ga * np.conj(gb)).real * a1 + np.abs(gb) ** 2 * a2).sum(axis=1)
        energy = np.maximum(syy - 2 * cross + power, 0.0)
        return np.sqrt(energy / self.total_length)


def _align(reference: np.ndarray, other: np.ndarray) -> int:
    """Lag (samples) that best aligns other to reference, by FFT cross-correlation."""
    n = reference.size + other.size
    size = 1 << (n - 1).bit_length()
    correlation = np.fft.irfft(np.fft.rfft(reference, size) * np.conj(np.fft.rfft(other, size)), size)
    lag = int(np.argmax(np.abs(correlation)))
    return lag if lag < size // 2 else lag - size


def repeat_lag(sweep1: Recording, sweep2: Recording) -> int:
    """Lag (samples) that aligns the second repeat to the first, on their input channels."""
    return _align(sweep1.u, sweep2.u)


def aligned_ears(sweep1: Recording, sweep2: Recording, skip_s: float, lag: int | None) -> tuple[np.ndarray, np.ndarray]:
    """The two ear signals over their overlap after alignment (``repeat_lag``, or the ``lag`` given),
    without the first ``skip_s`` seconds; empty when they do not overlap past it."""
    lag = repeat_lag(sweep1, sweep2) if lag is None else lag
    y1, y2 = (sweep1.y[lag:], sweep2.y) if lag >= 0 else (sweep1.y, sweep2.y[-lag:])
    first = int(round(skip_s * sweep1.fs))
    n = max(min(y1.size, y2.size), first)
    return y1[first:n], y2[first:n]


def _difference(sweep1: Recording, sweep2: Recording, skip_s: float, lag: int | None) -> tuple[np.ndarray, np.ndarray]:
    """y1 - y2 of ``aligned_ears`` and the first sweep's input over the same samples."""
    lag = repeat_lag(sweep1, sweep2) if lag is None else lag
    y1, y2 = aligned_ears(sweep1, sweep2, skip_s, lag)
    start = max(lag, 0) + int(round(skip_s * sweep1.fs))
    return y1 - y2, sweep1.u[start:start + y1.size]


def repeat_lines(sweep1: Recording, sweep2: Recording, band=VALIDATION_BAND, skip_s: float = SKIP_S,
                 lag: int | None = None) -> list[float]:
    """Frequencies (Hz) of the spectral lines in the difference of two repeats that the input lacks
    (``lines.find_lines``): a hum or engine order not phase-locked to the sweeps, which the
    difference keeps while it cancels the sweep's response. Empty on a clean session."""
    difference, u = _difference(sweep1, sweep2, skip_s, lag)
    if difference.size < 2:
        return []
    return [line[0] for line in find_lines(difference, u, sweep1.fs, band)]


def without_repeat_lines(sweep1: Recording, sweep2: Recording, band=VALIDATION_BAND, skip_s: float = SKIP_S,
                         lag: int | None = None, known=()) -> tuple[list[Recording], list[float]]:
    """The two sweeps with the lines of ``repeat_lines`` and the ``known`` ones (Hz; e.g. those of
    the session's noise recording, ``lines.undriven_lines``) fitted beside each sweep's response and
    taken out of its ear signal (``lines.without_lines``), and those lines' frequencies (Hz). The
    recordings themselves when there are none. A known line within 1 Hz of one of the repeats' is
    that one, at the repeats' frequency: where the response is far above the line (random helmet
    101 FB at 50 Hz) the noise recording places it less precisely (49.973 Hz against 50.000 from the
    repeats, whose difference holds no response; 1.22x against 1.07x of the floor after identify).

    A weak line the 2 s repeats do not show is found in a longer noise recording (random helmet 102
    FF, an engine order at 41.7 Hz, 5.4e-4 FS, beside 9.2e-4 FS of sensor noise: its third harmonic,
    1.8e-4 FS, a quarter of the floor's power, 23 times its neighbourhood in the repeats' difference
    against 291 times in 5 s of the noise recording).

    A line the input lacks is neither the plant's response nor output noise: left in, it inflates
    the noise floor (the difference of the repeats keeps it) and every model's validation rms alike
    (random helmet 101 FB with a 50 Hz hum at 1.16e-3 FS: floor 8.4e-4 FS against 7.2e-5 without),
    and the order search stops at a ratio that hides a core 180-360x off at 32-63 Hz.
    """
    repeats = [float(f) for f in repeat_lines(sweep1, sweep2, band, skip_s, lag)]
    lines = sorted(repeats + [float(f) for f in known if all(abs(f - g) > 1.0 for g in repeats)])
    return [without_lines(s, lines) for s in (sweep1, sweep2)], lines


def noise_floor(sweep1: Recording, sweep2: Recording, band=VALIDATION_BAND, skip_s: float = SKIP_S,
                lag: int | None = None) -> float:
    """Output-noise RMS in band (FS) from two recordings of the same excitation.

    The repeats are aligned on their input channels (``repeat_lag``, or the ``lag`` given);
    the ear signals' difference then holds the output noise of both, so the floor is
    rms(y1 - y2) / sqrt(2). Spectral lines of the difference that the input lacks (a hum or
    engine order not phase-locked to the sweeps, ``repeat_lines``) are fitted and taken out of
    it first: deterministic, they are no output noise, and a model cannot be asked to reach
    them. The floor excludes nothing else (4 of the difference's samples' degrees of freedom per
    line, a negligible share of its noise). ``identify`` gives it the sweeps with the session's
    lines already taken out (``without_repeat_lines``: also those found only in the noise
    recording), so the ``noise_floor`` a model stores is the output noise without any line the
    input lacks; on a session without such lines it is the plain repeat difference, as before.
    """
    difference, u = _difference(sweep1, sweep2, skip_s, lag)
    if difference.size < 2:
        raise IdentificationError(f"{sweep1.path}, {sweep2.path}: sweeps do not overlap enough to estimate the noise floor")
    lines = [line[0] for line in find_lines(difference, u, sweep1.fs, band)]
    difference = difference - fit_sinusoids(difference, lines, sweep1.fs)
    return band_rms(difference, sweep1.fs, band) / np.sqrt(2.0)


def _correlation(x1: np.ndarray, x2: np.ndarray, fs: float, band, lag: int) -> float:
    """Normalised cross-correlation of x1 and x2 in ``band`` (Hz), x1 advanced by ``lag`` samples, over
    their whole energies (1 for one signal twice, less for noise and for the parts they do not share)."""
    def in_band(x):
        X = np.fft.rfft(x)
        f = np.fft.rfftfreq(x.size, 1 / fs)
        X[(f < band[0]) | (f > band[1])] = 0.0
        return np.fft.irfft(X, x.size)

    v1, v2 = in_band(x1), in_band(x2)
    b1, b2 = (v1[lag:], v2) if lag >= 0 else (v1, v2[-lag:])
    m = min(b1.size, b2.size)
    energy = float(np.dot(v1, v1)) * float(np.dot(v2, v2))
    return float(np.dot(b1[:m], b2[:m]) / np.sqrt(energy)) if energy > 0 else 0.0


def excitation_seconds(sweep: Recording) -> float:
    """Length (s) of a sweep recording's excitation: from the first to the last 10 ms window whose
    input power is above a tenth of the largest window's (the silence around the sweep left out)."""
    window = max(1, int(round(0.01 * sweep.fs)))
    if sweep.u.size < window:
        return sweep.u.size / sweep.fs
    power = np.convolve(sweep.u**2, np.ones(window) / window, mode="valid")
    above = np.flatnonzero(power > 0.1 * np.max(power))
    return (above[-1] - above[0] + window) / sweep.fs if above.size else 0.0


@dataclass(frozen=True)
class RepeatCheck:
    """How well two sweep recordings repeat one excitation (``repeat_check``).

    ``correlation``: the larger normalised cross-correlation, in the validation band at the aligning
    lag, of their inputs and of their ears (1 for one excitation recorded twice, less by the channels'
    own noise); ``level_db``: the
    second input's level over the first's on the samples they share after alignment (dB);
    ``lengths_s``: each excitation's length (``excitation_seconds``); ``floor_inflation``: the
    repeats' ear difference over that difference with the second ear scaled to the first's
    input level (band rms ratio; 1 when the levels agree).
    """

    correlation: float
    level_db: float
    lengths_s: tuple[float, float]
    floor_inflation: float

    @property
    def repeats(self) -> bool:
        """The inputs share more than they differ, and a level difference would not make up most of the floor."""
        return self.correlation >= REPEAT_CORRELATION and self.floor_inflation <= REPEAT_FLOOR_INFLATION


def repeat_check(sweep1: Recording, sweep2: Recording, skip_s: float = SKIP_S, lag: int | None = None,
                 band=VALIDATION_BAND) -> RepeatCheck:
    """The figures of ``RepeatCheck`` for two sweep recordings aligned by ``lag`` (``repeat_lag`` by default)."""
    lag = repeat_lag(sweep1, sweep2) if lag is None else lag
    # One excitation recorded twice correlates in the band the models are judged in, on the input channel or, where
    # that channel is itself a noisy microphone (the input-noise effect: inputs at 0 dB SNR correlate 0.42), on the
    # ears; a sweep of another length or kind decorrelates both (2.0 and 2.05 s log sweeps: -0.31).
    correlation = max(_correlation(sweep1.u, sweep2.u, sweep1.fs, band, lag),
                      _correlation(sweep1.y, sweep2.y, sweep1.fs, band, lag))
    u1, u2 = (sweep1.u[lag:], sweep2.u) if lag >= 0 else (sweep1.u, sweep2.u[-lag:])
    n = min(u1.size, u2.size)
    shared1, shared2 = float(np.dot(u1[:n], u1[:n])), float(np.dot(u2[:n], u2[:n]))
    level_db = 10 * np.log10(shared2 / shared1) if shared1 > 0 and shared2 > 0 else float("-inf")
    inflation = 1.0
    y1, y2 = aligned_ears(sweep1, sweep2, skip_s, lag)
    if y1.size >= 2 and np.isfinite(level_db):
        # A level difference puts (1 - g) of the ear signal into the repeats' difference: the floor
        # from it is mostly that, not noise, when scaling the second ear to the first's level
        # lowers the difference beyond what the noise explains.
        plain = band_rms(y1 - y2, sweep1.fs, band)
        scaled = band_rms(y1 - 10 ** (-level_db / 20) * y2, sweep1.fs, band)
        inflation = plain / scaled if scaled > 0 else (np.inf if plain > 0 else 1.0)
    return RepeatCheck(correlation, float(level_db), (excitation_seconds(sweep1), excitation_seconds(sweep2)),
                       float(inflation))


def check_repeats(sweep1: Recording, sweep2: Recording, skip_s: float = SKIP_S, lag: int | None = None) -> RepeatCheck:
    """IdentificationError when the two sweeps cannot give a noise floor; else their ``RepeatCheck``.

    The floor is the difference of two repeats of one excitation (``noise_floor``), a shift
    between them aligned (``repeat_lag``). Refused, because no other estimate of the output
    noise exists in the sweeps and a floor from anything else is meaningless (a model whose
    order search stopped on it is written with a wrong verdict):

    * sample-identical ear signals (the same file given twice, or a copy): the difference is
      exactly zero, every error ratio infinite;
    * inputs that are not one excitation (sweeps of different lengths or kinds): aligned at
      their best lag their inputs and their ears correlate less than ``REPEAT_CORRELATION`` in the
      validation band (two log sweeps of 2.0 and 2.05 s: -0.31; a repeat with an input microphone at
      0 dB SNR: inputs 0.42, ears above 0.99);
    * one excitation at two levels, when the level difference makes up most of the ears'
      difference (``REPEAT_FLOOR_INFLATION``): a sweep at half level put 10x the noise into it
      (a floor 0.01x what a model is judged against). A change of the path itself between
      the repeats (time variation, which ``diagnose`` names) leaves the inputs alike and
      is not refused here.
    The message gives the level difference (dB) and the excitations' lengths (s).
    """
    y1, y2 = aligned_ears(sweep1, sweep2, skip_s, lag)
    if y1.size >= 2 and np.array_equal(y1, y2):
        raise IdentificationError(f"{sweep1.path}, {sweep2.path}: the two sweeps are sample-identical (the same "
                                  "recording twice?), so the noise floor is unknown; give two separate recordings")
    check = repeat_check(sweep1, sweep2, skip_s, lag)
    if not check.repeats:
        first, second = check.lengths_s
        if check.correlation < REPEAT_CORRELATION:
            what = (f"their inputs are not one excitation (excitations of {first:.2f} s and {second:.2f} s, "
                    f"correlation {check.correlation:.2f} at their best alignment, input level {check.level_db:+.1f} dB)")
        else:
            what = (f"the second input is {check.level_db:+.1f} dB from the first (excitations of {first:.2f} s and "
                    f"{second:.2f} s), which puts {check.floor_inflation:.1f}x the noise into their difference")
        raise IdentificationError(f"{sweep1.path}, {sweep2.path}: the sweeps do not repeat each other: {what}; the "
                                  "noise floor comes from the difference of two repeats, so record the same sweep "
                                  "twice at one level")
    return check


def simulated_rms(model, sweeps: list[Recording], band=VALIDATION_BAND, skip_s: float = SKIP_S) -> float:
    """The model's validation rms by time-domain simulation of each whole sweep from rest."""
    errors = [(sweep.y - model.simulate(sweep.u))[int(round(skip_s * sweep.fs)):] for sweep in sweeps]
    # Two repeats of one length: their DFTs as a pair (``rfft_pair``).
    if len(errors) == 2 and errors[0].size == errors[1].size:
        spectra = rfft_pair(*errors)
    else:
        spectra = [np.fft.rfft(error) for error in errors]
    energy = 0.0
    for sweep, error, E in zip(sweeps, errors, spectra):
        f = np.fft.rfftfreq(error.size, 1 / sweep.fs)
        energy += band_energy(E[(f >= band[0]) & (f <= band[1])], error.size)
    return float(np.sqrt(energy / sum(error.size for error in errors)))
