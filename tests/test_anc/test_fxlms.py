"""FxLMS (``anc.fxlms``): the step's stability bound, divergence above it, convergence judged from the ear's slope."""

from __future__ import annotations

import numpy as np
import pytest
from control_cases import random_pair, road_noise, seed_pair

from anc import fxlms
from anc.fxlms import convergence, diverging, run_fxlms, run_to_convergence, secondary_delay, stable_step


def test_the_bound_is_2_i_over_i_plus_delta():
    assert stable_step(128, 0) == 2.0
    assert stable_step(128, 128) == 1.0
    assert secondary_delay(seed_pair().s, 2) >= 2


def test_a_step_above_the_bound_diverges():
    """Twice the bound: the ear grows without limit within half a second (the seed pair)."""
    pair = seed_pair()
    x, d = road_noise(pair.p, 0.5, 3)
    mu = 2.0 * stable_step(32, secondary_delay(pair.s, 2))
    run = run_fxlms(pair.s, pair.s, x, d, 2, 32, mu)
    final, _, converged, slope, error = convergence(run, pair.s.fs)
    assert final < -60.0 and not converged


def test_a_converged_run_is_judged_converged():
    """A stationary ear (no adaptation: mu 0) is converged at 0 dB from the first frame."""
    pair = seed_pair()
    x, d = road_noise(pair.p, 1.0, 3)
    run = run_fxlms(pair.s, pair.s, x, d, 2, 16, 0.0)
    final, seconds, converged, _, _ = convergence(run, pair.s.fs)
    assert converged and abs(final) < 1e-9 and seconds == 0.0


@pytest.mark.slow
@pytest.mark.parametrize("pair", [seed_pair(), random_pair(3)], ids=["seed", "random 3"])
def test_runs_to_convergence_at_a_stable_step(pair):
    """From half the bound, the step is cut until the run does not diverge; it converges (slope within noise)."""
    x, d = road_noise(pair.p, 8.0, 3)
    _, result = run_to_convergence(pair.s, pair.s, x, d, 2, 64)
    assert not diverging(result) and result.converged, result
    assert result.mu <= 0.5 * result.mu_bound and np.isfinite(result.attenuation_db)


def test_the_record_is_doubled_until_the_run_converges(monkeypatch):
    """run_until_converged asks for records of 1, 2, 4 s and stops at the first that converges; without
    convergence it stops at the longest record it may take and says the run has not converged."""
    fs = 48000.0
    pair = seed_pair()

    def judged(s_true, s_model, x, d, latency, taps):
        converged = x.size >= 4 * fs
        return None, fxlms.FxlmsResult(-1.0, 0.5, converged, 0.0, 1.0, 0.1, 1.0, x.size / fs)

    monkeypatch.setattr(fxlms, "run_to_convergence", judged)
    asked = []

    def noise(seconds):
        asked.append(seconds)
        n = int(seconds * fs)
        return np.zeros(n), np.zeros(n)

    _, result = fxlms.run_until_converged(pair.s, pair.s, noise, 1.0, 64.0)
    assert asked == [1.0, 2.0, 4.0] and result.converged and result.run_seconds == 4.0
    asked.clear()
    _, result = fxlms.run_until_converged(pair.s, pair.s, noise, 1.0, 3.0)
    assert asked == [1.0, 2.0] and not result.converged and result.run_seconds == 2.0
