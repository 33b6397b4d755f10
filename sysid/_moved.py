"""Old import paths of modules that moved, kept working for a release with a deprecation warning.

The package's modules moved into folders that show the pipeline (``sysid.core``,
``sysid.io``, ``sysid.estimation``, ``sysid.validation``) and the report became the
top-level package ``report``. ``import sysid.lti`` still works: a finder on
``sys.meta_path`` answers each old name with a small forwarding module (as scipy's
``_sub_module_deprecation`` shims do) that warns once, on import, with
``DeprecationWarning`` and reads every attribute from the module's new home.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys
import types
import warnings

__all__ = ["MOVED", "install"]

# Old module name -> new module name.
MOVED = {
    "sysid.errors": "sysid.core.errors",
    "sysid.files": "sysid.core.files",
    "sysid.thresholds": "sysid.core.thresholds",
    "sysid.lti": "sysid.core.lti",
    "sysid.model": "sysid.core.model",
    "sysid.structures": "sysid.core.structures",
    "sysid.sections": "sysid.core.sections",
    "sysid.effect_spec": "sysid.core.effect_spec",
    "sysid.plants": "sysid.core.plants",
    "sysid.recordings": "sysid.io.recordings",
    "sysid.channels": "sysid.io.channels",
    "sysid.data_quality": "sysid.io.data_quality",
    "sysid.corrections": "sysid.io.corrections",
    "sysid.lines": "sysid.io.lines",
    "sysid.spectra": "sysid.estimation.spectra",
    "sysid.subspace": "sysid.estimation.subspace",
    "sysid.grid": "sysid.estimation.grid",
    "sysid.output_error": "sysid.estimation.output_error",
    "sysid.masked_output_error": "sysid.estimation.masked_output_error",
    "sysid.order_search": "sysid.estimation.order_search",
    "sysid.reduction": "sysid.estimation.reduction",
    "sysid.uncertainty": "sysid.estimation.uncertainty",
    "sysid.latency": "sysid.estimation.delay",
    "sysid.compare": "sysid.validation.compare",
    "sysid.report": "report",
    "sysid.report.data": "report.data",
    "sysid.report.diagnosis_figures": "report.diagnosis_figures",
    "sysid.report.figures": "report.figures",
    "sysid.report.html": "report.html",
    "sysid.report.identification_figures": "report.identification_figures",
    "sysid.report.model_figures": "report.model_figures",
    "sysid.report.signals": "report.signals",
    "sysid.report.style": "report.style",
    "sysid.report.tables": "report.tables",
    "sysid.report.validation_figures": "report.validation_figures",
    "anc.figures": "report.control_figures",
}


def _importer_stacklevel() -> int:
    """``warnings.warn``'s stack level (from ``create_module``) of the statement that imported the old path.

    ``warnings`` skips the import machinery's own frames when it counts levels, so they are not counted here.
    """
    frame, level = sys._getframe(2), 1
    while frame is not None and frame.f_code.co_filename == __file__ or frame.f_code.co_filename.startswith("<frozen importlib"):
        if not frame.f_code.co_filename.startswith("<frozen importlib"):
            level += 1
        frame = frame.f_back
    return level + 1


class _Forward(types.ModuleType):
    """A module at an old path whose attributes are those of the module at its new path."""

    def __init__(self, name: str, target: str):
        super().__init__(name, f"moved to {target}")
        self.__dict__["_target"] = target

    def __getattr__(self, attribute: str):
        if attribute.startswith("__") and attribute.endswith("__") and attribute != "__all__":
            # The import system asks for __path__, __spec__, ...: the shim's own, never the target's (a
            # forwarded __path__ would load the target's submodules a second time under the old name).
            raise AttributeError(attribute)
        return getattr(importlib.import_module(self.__dict__["_target"]), attribute)

    def __dir__(self):
        return dir(importlib.import_module(self.__dict__["_target"]))


class _MovedFinder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    def find_spec(self, fullname, path, target=None):
        if fullname not in MOVED:
            return None
        spec = importlib.util.spec_from_loader(fullname, self, is_package=any(
            name.startswith(fullname + ".") for name in MOVED))
        return spec

    def create_module(self, spec):
        new = MOVED[spec.name]
        warnings.warn(f"{spec.name} moved to {new}; import it from there (the old path goes in a later release)",
                      DeprecationWarning, stacklevel=_importer_stacklevel())
        return _Forward(spec.name, new)

    def exec_module(self, module):
        importlib.import_module(MOVED[module.__name__])


def install() -> None:
    """Put the finder on ``sys.meta_path`` once (after the regular finders: only names they lack reach it)."""
    if not any(isinstance(finder, _MovedFinder) for finder in sys.meta_path):
        sys.meta_path.append(_MovedFinder())
