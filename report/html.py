"""The self-contained HTML report: every figure a PNG embedded as base64, CSS inline, no scripts.

``report_figures(data)`` lists the figures (key, section, caption, drawing function);
``render_report(data)`` turns them and the tables into one HTML page;
``write_report(path, model, noise, sweeps, ...)`` does it all and writes atomically.
The page references nothing outside itself, so it opens offline and can be mailed.
"""

from __future__ import annotations

import base64
import io
from collections.abc import Callable
from dataclasses import dataclass
from html import escape
from pathlib import Path

import numpy as np

from sysid.core.errors import HelmetAncError
from sysid.core.model import atomic_write_text
from sysid.core.thresholds import TRANSIENT_S

from . import diagnosis_figures as diag
from . import identification_figures as ident
from . import model_figures as modelfig
from . import order_figures as orderfig
from . import validation_figures as valid
from .data import ReportData, prepare_report_data
from .tables import findings_table, hankel_table, history_table, matrices_html, sections_table, summary_table
from .target import report_file

__all__ = [
    "SECTIONS",
    "ReportFigure",
    "figure_png",
    "plotted_findings",
    "render_report",
    "report_figures",
    "write_report",
]

SECTIONS = (
    ("identification", "1. Identification, step by step (the seed's figures on this data)"),
    ("model", "2. The model"),
    ("validation", "3. Where the model fails: the sweeps"),
    ("diagnosis", "4. Diagnosis and refinement"),
    ("tables", "5. Model tables"),
)
# At most this many finding plots; the table lists every finding.
MAX_FINDING_PLOTS = 6


@dataclass(frozen=True)
class ReportFigure:
    """One figure of the report: a stable key, its section, a caption and how to draw it."""

    key: str
    section: str
    caption: str
    draw: Callable[[float], object]


def figure_png(figure, dpi: float) -> bytes:
    """The figure as PNG bytes at dpi."""
    buffer = io.BytesIO()
    figure.savefig(buffer, format="png", dpi=dpi)
    return buffer.getvalue()


def plotted_findings(findings: list[dict]) -> list[dict]:
    """The findings that get a plot: the significant ones, or the strongest one when none is."""
    significant = [f for f in findings if f["significant"]]
    if significant:
        return significant[:MAX_FINDING_PLOTS]
    return sorted(findings, key=lambda f: -f["score"])[:1]


def _identification_figures(data: ReportData) -> list[ReportFigure]:
    spectra = data.spectra
    chosen = data.grid.chosen.order if data.grid is not None else data.model.order
    if data.grid is not None and data.grid.singular_values:
        singular = data.grid.singular_values
    else:
        singular = ident.order_singular_values(spectra)
    figures = [
        ReportFigure("averaged-spectra", "identification",
                     "Seed fig. 3.1. Grey: DFT of the whole noise recording after the transient; blue: the seed's mean of "
                     "segment DFTs (one point per 20 Hz). Both sit at the same level and scatter alike: averaging the "
                     "DFTs of independent noise segments shrinks the excitation as fast as its noise, so the mean only "
                     "looks calmer because it has fewer points, and Y_av/U_av is no more accurate than one segment. "
                     "Averaging powers (Welch's H1 = S_yu/S_uu) is what reduces the noise; this report's estimates use "
                     f"the {spectra.estimator} estimator.",
                     lambda dpi: ident.averaged_spectra_figure(data.noise, data.transient_s, dpi=dpi)),
        ReportFigure("smoothed-estimates", "identification",
                     "Seed figs. 3.3/3.4. Small gamma = wide frequency window = strong smoothing: the curve is calm but "
                     "flattens narrow modes (bias). Large gamma follows the noisy estimate. Look for the smallest gamma "
                     "whose curve still keeps the peaks and notches of the grey one.",
                     lambda dpi: ident.smoothed_estimates_figure(spectra, dpi=dpi)),
        ReportFigure("singular-values", "identification",
                     "Seed appendix B. A gap between sigma_n and sigma_(n+1) would name the order n. A slow, gapless "
                     "decay (what the seed found) means the order has to be chosen by validation instead. Dashed: the order "
                     "of the grid's choice (refinement may settle on another; see the summary).",
                     lambda dpi: ident.singular_values_figure(singular, chosen, dpi=dpi)),
    ]
    if data.grid is not None:
        figures.append(ReportFigure(
            "rms-grid", "identification",
            "Seed appendix C: validation rms of every stable (gamma, order) candidate relative to the noise floor; "
            f"hatched cells are unstable. Grid: {data.grid_note}. A flat valley means the choice is not critical; "
            "an isolated best cell next to unstable ones is fragile.",
            lambda dpi: ident.rms_heatmap_figure(data.grid, data.comparison.noise_floor, dpi=dpi)))
    return figures


