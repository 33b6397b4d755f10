"""Pictures a helmet engineer reads: an HTML report of identification, validation, diagnosis and refinement.

``write_report(path, model, noise, sweeps, identification=None, findings=None)`` writes
one self-contained HTML file (figures embedded as PNG, no network). The figures one by
one are in ``report.figures``; the transfer function as second-order sections
is ``sysid.core.sections.second_order_sections`` and the Hankel singular values
``sysid.core.lti.hankel_singular_values``.

The names below load their module (and matplotlib) on first use, so importing
``sysid`` or starting the command line stays fast.
"""

import importlib

__all__ = [
    "ReportData",
    "prepare_report_data",
    "render_report",
    "report_figures",
    "write_report",
]

_HOMES = {
    "write_report": "html", "render_report": "html", "report_figures": "html",
    "prepare_report_data": "data", "ReportData": "data",
}


def __getattr__(name):
    if name in _HOMES:
        return getattr(importlib.import_module(f"{__name__}.{_HOMES[name]}"), name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(list(globals()) + __all__)
