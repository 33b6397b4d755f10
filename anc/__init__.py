"""Active noise control designed from the identified helmet models.

From the feedback-path model S (drive -> ear) and optionally the feed-forward model P
(chin microphone -> ear) and a disturbance spectrum, ``anc.design`` computes a
feed-forward filter W and an internal-model-control feedback filter Q, predicts the
attenuation per third-octave band beside the limits the paths allow (``anc.limits``: causal
Wiener feed-forward and coherence bounds; ``anc.feedback_bound``: the robust feedback bound) and
what limits each band, and writes the controller JSON (format ``helmet-anc/controller@1``,
design.md "Control"; the limits in its ``limits`` field). The design's latency defaults to the
board's control path, ``anc.controller.BOARD_LATENCY_SAMPLES`` (2). ``anc.closed_loop`` and
``anc.fxlms`` check a design sample by sample on a true plant.

Signal convention (binding): ear e = d + S y, drive y[k] = W x[k-L] + Q d_hat[k-L],
d_hat = e - S_model y; W and Q carry their own sign.
"""

from .controller import CONTROLLER_FORMAT, Controller, StateSpaceFilter
from .design import DesignOptions, design

__all__ = ["CONTROLLER_FORMAT", "Controller", "StateSpaceFilter", "DesignOptions", "design"]