def _model_figures(data: ReportData) -> list[ReportFigure]:
    model = data.model
    zeros = model.zeros()
    outside = int(np.sum(np.abs(zeros) > 1.0))
    decay = modelfig.transient_decay_db(model, data.transient_s)
    return [
        ReportFigure("model-bode", "model",
                     "Seed figs. 4.1/4.4. Red: the model; grey: the non-smoothed estimate; blue: smoothed at the chosen "
                     "gamma; orange dashed: the seed grid's choice before refinement. The estimates' phase is drawn on "
                     "the model's branch, so where grey scatters around red the model is as good as the data; a steady "
                     "offset or slope is a model error.",
                     lambda dpi: modelfig.model_bode_figure(model, data.spectra, data.gamma, seed_model=data.seed_model, dpi=dpi)),
        ReportFigure("pole-zero", "model",
                     f"Seed figs. 4.2/4.5. Poles (x) must lie inside the unit circle; the largest radius is "
                     f"{model.spectral_radius:.6f}. {outside} zero(s) lie outside (red): a non-minimum-phase path, whose "
                     "impulse response starts the wrong way; a controller cannot invert those zeros. Zeros almost on top "
                     "of poles cancel and hint that the order could be lower.",
                     lambda dpi: modelfig.pole_zero_figure(model, dpi=dpi)),
        ReportFigure("impulse-response", "model",
                     f"Seed figs. 4.3/4.6. Left: the first milliseconds (a non-minimum-phase path starts in the opposite "
                     f"direction). Right: decay in dB; at {data.transient_s:g} s the response is "
                     f"{modelfig.decay_label(decay)}, so dropping the first {data.transient_s:g} s of the noise recording as transient is "
                     f"{'justified' if decay < -60 else 'NOT justified: the slowest mode is still ringing'} "
                     "(criterion: below -60 dB).",
                     lambda dpi: modelfig.impulse_response_figure(model, data.transient_s, dpi=dpi)),
    ] + ([ReportFigure("order-curve", "model",
                       "The order/error/cost trade-off identify found (from the model's provenance): top, the "
                       "validation rms on the sweeps over the noise floor of each order (circles: models refined at "
                       "that order; red: the order chosen); bottom, how much of the response the states beyond n hold "
                       "(Hankel singular values) and what a model of n states costs the board per sample.",
                       lambda dpi: orderfig.order_curve_figure(model, dpi=dpi))]
         if orderfig.has_order_curve(model) else [])


def _validation_figures(data: ReportData) -> list[ReportFigure]:
    c = data.comparison
    figures = []
    for k, record in enumerate(c.per_sweep, start=1):
        figures.append(ReportFigure(
            f"sweep-{k}", "validation",
            f"Sweep {k} ({record['path']}): measured (grey) and predicted (red) ear signal, error in black. The "
            "dashed brown curve (right axis) is the sweep's instantaneous frequency: read the frequency at which the "
            "error grows. The lower panel zooms on the 20 ms with the largest error.",
            lambda dpi, record=record: valid.sweep_prediction_figure(record, dpi=dpi)))
    figures += [
        ReportFigure("error-bands", "validation",
                     "Error per third-octave band against the noise floor measured from the two repeated sweeps. Shaded "
                     "bands have an error more than twice the noise: that is where the model misses something. At or "
                     "below the green line the data cannot tell a better model from this one.",
                     lambda dpi: valid.error_bands_figure(c, dpi=dpi)),
        ReportFigure("residual-correlation", "validation",
                     "Residual tests (Ljung; MATLAB resid), 99 % bounds shaded. Top: a white error stays inside. Bottom: "
                     "an error that still correlates with the input at lag k > 0 means dynamics the model misses "
                     "(a single peak at a positive lag is a missing delay of k samples); at negative lags, feedback.",
                     lambda dpi: valid.residual_correlation_figure(c, dpi=dpi)),
        ReportFigure("coherence", "validation",
                     "Coherence of input and ear signal in the noise recording. Below 1 the ear signal holds something "
                     "the input does not explain linearly: noise, nonlinearity or disturbance lines. |H1/H2| below "
                     "0 dB where the output is strong points at noise on the input channel (H1 then reads low).",
                     lambda dpi: valid.coherence_figure(data.spectra, dpi=dpi)),
    ]
    return figures


