"""Spectral lines in an ear signal that the input does not drive (mains hum, engine orders).

A deterministic line is neither the plant's response nor output noise: identification,
the noise floor, the delay search and the periodic-disturbance finding all take it out the
same way, with the functions here.

- ``find_lines``: the lines of x that u lacks. x is Hann-windowed and transformed in one
  piece; a line is a local maximum more than ``LINE_RATIO`` times the median of its
  ``NEIGHBOURHOOD_HZ`` neighbourhood (for noise the periodogram is exponentially
  distributed, so chance exceedances are of order exp(-LINE_RATIO ln 2)) where u's own
  spectrum is not a line. Frequencies are refined by parabolic interpolation of the log
  spectrum around the peak (for a Hann window the bias is below a tenth of a bin).
- ``driven``: which of those peaks the input explains after all. In a model's residual, a
  lightly damped mode the model lacks or misplaces rings like a line (a peak far above its
  neighbourhood where the input's spectrum is flat) but is the input's response. In the DFT of
  the whole residual, the bins within ``DRIVEN_WINDOW`` of the peak are fitted twice, both times
  with a transient smooth in frequency: as a response to the input locally quadratic in
  frequency, (c0 + c1 k + c2 k^2) U_k (the local polynomial method below), and as a sinusoid of
  constant amplitude (its Dirichlet kernel); the peak is driven when the response fits better.
  A line's bins are its kernel and the input's explain a chance share of them (6 of 42 real
  equations); a mode's bins follow U_k times its smooth resonance, which no single sinusoid
  follows. Welch coherence was tried and dropped: its segments must outlast the mode's ringing
  (at 0.5 s, 2 Hz, a 130 Hz mode of Q 100 read 0.3, at 0.25 s the 129.6 Hz mode of random helmet
  100 FB 0.42) and on a 5 s residual longer segments leave too few to average. Measured on
  modes of Q 10-300 at 30-300 Hz beside a line 0.3-20 times the noise (5 s, 131 peaks found):
  every line and every mode told apart but one mode of Q 300 at 40.7 Hz, whose 0.14 Hz
  bandwidth is below the recording's resolution of 0.2 Hz: it rings through the whole recording
  like a line, and no fit of this length tells them apart.
- ``fit_sinusoids``: least squares of x on the lines' columns (``line_regressor``).
- ``response_lines``: the lines in a recording of the plant's response, where the response
  (a sweep's passes through every line frequency; a noise input's covers them all) is far
  above the noise and a plain least-squares fit would take part of it for the line. In the
  DFT of the whole recording, the bins within ``RESPONSE_WINDOW`` of each line are modelled as
  the line's columns (their DFTs: a Dirichlet kernel, peaked at the line) plus a response
  smooth in frequency, (c0 + c1 k + c2 k^2) U_k + (t0 + t1 k) (a plant response
  locally quadratic in frequency, and the transient of a finite record, smooth in
  frequency: the local polynomial method of Pintelon, Schoukens, Vandersteen & Barbe,
  "Estimation of nonparametric noise and FRF models for multivariable systems, part I",
  Mechanical Systems and Signal Processing 24(3), 2010). The line's amplitudes come from that
  joint fit and only the line is taken out.
- ``line_search``: the lines of a whole session (the noise recording and the sweeps) in what a
  model leaves of each ear signal, where the ear signal is below ``LOUD`` of its extreme (a clipped
  stretch's misfit is broadband): the diagnosis's one line search, and the lines the clipping
  correction takes out before it looks for flat tops.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.ndimage

from ..core.thresholds import IDENTIFICATION_BAND, LINE_RATIO
from .recordings import Recording

__all__ = ["LINE_RATIO", "MAX_LINES", "NEIGHBOURHOOD_HZ", "RESPONSE_WINDOW", "DRIVEN_WINDOW", "LOUD", "find_lines",
           "driven", "undriven_lines", "line_regressor", "fit_sinusoids", "response_lines", "without_lines",
           "quiet_samples", "SessionLines", "line_search", "session_lines"]

MAX_LINES = 12
NEIGHBOURHOOD_HZ = 20.0
# response_lines: DFT bins either side of a line in its local fit (2 x 5 + 1 complex bins, 22 real equations,
# for 4 line and 10 response unknowns). Measured on random helmets 100-102 with a hum (2 s sweeps): what is
# left of the hum is 1.0-1.9x the 16-bit quantisation's share at 5 bins, up to 26x at 20 (the response is
# no longer quadratic over the window near a mode) and up to 7x at 3 (too few equations).
RESPONSE_WINDOW = 5
# driven: DFT bins either side of a peak in its two fits (at 5 s of residual, +-2 Hz).
DRIVEN_WINDOW = 10
# fit_sinusoids: samples per block of the regressor (8192 x 4 columns x 8 bytes per line: in cache).
FIT_BLOCK = 8192
# The lines are fitted on the ear samples below LOUD of the extreme: the clipped stretches sit at the
# extreme, and what the model leaves there is the clipper's error (up to tens of percent of the
# level), not the hum, which would pull the fit. Half the extreme leaves room for a hum of up to half
# the clip level.
LOUD = 0.5


def find_lines(x: np.ndarray, u: np.ndarray, fs: float, band=IDENTIFICATION_BAND, known=()) -> list[tuple[float, float, float]]:
    """(frequency Hz, ratio to neighbourhood, RMS level FS) of the lines of x that u lacks, in band (Hz).

    Lines within two bins of a frequency in ``known`` (Hz) are left out.
    """
    n = x.size
    if n < 2:
        return []
    window = np.hanning(n)
    f = np.fft.rfftfreq(n, 1 / fs)
    width = max(9, int(NEIGHBOURHOOD_HZ * n / fs) | 1)
    # Only the band and half a neighbourhood around it: the median filter is the costly step.
    lo = max(int(np.searchsorted(f, band[0])) - width, 1)
    hi = min(int(np.searchsorted(f, band[1])) + width, f.size - 1)
    if hi - lo < width:
        # Fewer bins than one neighbourhood: no background to stand out from.
        return []
    X = np.zeros(f.size)
    X[lo - 1:hi + 1] = (np.abs(np.fft.rfft((x - x.mean()) * window)) ** 2)[lo - 1:hi + 1]
    Uu = (np.abs(np.fft.rfft((u - u.mean()) * window)) ** 2)[lo:hi]
    background = scipy.ndimage.median_filter(X[lo:hi], size=width, mode="nearest")
    background_u = scipy.ndimage.median_filter(Uu, size=width, mode="nearest")
    ratio = np.zeros(f.size)
    ratio_u = np.zeros(f.size)
    ratio[lo:hi] = X[lo:hi] / np.maximum(background, 1e-300)
    ratio_u[lo:hi] = Uu / np.maximum(background_u, 1e-300)
    inside = (f >= band[0]) & (f <= band[1])
    peaks = np.where(inside[1:-1] & (ratio[1:-1] > LINE_RATIO) & (X[1:-1] >= X[:-2]) & (X[1:-1] >= X[2:])
                     & (ratio_u[1:-1] < LINE_RATIO / 4))[0] + 1
    peaks = peaks[np.argsort(ratio[peaks])[::-1]][:MAX_LINES]
    lines = []
    for k in peaks:
        a, b, c = np.log(X[k - 1:k + 2] + 1e-300)
        offset = 0.5 * (a - c) / (a - 2 * b + c) if (a - 2 * b + c) != 0 else 0.0
        frequency = (k + float(np.clip(offset, -0.5, 0.5))) * fs / n
        if any(abs(frequency - g) < 2 * fs / n for g in known):
            continue
        # The level from 2 s of the recording: plenty for a line this far above the noise.
        excerpt = x[: int(2 * fs)] - x.mean()
        fitted = fit_sinusoids(excerpt, [frequency], fs)
        lines.append((frequency, float(ratio[k]), float(np.sqrt(np.mean(fitted**2)))))
    return sorted(lines)


def _least_squares_residual(columns: np.ndarray, target: np.ndarray) -> float:
    """Residual energy of complex target on complex columns (complex coefficients)."""
    theta, *_ = np.linalg.lstsq(columns, target, rcond=None)
    return float(np.sum(np.abs(target - columns @ theta) ** 2))


def driven(x: np.ndarray, u: np.ndarray, fs: float, frequencies) -> list[bool]:
    """For each frequency (Hz): does u explain the peak of x there better than a sinusoid does?
    See the module docstring."""
    if not len(frequencies):
        return []
    n = x.size
    X, U = np.fft.rfft(x - x.mean()), np.fft.rfft(u - u.mean())
    answers = []
    for f in frequencies:
        centre = f * n / fs
        k = np.arange(max(int(round(centre)) - DRIVEN_WINDOW, 1), min(int(round(centre)) + DRIVEN_WINDOW + 1, X.size))
        z = (k - centre) / DRIVEN_WINDOW
        transient = [np.ones(k.size, complex), z.astype(complex)]
        # sum_{t<n} exp(j w t) exp(-j 2 pi k t / n): the kernel of a sinusoid at w = 2 pi f / fs.
        step = 2 * np.pi * (f / fs - k / n)
        exact = np.abs(step) < 1e-12
        kernel = np.where(exact, n, (1 - np.exp(1j * step * n)) / np.where(exact, 1.0, 1 - np.exp(1j * step)))
        response = np.column_stack([U[k] * z**m for m in range(3)] + transient)
        line = np.column_stack([kernel] + transient)
        answers.append(_least_squares_residual(response, X[k]) < _least_squares_residual(line, X[k]))
    return answers


def undriven_lines(recording: Recording, band=IDENTIFICATION_BAND) -> list[float]:
    """Frequencies (Hz) of the lines of a recording's ear signal that its input neither holds
    (``find_lines``) nor explains (``driven``: the peaks of the plant's own modes)."""
    peaks = [line[0] for line in find_lines(recording.y, recording.u, recording.fs, band)]
    return [f for f, by_input in zip(peaks, driven(recording.y, recording.u, recording.fs, peaks)) if not by_input]


def line_regressor(n: int, frequencies, fs: float) -> np.ndarray:
    """The (n, 4 L) columns of L lines at ``frequencies`` (Hz): cos, sin, and both times centred
    time over its span, so a small frequency error or a slow amplitude change of a line is
    absorbed too."""
    t = (np.arange(n) - n / 2) / fs
    span = t[-1] - t[0] if n > 1 else 1.0
    regressor = np.empty((n, 4 * len(frequencies)), order="F")  # column by column
    for k, f in enumerate(frequencies):
        phase = 2 * np.pi * f * t
        regressor[:, 4 * k] = np.cos(phase)
        regressor[:, 4 * k + 1] = np.sin(phase)
        regressor[:, 4 * k + 2] = regressor[:, 4 * k] * (t / span)
        regressor[:, 4 * k + 3] = regressor[:, 4 * k + 1] * (t / span)
    return regressor


class _BlockedRegressor:
    """``line_regressor``'s rows ``FIT_BLOCK`` at a time, without a sine or cosine per sample.

    Each line's exp(j 2 pi f m / fs), m < ``FIT_BLOCK``, is computed once; the block from sample s is
    that vector times the constant exp(j 2 pi f (s - n/2) / fs) (one complex product per sample
    instead of a cosine and a sine). The rounding of a product is that of the phase 2 pi f t at the
    recording's end (1e-16 of 2 pi f t, 3e5 rad at 5 kHz and 10 s), so the columns agree with
    ``line_regressor``'s to about 1e-11.
    """

    def __init__(self, n: int, frequencies, fs: float):
        self.n, self.fs = n, fs
        self.omegas = 2 * np.pi * np.asarray(frequencies, float) / fs  # rad per sample
        self.steps = np.exp(1j * np.outer(self.omegas, np.arange(min(FIT_BLOCK, n))))
        self.span = (n - 1) / fs if n > 1 else 1.0

    def blocks(self):
        """(start, stop, rows) of every block: rows the (4 L, stop - start) columns of those samples,
        transposed (each column contiguous) and grouped by kind: the L cosines, the L sines, then both
        times centred time over its span."""
        lines = self.omegas.size
        for start in range(0, self.n, FIT_BLOCK):
            stop = min(start + FIT_BLOCK, self.n)
            size = stop - start
            t = (np.arange(start, stop) - self.n / 2) / self.fs / self.span
            turns = np.exp(1j * self.omegas * (start - self.n / 2))[:, None] * self.steps[:, :size]
            rows = np.empty((4, lines, size))
            rows[0], rows[1] = turns.real, turns.imag
            np.multiply(rows[:2], t, out=rows[2:])
            yield start, stop, rows.reshape(4 * lines, size)


def fit_sinusoids(x: np.ndarray, frequencies, fs: float, keep: np.ndarray | None = None) -> np.ndarray:
    """Least-squares fit of sinusoids at the given frequencies (Hz) to x; returns the fitted signal
    (``line_regressor``'s columns) at every sample. ``keep`` (boolean, x's length): the samples the
    fit is taken over (clipped stretches carry the clipper's error, not the line); all by default."""
    frequencies = list(frequencies or [])
    if not frequencies or x.size < 8:
        return np.zeros_like(x)
    columns = _BlockedRegressor(x.size, frequencies, fs)
    # Normal equations: the columns are near orthogonal over a recording of many periods, so the
    # small Gram matrix is well conditioned (lstsq on it still copes with coinciding lines). It is
    # summed block by block: the (n, 4 L) regressor of a 20 s recording is tens of MB, and writing it
    # and reading it back three times (the kept rows, the Gram matrix, the fitted signal) cost 0.2-0.5 s
    # a fit; a block's rows stay in cache.
    gram = np.zeros((4 * len(frequencies),) * 2)
    moment = np.zeros(4 * len(frequencies))
    for start, stop, rows in columns.blocks():
        target = x[start:stop]
        if keep is not None:
            rows, target = rows[:, keep[start:stop]], target[keep[start:stop]]
        gram += rows @ rows.T
        moment += rows @ target
    theta, *_ = np.linalg.lstsq(gram, moment, rcond=None)
    fitted = np.empty(x.size)
    for start, stop, rows in columns.blocks():
        fitted[start:stop] = theta @ rows
    return fitted


def response_lines(u: np.ndarray, y: np.ndarray, frequencies, fs: float) -> np.ndarray:
    """The lines at ``frequencies`` (Hz) in the ear signal y of a recording with input u, fitted
    beside the plant's response (see the module docstring); returns the fitted lines (FS)."""
    frequencies = [f for f in (frequencies or []) if 0 < f < fs / 2]
    n = y.size
    if not frequencies or n < 8 * RESPONSE_WINDOW:
        return np.zeros_like(y)
    regressor = line_regressor(n, frequencies, fs)
    columns = np.fft.rfft(regressor, axis=0)
    U, Y = np.fft.rfft(u), np.fft.rfft(y)
    bins = n // 2 + 1
    rows, blocks = [], []
    for f in frequencies:
        centre = f * n / fs
        k = np.arange(max(int(round(centre)) - RESPONSE_WINDOW, 0), min(int(round(centre)) + RESPONSE_WINDOW + 1, bins))
        x = (k - centre) / RESPONSE_WINDOW
        rows.append(k)
        blocks.append(np.column_stack([U[k] * x**m for m in range(3)] + [x**m for m in range(2)]))
    k = np.concatenate(rows)
    # Real unknowns: the lines' 4 L coefficients, then each window's complex response coefficients.
    response = np.zeros((k.size, sum(b.shape[1] for b in blocks)), complex)
    r = c = 0
    for block in blocks:
        response[r:r + block.shape[0], c:c + block.shape[1]] = block
        r, c = r + block.shape[0], c + block.shape[1]
    line_part = columns[k]
    design = np.vstack([np.hstack([line_part.real, response.real, -response.imag]),
                        np.hstack([line_part.imag, response.imag, response.real])])
    target = np.concatenate([Y[k].real, Y[k].imag])
    scale = np.linalg.norm(design, axis=0)
    scale[scale == 0] = 1.0
    theta, *_ = np.linalg.lstsq(design / scale, target, rcond=None)
    return regressor @ (theta[: regressor.shape[1]] / scale[: regressor.shape[1]])


def without_lines(recording: Recording, frequencies) -> Recording:
    """``recording`` with the lines at ``frequencies`` (Hz) fitted beside the plant's response
    (``response_lines``) and taken out of its ear signal; the recording itself when there are none."""
    if not frequencies:
        return recording
    y = recording.y - response_lines(recording.u, recording.y, frequencies, recording.fs)
    return Recording(recording.u, y, recording.fs, recording.path, recording.clipped_fraction, recording.dc_offset)


def quiet_samples(y: np.ndarray) -> np.ndarray:
    """The samples where |y| is below ``LOUD`` of its largest value: away from any clip level."""
    level = np.abs(y)
    return level < LOUD * float(np.max(level, initial=0.0))


@dataclass(frozen=True)
class SessionLines:
    """The lines of a session (``line_search``): ``found`` per recording, in the order searched, the
    ``find_lines`` tuples (frequency Hz, ratio to neighbourhood, RMS level FS) of the lines not
    found before (in ``known`` or an earlier recording); ``frequencies`` (Hz) all of them with the
    ``known`` ones, sorted."""

    found: tuple[tuple[tuple[float, float, float], ...], ...]
    frequencies: tuple[float, ...]


def line_search(recordings, predictions, known=()) -> SessionLines:
    """The lines that the inputs lack in what the model leaves of the ear signals (y minus
    ``predictions``, the model's predictions without lines, FS), over every recording of a session
    (``find_lines``); ``known`` (Hz): the model's disturbance, not searched again."""
    lines = [float(f) for f in known or ()]
    found = []
    for recording, predicted in zip(recordings, predictions):
        n = min(recording.y.size, predicted.size)
        # Where the ear signal is loud it may be clipped, and what the model leaves there is the clipper's
        # broadband error (a quarter of the samples clipped buries a 50 Hz hum): searched without them.
        left = np.where(quiet_samples(recording.y[:n]), recording.y[:n] - predicted[:n], 0.0)
        found.append(tuple(find_lines(left, recording.u[:n], recording.fs, IDENTIFICATION_BAND, lines)))
        lines += [line[0] for line in found[-1]]
    return SessionLines(tuple(found), tuple(sorted(lines)))


def session_lines(recordings, predictions, known=()) -> list[float]:
    """Frequencies (Hz) of the lines that the inputs lack in what the model leaves of the ear signals,
    over every recording of a session, with the ``known`` ones (``line_search``)."""
    return list(line_search(recordings, predictions, known).frequencies)
