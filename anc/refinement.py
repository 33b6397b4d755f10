"""What each refinement step did for control: the attenuation a design on each step's model predicts.

Issue 13 item 5 (the effect loop closes through control): a model that is better at the
bands that matter for control (50 Hz - 1 kHz, where helmet noise lives) is worth more than
one that is better at 4 kHz. For the FB models of a refinement history (the identified
model, then the model after each accepted ``sysid.refine`` step, whose last ``history``
entry names the step), ``attenuation_along`` designs a controller on each model with
``anc.design`` (its own uncertainty band, so a better-known model may be controlled
harder) and predicts the attenuation per third-octave band on that same model
(``anc.design.predict``). Achieved values need the true plant and come from
``anc.closed_loop.verify`` (tests, benchmarks). A model ``anc.design`` refuses is
recorded with the reason, not raised.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from sysid.core.errors import HelmetAncError
from sysid.core.model import Model

from .controller import Controller
from .design import DesignOptions, design
from .disturbance import Disturbance
from .prediction import band_centres

__all__ = ["StepAttenuation", "attenuation_along", "step_label", "band_mean", "CONTROL_BAND_HZ"]

# The bands that matter for helmet noise control (issue 13): wind and engine below 1 kHz.
CONTROL_BAND_HZ = (50.0, 1000.0)


def band_mean(values, lo_hz: float = CONTROL_BAND_HZ[0], hi_hz: float = CONTROL_BAND_HZ[1]) -> float:
    """Mean (dB) of per-band values (on ``anc.prediction.band_centres()``) over centres lo_hz..hi_hz."""
    centres = np.array(band_centres())
    inside = (centres >= lo_hz) & (centres <= hi_hz)
    return float(np.mean(np.asarray(values, dtype=float)[inside]))


def step_label(model: Model, index: int) -> str:
    """'identified' for the first model, else the effect of its last history step ('delay', ...)."""
    if index == 0 or not model.history:
        return "identified" if index == 0 else f"step {index}"
    last = model.history[-1]
    return f"{index}. + {last.get('effect', '?')}"


@dataclass
class StepAttenuation:
    """One model of a history: its label, rms over the noise floor, and the design on it
    (None when refused, with ``refused`` saying why). dB per band on ``band_centres()``."""

    label: str
    model: Model
    rms_ratio: float | None
    controller: Controller | None
    refused: str | None = None

    @property
    def predicted_db(self) -> dict[str, list[float]] | None:
        return None if self.controller is None else self.controller.predicted_attenuation_db

    def mean_db(self, part: str) -> float | None:
        """Predicted mean attenuation (dB) of part ('ff', 'fb', 'both') over ``CONTROL_BAND_HZ``."""
        return None if self.controller is None else band_mean(self.controller.predicted_attenuation_db[part])


def attenuation_along(models: list[Model], ff_model: Model | None = None, disturbance: Disturbance | None = None,
                      options: DesignOptions | None = None, labels: list[str] | None = None) -> list[StepAttenuation]:
    """Design on each FB model of a refinement history and predict on it (module docstring).

    ``models``: the FB models in order (identified first); ``ff_model``, ``disturbance``,
    ``options``: as ``anc.design``, the same for every step so only the model changes.
    """
    if labels is not None and len(labels) != len(models):
        raise HelmetAncError(f"{len(labels)} labels for {len(models)} models")
    result = []
    for i, model in enumerate(models):
        label = labels[i] if labels is not None else step_label(model, i)
        info = model.identification if isinstance(model.identification, dict) else {}
        ratio = (info["rms"] / info["noise_floor"]) if info.get("rms") and info.get("noise_floor") else None
        try:
            controller = design(model, ff_model, disturbance, options)
        except HelmetAncError as exc:
            result.append(StepAttenuation(label, model, ratio, None, str(exc)))
            continue
        result.append(StepAttenuation(label, model, ratio, controller))
    return result
