"""What the detectors see: the one place a ``DiagnosisContext`` is built.

``diagnose``, ``refine`` (an effect's ``complete`` and the builders that read a
detector's estimate) and the report all build the context here, so every reader
sees the recordings as the model does: the ear clock resampled by the model's
``clock_ratio`` (``sysid.io.corrections.corrected``).
"""

from __future__ import annotations

from ..core.model import Model
from ..core.thresholds import TRANSIENT_S
from ..io.corrections import corrected
from ..io.recordings import Recording
from . import DiagnosisContext

__all__ = ["detector_context"]


def detector_context(model: Model, noise: Recording, sweeps: list[Recording], comparison,
                     transient_s: float = TRANSIENT_S) -> DiagnosisContext:
    """The context of ``model`` on a noise recording and its sweeps (``comparison``: the model's
    ``sysid.validation.compare.Comparison`` on the sweeps), the recordings corrected by the model's clock ratio."""
    return DiagnosisContext(model, corrected(noise, model.clock_ratio), [corrected(s, model.clock_ratio) for s in sweeps],
                            comparison, transient_s)
