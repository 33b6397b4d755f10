"""The core's order chosen again behind a fitted input map: the fewest states the compensated data hold.

An order chosen on a nonlinear driver's session is no bound: the harmonics of the drive look like
dynamics the linear order search has not explained, so identification (and the re-identification
behind a first map, which keeps the order of lowest validation rms) takes states that fit distortion
(random helmet 11 FF, true order 4, H2 -15 dB: identified at 28 and 30 states and refined to the floor
there; helmet 12 FB, true 8: the refit grew 5-7 identified states to 10-14). Once the map (and its
pre-filter) take the harmonics, the order is chosen again on the compensated problem: the core is
balanced-truncated (Moore 1981, ``sysid.core.lti.balanced_truncation``) to each order from one up to
its own, each truncation refitted jointly with the map by the output-error alternation
(``sysid.estimation.hammerstein``), and the fewest states are kept whose validation rms lies within
``MIN_GAIN`` of the model's (identify's own order rule: the lowest order within that of the best), or
within the validation's run-to-run noise where that is larger. A truncation is not the least-squares
fit of its order, so the joint refit, not the truncation, is what is judged. The model's own rms is
the reference though it was chosen on the sweeps (identify's grid keeps the candidate that validates
best; helmet 11 FF: 28 states at 1.001x the floor), while the joint refit of a truncation is fitted
on the noise recording alone: the true plant refitted so, from its own core and map, validates at
1.022x, its order's truncation of the 28 states at 1.026x.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from ..core import lti
from ..core.model import Model
from ..core.thresholds import MIN_GAIN
from ..validation.compare import compare
from .machinery import _with

__all__ = ["within_noise", "fewest_states"]


def within_noise(rms: float, reference) -> bool:
    """Whether a validation rms (FS) is as good as ``reference``'s (a comparison) for the order choice:
    at most its rms plus max(run-to-run noise, ``MIN_GAIN`` of its rms)."""
    return rms <= reference.rms + max(reference.run_to_run, MIN_GAIN * reference.rms)


def _truncated(model: Model, order: int) -> Model | None:
    """``model`` with its core balanced-truncated to ``order`` states (map, delay and the rest kept), or None."""
    truncated = lti.balanced_truncation(model.A, model.B, model.C, model.D, order=order)
    if truncated is None:
        minimal = lti.minimal_balanced_realisation(model.A, model.B, model.C, model.D, order=order)
        truncated = (minimal.A, minimal.B, minimal.C, np.array([[minimal.D]]))
    if truncated[0].shape[0] != order:
        return None
    return _with(model, truncated)


def fewest_states(model: Model, sweeps, refit: Callable[[Model], Model | None]) -> tuple[Model, list[tuple[int, float]]]:
    """(the model of fewest states validating as well as ``model``, [(order, rms/floor), ...]
    of the orders tried): ``model``'s core truncated to 1, 2, ... states below its own, each refitted by
    ``refit`` (the joint map-and-core fit; None when it fails), the first stable one whose validation rms
    on ``sweeps`` is ``within_noise`` of ``model``'s kept; ``model`` itself when none is."""
    reference = compare(model, sweeps)
    tried = []
    for order in range(1, model.order):
        start = _truncated(model, order)
        trial = None if start is None or not start.stable else refit(start)
        if trial is None or not trial.stable or trial.order != order:
            continue
        after = compare(trial, sweeps)
        tried.append((order, after.ratio))
        if within_noise(after.rms, reference):
            return trial, tried
    return model, tried
