"""refits.nonlinear_order: the core's order chosen again by truncation and refit, the fewest states that validate as well."""

import numpy as np
import pytest

from sysid.core.model import Model
from sysid.core.structures import mode_block, with_states
from sysid.random_plant import random_session
from sysid.refits.machinery import _with
from sysid.refits.nonlinear_order import fewest_states, within_noise
from sysid.validation.compare import compare


@pytest.fixture(scope="module")
def clean():
    session = random_session(3, "fb", noise_duration=4.0, sweep_duration=1.0, sweep_silence=0.2)
    return session, Model.from_dict(session.truth["plant"])


def padded(model: Model, weight: float) -> Model:
    """``model`` with a spare mode at 3 kHz (Q 5) whose input and output weights are ``weight``: four states
    more than the plant holds, which move its response by next to nothing (states fitted to nothing)."""
    A, B, C = with_states(model.A, model.B, model.C, mode_block(3000.0, 5.0, model.fs), mode_block(800.0, 2.0, model.fs))
    B[model.order:] = weight
    C[0, model.order:] = weight
    return _with(model, (A, B, C, model.D))


def test_spare_states_are_truncated_to_the_order_the_data_hold(clean):
    session, true = clean
    model = padded(true, 1e-4)
    assert model.order == true.order + 4
    best, tried = fewest_states(model, session.sweeps, lambda start: start)
    assert best.order == true.order
    assert [order for order, _ in tried] == list(range(1, true.order + 1))
    # Each order below the plant's misses by far more than the validation's noise.
    assert all(ratio > 1.5 for order, ratio in tried if order < true.order)
    assert within_noise(compare(best, session.sweeps).rms, compare(model, session.sweeps))


def test_a_model_at_its_order_is_kept_when_no_refit_succeeds(clean):
    session, true = clean
    best, tried = fewest_states(true, session.sweeps, lambda start: None)
    assert best is true and tried == []


def test_within_noise_is_the_larger_of_the_run_to_run_noise_and_the_order_rule(clean):
    session, true = clean
    reference = compare(true, session.sweeps)
    assert within_noise(reference.rms, reference)
    assert not within_noise(reference.rms * 1.5, reference)