def _diagnosis_figures(data: ReportData) -> list[ReportFigure]:
    figures = []
    keys = set()
    for finding in plotted_findings(data.findings):
        prefix = "" if finding["significant"] else "Nothing is significant; the strongest candidate is shown. "
        key = f"finding-{finding['effect']}"
        key = key if key not in keys else f"{key}-{len(keys) + 1}"
        keys.add(key)
        figures.append(ReportFigure(
            key, "diagnosis",
            f"{prefix}{finding['effect']}: {finding['explanation']}. Remedy: {finding['remedy']}.",
            lambda dpi, finding=finding: diag.finding_figure(finding, data.context, data.spectra, dpi=dpi)))
    history = data.model.history
    figures.append(ReportFigure(
        "refinement", "diagnosis",
        ("Validation error after each refinement step; the dashed line is the noise floor, the best any model can do on "
         "these recordings. Steps that do not lower the error added an effect the data did not ask for."
         if history else "No refinement recorded in this model's history: the single level is the identified model's "
                          "error against the noise floor."),
        lambda dpi: diag.refinement_figure(history, data.comparison.noise_floor, data.comparison.rms, dpi=dpi)))
    return figures


def report_figures(data: ReportData) -> list[ReportFigure]:
    """Every figure of the report for data, in page order."""
    return _identification_figures(data) + _model_figures(data) + _validation_figures(data) + _diagnosis_figures(data)


_CSS = """
body{font-family:system-ui,-apple-system,'Segoe UI',Roboto,Arial,sans-serif;max-width:1100px;margin:1.5em auto;
padding:0 1em;color:#222;line-height:1.45}
h1{font-size:1.6em;margin-bottom:.2em}h2{border-bottom:2px solid #ccc;padding-bottom:.2em;margin-top:2em}
figure{margin:1.5em 0;padding:.5em;border:1px solid #e4e4e4;border-radius:4px;background:#fff}
figure img{max-width:100%;height:auto;display:block;margin:auto}
figcaption{font-size:.92em;color:#333;margin-top:.4em}
table{border-collapse:collapse;margin:.6em 0;font-size:.88em}
th,td{border:1px solid #ddd;padding:.25em .5em;text-align:left;vertical-align:top}
th{background:#f3f3f3}table.numbers td,table.matrix td{font-family:ui-monospace,Menlo,Consolas,monospace;text-align:right}
table.findings td:nth-child(6),table.findings td:nth-child(7){min-width:16em}
.matrix{display:inline-block;vertical-align:top;margin-right:1.5em}.matrix .label{font-weight:bold}
.note{background:#fff8e0;border-left:4px solid #e0b000;padding:.4em .8em}
.scroll{overflow-x:auto}
nav ul{list-style:none;padding-left:0;columns:2}nav a{color:#1a5fb4}
"""


def _figure_html(figure: ReportFigure, dpi: float) -> str:
    drawn = figure.draw(dpi)
    png = base64.b64encode(figure_png(drawn, dpi)).decode("ascii")
    return (f'<figure id="{figure.key}"><img id="fig-{figure.key}" alt="{escape(figure.key)}" '
            f'src="data:image/png;base64,{png}"><figcaption>{escape(figure.caption)}</figcaption></figure>')


