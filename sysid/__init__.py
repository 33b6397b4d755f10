"""helmet-anc identification: recordings -> spectra -> subspace fit -> model -> validation.

The Python API mirrors the command line; every step takes and returns numpy arrays
and small dataclasses, so a notebook needs no files::

    from sysid import simulate_session, SessionSpec, identify
    session = simulate_session(SessionSpec(path="ff", seed=1))
    result = identify(session.noise, session.sweeps, path="ff")
    result.model.save("ff_model.json")
"""

from .errors import HelmetAncError, IdentificationError, ModelError, RecordingError
from .grid import GridResult, grid_search
from .identify import Identification, IdentificationOptions, identify
from .model import Model
from .plants import appendix_a_model
from .recordings import (Recording, RecordingFile, RecordingWarning, check_same_rate, load_recording, open_recording,
                         recording_from_arrays)
from .simulate import Session, SessionSpec, simulate_session, write_session
from .spectra import estimate_spectra, parzen_lag_window, response, smooth_spectra, smoothed_response
from .subspace import SubspaceDecomposition, subspace_fit
from .validation import noise_floor, simulated_rms
from .uncertainty import UncertaintyBand, frequency_response_band
from .compare import Comparison, compare, format_comparison
from .diagnose import diagnose, format_findings
from .refine import Refinement, format_refinement, refine, refine_auto
from . import report  # write_report and the figures; matplotlib loads on first use

__version__ = "0.1.0"

__all__ = [
    "HelmetAncError", "IdentificationError", "ModelError", "RecordingError", "RecordingWarning",
    "GridResult", "grid_search", "Identification", "IdentificationOptions", "identify", "Model",
    "appendix_a_model", "Recording", "RecordingFile", "check_same_rate", "load_recording", "open_recording",
    "recording_from_arrays",
    "Session", "SessionSpec", "simulate_session", "write_session", "estimate_spectra", "parzen_lag_window",
    "response", "smooth_spectra", "smoothed_response", "SubspaceDecomposition", "subspace_fit",
    "noise_floor", "simulated_rms", "UncertaintyBand", "frequency_response_band", "Comparison", "compare", "format_comparison", "diagnose", "format_findings",
    "Refinement", "refine", "refine_auto", "format_refinement", "report", "__version__",
]
