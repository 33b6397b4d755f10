"""A hum is one phasor over the whole recording; a noise-driven lightly damped mode's phase wanders."""

import numpy as np
import pytest
import scipy.signal

from sysid.io.line_stationarity import (
    LINE_SEGMENTS,
    is_stationary,
    line_departure,
    line_significance,
    segment_phasors,
)
from sysid.io.lines import LINE_RATIO, driven, find_lines

FS = 48000.0
N = 5 * 48000  # the noise recording of a short session after its transient: 5 s


def _resonance(rng, f0: float, q: float, level: float) -> np.ndarray:
    """White noise through a second-order resonance at f0 (Hz), quality q, scaled to ``level`` rms (FS)."""
    b, a = scipy.signal.iirpeak(f0, q, FS)
    x = scipy.signal.lfilter(b, a, rng.standard_normal(N + 96000))[96000:]  # its own transient left out
    return level * x / np.std(x)


def _line(f: float, level: float, phase: float = 0.3) -> np.ndarray:
    return np.sqrt(2) * level * np.sin(2 * np.pi * f * np.arange(N) / FS + phase)


@pytest.mark.parametrize("seed", range(3))
def test_a_line_is_stationary_and_a_noise_driven_q30_mode_is_not(seed):
    # Both stand out at 91 Hz far above the neighbourhood of a residual whose input does not drive them (the
    # mode rung by something else: the drive's distortion products, ambient noise), so the line search and
    # ``driven`` take both for lines; only the mode's phase wanders, at its bandwidth f/Q = 3 Hz.
    rng = np.random.default_rng(seed)
    u = rng.standard_normal(N)
    background = 1e-5 * rng.standard_normal(N)
    mode = background + _resonance(rng, 91.0, 30.0, 3e-4)
    line = background + _line(91.0, 3e-7)
    for x in (mode, line):
        found = find_lines(x, u, FS)
        assert found and all(abs(f - 91.0) < 91.0 / 30.0 and ratio > LINE_RATIO for f, ratio, _ in found)
        undriven = [f for (f, _, _), by_input in zip(found, driven(x, u, FS, [f for f, _, _ in found])) if not by_input]
        assert undriven
        for f in undriven:
            departure = line_departure(x, f, FS)
            if x is line:
                assert departure.over_background < departure.bound and is_stationary(x, f, FS), departure
            else:
                # Its departures carry its own power, tens of times the background's: not a bound's edge case.
                assert departure.over_background > 10 * departure.bound and departure.share > 1 / LINE_RATIO
                assert not is_stationary(x, f, FS)


@pytest.mark.parametrize("level", [2.2e-7, 1e-6, 1e-4])
def test_lines_from_the_detection_threshold_up_are_stationary(level):
    # The weakest line the search reports (LINE_RATIO times its neighbourhood's median) departs only by the
    # background's noise; a strong one by nothing either, also when its amplitude drifts by a tenth.
    rng = np.random.default_rng(11)
    u = rng.standard_normal(N)
    drift = 1 + 0.1 * np.arange(N) / N
    for x in (1e-5 * rng.standard_normal(N) + _line(50.0, level), 1e-5 * rng.standard_normal(N) + drift * _line(50.0, level)):
        found = find_lines(x, u, FS)
        assert len(found) == 1 and found[0][0] == pytest.approx(50.0, abs=0.1)
        assert is_stationary(x, found[0][0], FS), line_departure(x, found[0][0], FS)


def test_the_phasors_share_one_time_axis_and_skip_what_is_left_out():
    x = _line(50.0, 1e-3, phase=1.1)
    phasors, gains = segment_phasors(x, 50.0, FS)
    assert phasors.shape == (LINE_SEGMENTS, 1) and gains.shape == (LINE_SEGMENTS,)
    # x = sqrt(2) 1e-3 sin(w t + 1.1) = |a| cos(w t + arg a): one phasor, sqrt(2) 1e-3 at 1.1 - pi/2.
    assert np.allclose(phasors[:, 0], np.sqrt(2) * 1e-3 * np.exp(1j * (1.1 - np.pi / 2)), rtol=1e-6)
    # A stretch of loud broadband error (a clipped burst) is left out with ``keep``; a stretch with fewer kept
    # samples than four periods has no phasor, and the line is still one sinusoid over the rest.
    rng = np.random.default_rng(3)
    noisy = x + 1e-6 * rng.standard_normal(N)
    noisy[: N // LINE_SEGMENTS] += 0.1 * rng.standard_normal(N // LINE_SEGMENTS)
    keep = np.ones(N, bool)
    keep[: N // LINE_SEGMENTS] = False
    assert np.isnan(segment_phasors(noisy, 50.0, FS, keep=keep)[0][0, 0])
    assert not is_stationary(noisy, 50.0, FS) and is_stationary(noisy, 50.0, FS, keep)


def test_a_weak_line_stands_out_of_a_sweeps_error_where_the_sweep_is_elsewhere():
    # A sweep's residual: a loud error (a distorted drive's harmonics) 0.5 s long and broadband, a hum 40 dB
    # below it throughout. Against the residual's rms the hum is within the noise; against the background
    # beside it, stretch by stretch, it is many standard errors out, and a frequency without a line is not.
    rng = np.random.default_rng(5)
    n = int(2.4 * FS)
    error = np.zeros(n)
    error[int(0.4 * FS):int(0.9 * FS)] = 1e-2 * rng.standard_normal(int(0.5 * FS))
    hum = np.sqrt(2) * 1e-4 * np.sin(2 * np.pi * 50.0 * np.arange(n) / FS)
    x = error + hum + 1e-6 * rng.standard_normal(n)
    assert np.sqrt(4 / n) * np.std(x) * 5 > 1e-4  # the broadband rule would not see it
    assert line_significance(x, 50.0, FS) > 1e3 and line_significance(x, 70.0, FS) < 25