def _tables_html(data: ReportData) -> str:
    model = data.model
    parts = [
        "<h3>State-space matrices</h3>",
        ("<p>x(t+1) = A x(t) + B u(t - d), y(t) = C x(t) + D u(t - d), full-scale units, "
        f"d = {model.delay} sample(s) at {model.fs:g} Hz.</p>"),
        f'<div class="scroll">{matrices_html(model)}</div>',
        "<h3>Transfer function as second-order sections</h3>",
        ("<p>G(z) = z^-d &prod;<sub>k</sub> (b0 + b1 z^-1 + b2 z^-2) / (1 + a1 z^-1 + a2 z^-2). Poles are paired with "
        "their nearest zeros, the sections closest to the unit circle come last, the gain sits in section 1. A section "
        "with b0 = 0 carries one sample of the model's relative degree. The model is never written as one high-order "
        "polynomial: rounded to a few digits such a polynomial can turn unstable (seed appendix A).</p>"),
        f'<div class="scroll">{sections_table(model)}</div>',
        "<h3>Hankel singular values</h3>",
        ("<p>How much each state of a balanced realisation contributes to the input-output behaviour; states far "
        "below the first (tens of dB) could be truncated.</p>"),
        hankel_table(model),
    ]
    return "\n".join(parts)


def render_report(data: ReportData, dpi: float = 100.0, title: str | None = None, extra_sections=()) -> str:
    """The report page as an HTML string.

    ``extra_sections``: (key, heading, HTML body) triples the caller appends after the
    report's own sections (e.g. the control section, built outside sysid).
    """
    model = data.model
    title = title or f"helmet-anc report: {model.path.upper()} path model"
    figures = report_figures(data)
    body = {key: [] for key, _ in SECTIONS}
    for figure in figures:
        body[figure.section].append(_figure_html(figure, dpi))
    if data.grid is None:
        body["identification"].append(f'<p class="note">The (gamma, order) grid of seed appendix C is {escape(data.grid_note)}.</p>')
    body["diagnosis"].insert(0, '<div class="scroll">' + findings_table(data.findings) + "</div>")
    if model.history:
        body["diagnosis"].append(history_table(model.history))
    body["tables"].append(_tables_html(data))
    headings = list(SECTIONS)
    for key, heading, html in extra_sections:
        headings.append((key, heading))
        body[key] = [html]
    contents = "<nav><ul>" + "".join(f'<li><a href="#{key}">{escape(heading)}</a></li>' for key, heading in headings) + "</ul></nav>"
    sections = "\n".join(f'<section id="{key}"><h2>{escape(heading)}</h2>\n' + "\n".join(body[key]) + "</section>"
                         for key, heading in headings)
    return (f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
            f'<meta name="viewport" content="width=device-width, initial-scale=1">'
            f'<meta name="generator" content="helmet-anc">'
            f"<title>{escape(title)}</title><style>{_CSS}</style></head><body>\n"
            f"<h1>{escape(title)}</h1>\n{summary_table(data)}\n{contents}\n{sections}\n</body></html>\n")


def write_report(path, model, noise, sweeps, identification=None, findings=None, *, dpi: float = 100.0,
                 grid: str = "modest", transient_s: float = TRANSIENT_S, extra_sections=()) -> Path:
    """Write the HTML report of model on the recordings to path and return the file written.

    ``identification`` (an ``Identification``) supplies spectra, grid and seed model;
    without it they are recomputed (``grid``: "modest" or "skip", see ``report.data``).
    ``findings`` defaults to ``sysid.diagnose.diagnose``'s. When path is an existing
    folder (or ends with a separator: a folder, which must exist; ``report.target``) the file is
    ``<path>/<fb|ff>-report.html``. The file appears only once
    complete (written beside it and renamed). ``extra_sections``: see ``render_report``.
    """
    target = report_file(path, model.path)
    folder = target.parent if str(target.parent) else Path(".")
    if not folder.is_dir():
        raise HelmetAncError(f"{target}: folder {folder} does not exist")
    data = prepare_report_data(model, noise, sweeps, identification, findings, grid, transient_s)
    atomic_write_text(target, render_report(data, dpi, extra_sections=extra_sections))
    return target
