"""Tests of the feed-forward basis from the paths' own poles (anc.feedforward_fit.path_poles)."""

from __future__ import annotations

import numpy as np

from anc.basis import KautzBasis
from anc.feedforward_fit import path_poles
from sysid.core.model import Model

FS = 48000.0
LATENCY = 2


def _model(path: str, poles, zeros, delay: int) -> Model:
    """A model of the given poles and zeros (a companion realisation), unit gain at DC."""
    a, b = np.real(np.poly(poles)), np.atleast_1d(np.real(np.poly(zeros)))
    b = b * np.sum(a) / np.sum(b)
    n = len(a) - 1
    b = np.concatenate((np.zeros(n + 1 - len(b)), b))
    A = np.zeros((n, n))
    A[0] = -a[1:]
    A[1:, :-1] = np.eye(n - 1)
    C = (b[1:] - b[0] * a[1:]).reshape(1, -1)
    return Model(path, FS, A, np.eye(n, 1), C, np.array([[b[0]]]), delay=delay)


def test_the_basis_holds_the_filter_that_cancels_the_chin_noise():
    # W = -z^L P / S with the chin path three samples slower than the drive path and latency 2: one sample of
    # delay beside the poles of P and the zeros of S (minimum phase: W is causal and stable). Least squares in
    # the basis against it leaves round-off.
    s = _model("fb", [0.95, 0.6 * np.exp(0.4j), 0.6 * np.exp(-0.4j)], [0.5, -0.7], delay=0)
    p = _model("ff", [0.9 * np.exp(0.1j), 0.9 * np.exp(-0.1j)], [0.3], delay=3)
    poles = path_poles(s, p)
    assert np.max(np.abs(poles)) < 1.0
    f = np.linspace(10.0, FS / 2.0, 3000)
    z = np.exp(2j * np.pi * f / FS)
    target = -z ** LATENCY * p.frequency_response(f) / s.frequency_response(f)
    responses = KautzBasis.from_poles(poles).responses(f, FS)
    c = np.linalg.lstsq(responses, target, rcond=None)[0]
    assert np.max(np.abs(responses @ c - target)) <= 1e-8 * np.max(np.abs(target))


def test_a_zero_outside_the_unit_circle_is_reflected_and_the_loop_poles_are_kept():
    s = _model("fb", [0.9, 0.5], [1.25], delay=1)
    p = _model("ff", [0.8], [], delay=4)
    loop = np.array([0.99, 0.3 + 0.2j, 0.3 - 0.2j])
    poles = path_poles(s, p, loop)
    assert np.any(np.isclose(poles, 0.8)) and np.any(np.isclose(poles, 1.0 / 1.25))
    assert all(np.any(np.isclose(poles, pole)) for pole in loop)
    assert len(poles) == 1 + 1 + 16 + loop.size
