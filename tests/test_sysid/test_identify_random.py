"""identify() on random helmet paths (sysid.random_plant) without hints: floor, frequency response, latency.

Pass criteria (issue 10): in-band validation rms at most 1.2 times the true noise floor
(the rms of the true plant on the same sweeps), max |H_model - H_true| over 20 Hz-4 kHz
at most 5 % of the true peak gain, estimated delay within 2 samples of the true one.
"""

import numpy as np
import pytest

from sysid.identify import IdentificationOptions, identify
from sysid.random_plant import random_plant, random_session
from sysid.validation.sweeps import simulated_rms

SHORT = dict(noise_duration=8.0, sweep_duration=2.0, sweep_silence=0.2)
OPTIONS = IdentificationOptions(gammas=tuple(range(10, 1001, 30)))
# Issue 10 asks for 20 plants in the default run; one identification of a short session
# takes 2-25 s of CPU, median 6-9 s (BENCHMARKS.md, random helmets), so the default run holds
# the cheaper ones that still span the drawn range: true orders 2 to 19, delays 1 to 64
# samples, Q up to 50 (61, 22, 28), modes down to 35 Hz, 44.1 and 48 kHz; two whose delay a
# 4-sample search at the picked order missed (30: the onset 10 samples short, found by the
# 12-sample search; 49: 3 short, where with the benchmark's grid the picked core's fixed-pole
# cost dips back near the true delay and only refitted poles tell, sysid.estimation.delay.refine_delay).
# All 20 pass at 6f37370: 88 s of wall time in all on 2 cores at load average 2-4 (39: 9.8 s,
# 28: 9.4 s, 31: 8.7 s; 44 and 85: 1.1 s).
DEFAULT_SEEDS = (3, 11, 18, 22, 29, 32, 34, 36, 38, 39, 30, 49, 28, 31, 97, 61, 75, 85, 44, 35)
SLOW_SEEDS = range(100)
# Seeds whose order search stalled in a local minimum, 4x-46x above the floor (1, 25, 27, 72: a
# lightly damped mode below 60 Hz or near 150 Hz missed, found by sysid.estimation.order_search's mode
# insertion), or whose pick rang in simulation through an out-of-band pole at z = -1 (63, 13x:
# dropped by identify's settling). 12-22 s of CPU each, so slow-marked.
# Seed 1 kept a real pole at z = -1 at the parametrisation's old margin (1 - 1e-9), which balancing
# left as an entry of 196; the pole radius is now bounded by the block's time constant
# (sysid.estimation.output_error.decay_bound) and it passes.
LOCAL_MINIMUM_SEEDS = (1, 25, 27, 63, 72)


def _failure(seed: int) -> str | None:
    """Why the identification of random helmet ``seed`` misses issue 10's criteria (None: it meets them)."""
    rp = random_plant(seed)
    session = random_session(seed, **SHORT)
    result = identify(session.noise, session.sweeps, "fb", OPTIONS)
    model = result.model
    true_floor = simulated_rms(rp.model, session.sweeps)
    f = np.geomspace(20.0, 4000.0, 2000)
    h_true = rp.model.frequency_response(f)
    frf_error = np.max(np.abs(model.frequency_response(f) - h_true)) / np.max(np.abs(h_true))
    assert model.stable
    assert model.identification["latency"]["samples"] == model.delay == model.identification["delay"]
    problems = []
    # Balanced: every entry of order one (a modal form held up to 1e12 in B). Counted as a miss
    # beside the others, so that the hundred-helmet count holds every seed.
    entry = max(np.abs(model.A).max(), np.abs(model.B).max(), np.abs(model.C).max())
    if entry > 10.0:
        problems.append(f"balanced entry {entry:.3g}")
    if abs(model.delay - rp.delay) > 2:
        problems.append(f"delay {model.delay}, true {rp.delay}")
    if model.identification["rms"] > 1.2 * true_floor:
        problems.append(f"rms {model.identification['rms'] / true_floor:.2f}x floor")
    if frf_error > 0.05:
        problems.append(f"FRF error {frf_error:.3f} of the peak gain")
    return f"seed {seed}: " + ", ".join(problems) if problems else None


@pytest.mark.parametrize("seed", DEFAULT_SEEDS)
def test_random_helmet_reaches_the_floor(seed):
    failure = _failure(seed)
    assert failure is None, failure


@pytest.mark.slow
@pytest.mark.parametrize("seed", LOCAL_MINIMUM_SEEDS)
def test_random_helmet_out_of_a_local_minimum_reaches_the_floor(seed):
    failure = _failure(seed)
    assert failure is None, failure


# Seeds whose delay was read past the true one, where a core imitates the lead (41: the pick rang in simulation,
# 9.9x moved back from its poles, the scan again behind the shorter delay; 76: a moved core with poles at -0.85 and
# -0.87, Hankel norm 1780, balanced entry 11.7). 10-20 s of CPU each, so slow-marked.
DELAY_PAST_SEEDS = (41, 76)


@pytest.mark.slow
@pytest.mark.parametrize("seed", DELAY_PAST_SEEDS)
def test_random_helmet_behind_a_delay_read_past_its_own_reaches_the_floor(seed):
    failure = _failure(seed)
    assert failure is None, failure


# 97 of 100 at cee2f29 (402 s of CPU in all). Seeds 57, 77 and 78 miss by their delay alone, 3 to 4 samples off at
# 1.03-1.11x the floor: 57 and 77 start smoothly
# (two roll-offs at 2.3-5.7 kHz, the onset's lag fs / (2 pi f_c) samples each, read long on 57 and short on 77); 78's
# 12-state pick refits 0.1 % lower (9 noise variances) one to three samples short of its pure delay, where its spare
# poles imitate the missing samples. 41 (a delay read 2 long: the pick rang in simulation, the scan again behind the
# moved delay reaches 1.0x) and 76 (a core behind 2 samples too many imitating the lead: Hankel norm 1780, balanced
# entry 11.7) are identify's own fixes (sysid.identify, sysid.estimation.delay.trials).
@pytest.mark.slow
def test_hundred_random_helmets_at_least_97_percent_reach_the_floor():
    failures = [f for f in map(_failure, SLOW_SEEDS) if f is not None]
    assert len(failures) <= 3, "; ".join(failures)
