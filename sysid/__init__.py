"""helmet-anc identification: recordings -> spectra -> subspace fit -> model -> validation.

The Python API mirrors the command line; every step takes and returns numpy arrays
and small dataclasses, so a notebook needs no files::

    from sysid import simulate_session, SessionSpec, identify
    session = simulate_session(SessionSpec(path="ff", seed=1))
    result = identify(session.noise, session.sweeps, path="ff")
    result.model.save("ff_model.json")

The names below are imported from their modules when first read (PEP 562, as scipy
does): ``import sysid.simulate`` or ``import sysid.core.model`` loads what that
module needs, not identification, diagnosis and refinement behind the facade.
"""

import importlib as _importlib
import sys as _sys
import types as _types

from . import _moved

__version__ = "0.1.0"

_moved.install()

# Public name -> the module that defines it.
_HOMES = {
    "sysid.core.errors": ("HelmetAncError", "IdentificationError", "ModelError", "RecordingError"),
    "sysid.core.model": ("Model",),
    "sysid.core.plants": ("appendix_a_model",),
    "sysid.diagnose": ("diagnose", "format_findings"),
    "sysid.estimation.grid": ("GridResult", "grid_search"),
    "sysid.estimation.spectra": ("estimate_spectra", "parzen_lag_window", "response", "smooth_spectra",
                                 "smoothed_response"),
    "sysid.estimation.subspace": ("SubspaceDecomposition", "subspace_fit"),
    "sysid.estimation.uncertainty": ("UncertaintyBand", "frequency_response_band"),
    "sysid.identify": ("Identification", "IdentificationOptions", "identify"),
    "sysid.io.recordings": ("Recording", "RecordingFile", "RecordingWarning", "check_same_rate", "load_recording",
                            "open_recording", "recording_from_arrays"),
    "sysid.refine": ("Refinement", "format_refinement", "refine", "refine_auto"),
    "sysid.simulate": ("Session", "SessionSpec", "simulate_session", "write_session"),
    "sysid.validation.compare": ("Comparison", "compare", "format_comparison"),
    "sysid.validation.sweeps": ("noise_floor", "simulated_rms"),
}
_HOME = {name: module for module, names in _HOMES.items() for name in names}
# The subpackages (and ``simulate``) that ``import sysid`` used to bind as attributes.
_SUBMODULES = ("core", "effects", "estimation", "findings", "io", "refits", "simulate", "validation")
# The modules named as a function of the facade: ``sysid.diagnose`` is the function.
_SHADOWED = ("diagnose", "identify", "refine")

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


def __getattr__(name: str):
    if name in _HOME:
        value = getattr(_importlib.import_module(_HOME[name]), name)
        globals()[name] = value
        return value
    if name in _SUBMODULES:
        return _importlib.import_module(f"{__name__}.{name}")
    # ``report`` (the report is the top-level package ``report`` now), through the old path's shim.
    if name == "report":
        return _importlib.import_module("report")
    raise AttributeError(f"module 'sysid' has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(__all__) | set(_SUBMODULES))


class _Facade(_types.ModuleType):
    """The package module: a function of the facade keeps its name when the module of the same name
    (``sysid.diagnose``, ``sysid.identify``, ``sysid.refine``) is imported."""

    def __setattr__(self, name: str, value) -> None:
        # The import system binds a loaded submodule on its package; ``sysid.diagnose`` stays the function.
        if name in _SHADOWED and isinstance(value, _types.ModuleType) and value.__name__ == f"{__name__}.{name}":
            return
        super().__setattr__(name, value)


_sys.modules[__name__].__class__ = _Facade
