"""helmet-anc identification: recordings -> spectra -> subspace fit -> model -> validation.

The Python API mirrors the command line; every step takes and returns numpy arrays
and small dataclasses, so a notebook needs no files::

    from sysid import simulate_session, SessionSpec, identify
    session = simulate_session(SessionSpec(path="ff", seed=1))
    result = identify(session.noise, session.sweeps, path="ff")
    result.model.save("ff_model.json")
"""

from . import _moved
from .core.errors import HelmetAncError, IdentificationError, ModelError, RecordingError
from .core.model import Model
from .core.plants import appendix_a_model
from .diagnose import diagnose, format_findings
from .estimation.grid import GridResult, grid_search
from .estimation.spectra import estimate_spectra, parzen_lag_window, response, smooth_spectra, smoothed_response
from .estimation.subspace import SubspaceDecomposition, subspace_fit
from .estimation.uncertainty import UncertaintyBand, frequency_response_band
from .identify import Identification, IdentificationOptions, identify
from .io.recordings import (Recording, RecordingFile, RecordingWarning, check_same_rate, load_recording, open_recording,
                            recording_from_arrays)
from .refine import Refinement, format_refinement, refine, refine_auto
from .simulate import Session, SessionSpec, simulate_session, write_session
from .validation.compare import Comparison, compare, format_comparison
from .validation.sweeps import noise_floor, simulated_rms

__version__ = "0.1.0"

_moved.install()


def __getattr__(name: str):
    # ``report`` (the report is the top-level package ``report`` now), through the old path's shim.
    if name == "report":
        import importlib
        return importlib.import_module("report")
    raise AttributeError(f"module 'sysid' has no attribute {name!r}")

__all__ = [
    "HelmetAncError", "IdentificationError", "ModelError", "RecordingError", "RecordingWarning",
    "GridResult", "grid_search", "Identification", "IdentificationOptions", "identify", "Model",
    "appendix_a_model", "Recording", "RecordingFile", "check_same_rate", "load_recording", "open_recording",
    "recording_from_arrays",
    "Session", "SessionSpec", "simulate_session", "write_session", "estimate_spectra", "parzen_lag_window",
    "response", "smooth_spectra", "smoothed_response", "SubspaceDecomposition", "subspace_fit",
    "noise_floor", "simulated_rms", "UncertaintyBand", "frequency_response_band", "Comparison", "compare", "format_comparison", "diagnose", "format_findings",
    "Refinement", "refine", "refine_auto", "format_refinement", "__version__",
]
