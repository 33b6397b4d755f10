"""Figures of a controller: sensitivity, Nyquist with the uncertainty discs, attenuation per band against the limits.

The attenuation figure and table read the limits the controller records (``Controller.limits``: the
causal feed-forward bound, the coherence bound, the robust feedback bound and what limits each band);
nothing is designed again here.

Drawn on ``matplotlib.figure.Figure`` with the report's shared look (``report.style``),
no pyplot state. ``control_page`` puts them on one standalone HTML page (``design --report``)
with the report's PNG helper and generator tag, so ``report`` never imports ``anc``.
"""

from __future__ import annotations

import base64
from html import escape

import numpy as np
from matplotlib.patches import Circle

from anc.controller import Controller
from anc.uncertainty import model_uncertainty

from .html import figure_png
from .style import COLORS, new_figure

__all__ = ["sensitivity_figure", "nyquist_figure", "attenuation_figure", "refinement_figure", "refinement_table_html",
           "control_section", "control_page"]


def _loop(controller: Controller, f: np.ndarray) -> np.ndarray:
    model = controller.internal_model
    G = model.frequency_response(f) * np.exp(-2j * np.pi * f * controller.latency_samples / controller.fs)
    return G * controller.fb.frequency_response(f, controller.fs)


def sensitivity_figure(controller: Controller, dpi: float = 100.0):
    """|1 + G Q| in dB (ear noise with over without feedback, nominal model) and the robustness usage."""
    figure, (ax,) = new_figure(dpi=dpi)
    f = np.geomspace(10.0, controller.fs / 2, 2000)
    loop = _loop(controller, f)
    r95 = model_uncertainty(controller.internal_model).at(f) if controller.fb is not None else f * 0
    ax.semilogx(f, 20 * np.log10(np.abs(1 + loop)), color=COLORS["model"], label="|1 + G Q| (sensitivity)")
    ax.semilogx(f, 20 * np.log10(np.maximum(r95 * np.abs(loop), 1e-6)), color=COLORS["bound"],
                label="r95 |S_model Q| (robust if below -6 dB)")
    ax.axhline(-6.0, color=COLORS["bound"], linestyle=":")
    ax.set_xlabel("frequency (Hz)")
    ax.set_ylabel("dB")
    ax.set_ylim(-40, 15)
    ax.legend(loc="lower left", fontsize="small")
    return figure


def nyquist_figure(controller: Controller, dpi: float = 100.0):
    """Nyquist plot of the equivalent loop Lg = -G Q / (1 + G Q) with the model's 95 % uncertainty
    disc (radius r95 |Lg|) at third-octave centres; the loop is robustly stable if no disc reaches -1."""
    figure, (ax,) = new_figure(height=5.0, width=5.5, dpi=dpi)
    f = np.geomspace(5.0, controller.fs / 2, 4000)
    loop = _loop(controller, f)
    Lg = -loop / (1 + loop)
    ax.plot(Lg.real, Lg.imag, color=COLORS["model"], label="Lg (nominal)")
    ax.plot(Lg.real, -Lg.imag, color=COLORS["model"], linestyle=":", linewidth=0.8)
    centres = np.array(controller.bands_hz)
    lc = _loop(controller, centres)
    Lc = -lc / (1 + lc)
    r95 = model_uncertainty(controller.internal_model).at(centres)
    for point, radius in zip(Lc, r95 * np.abs(Lc)):
        ax.add_patch(Circle((point.real, point.imag), radius, fill=False, color=COLORS["bound"], linewidth=0.6))
    ax.plot([-1], [0], "k+", markersize=12, label="-1")
    ax.set_aspect("equal")
    ax.set_xlim(-2, 2)
    ax.set_ylim(-2, 2)
    ax.set_xlabel("real")
    ax.set_ylabel("imaginary")
    ax.legend(loc="upper right", fontsize="small")
    return figure


def attenuation_figure(controller: Controller, achieved: dict[str, list[float]] | None = None, dpi: float = 100.0):
    """Predicted (lines) and, when given, achieved (markers) attenuation per third-octave band, dB."""
    figure, (ax,) = new_figure(dpi=dpi)
    centres = np.array(controller.bands_hz)
    colours = {"ff": "tab:blue", "fb": "tab:red", "both": "black"}
    for part, values in controller.predicted_attenuation_db.items():
        ax.semilogx(centres, values, color=colours[part], label=f"{part} predicted")
        if achieved and part in achieved:
            ax.semilogx(centres, achieved[part], "o", color=colours[part], markersize=4, label=f"{part} achieved")
    limits = controller.limits or {}
    drawn = False
    for key, label, style, colour in (("causal_ff_db", "causal feed-forward bound", "--", "tab:blue"),
                                      ("causal_ff_ruled_db", "the same within the design's rules", "-.", "tab:cyan"),
                                      ("coherence_db", "coherence bound", "--", "0.6"),
                                      ("feedback_db", "robust feedback bound", ":", "tab:red")):
        values = _values(limits.get(key))
        if values is not None and np.any(np.isfinite(values)):
            ax.semilogx(centres, values, color=colour, linestyle=style, label=label)
            drawn = drawn or key == "coherence_db"
    if not drawn and controller.coherence_bound_db is not None:
        ax.semilogx(centres, controller.coherence_bound_db, color="0.6", linestyle="--", label="coherence bound")
    ax.axhline(0.0, color="0.3", linewidth=0.6)
    ax.set_xlabel("third-octave band centre (Hz)")
    ax.set_ylabel("attenuation (dB, positive = quieter)")
    ax.legend(fontsize="small", ncol=2)
    return figure


def _values(values) -> np.ndarray | None:
    """Per-band values with None as NaN (not drawn), or None."""
    return None if values is None else np.array([np.nan if v is None else float(v) for v in values])


def _cell(value) -> str:
    return "<td></td>" if value is None or not np.isfinite(float(value)) else f"<td>{float(value):.1f}</td>"


def _reasons(controller: Controller, i: int) -> str:
    reasons = (controller.limits or {}).get("reasons", {})
    return "; ".join(f"{name}: {reasons[name][i]}" for name in ("ff", "fb") if reasons.get(name) and reasons[name][i])


def _margin_items(margins: dict) -> str:
    """The margins as list items; no phase margin where the loop gain never crosses 1."""
    items = []
    for key, value in margins.items():
        if key == "phase_margin_deg" and value is None:
            value = "no crossover (loop gain below 1 at every frequency)"
        elif key == "gain_margin_db" and value is None:
            value = "none (the loop never crosses the negative real axis)"
        items.append(f"<li>{escape(key)}: {escape(str(value))}</li>")
    return "".join(items)


def _img(figure, dpi: float, caption: str) -> str:
    png = base64.b64encode(figure_png(figure, dpi)).decode("ascii")
    return f'<figure><img alt="{escape(caption)}" src="data:image/png;base64,{png}"><figcaption>{escape(caption)}</figcaption></figure>'


def refinement_figure(steps, dpi: float = 100.0, part: str = "both"):
    """Predicted attenuation per band (dB) of the design on each model of a refinement history
    (``anc.refinement.attenuation_along``), one line per step."""
    figure, (ax,) = new_figure(dpi=dpi)
    for step in steps:
        if step.controller is not None:
            ax.semilogx(step.controller.bands_hz, step.predicted_db[part], marker=".", label=step.label)
    ax.axhline(0.0, color="0.3", linewidth=0.6)
    ax.set_xlabel("third-octave band centre (Hz)")
    ax.set_ylabel(f"predicted attenuation, {part} (dB)")
    ax.legend(fontsize="small")
    return figure


def refinement_table_html(steps, achieved: list[float | None] | None = None) -> str:
    """HTML table: per step of a refinement history, rms / noise floor, predicted mean attenuation
    50 Hz - 1 kHz (dB) for ff, fb, both, and (when given) the achieved mean for both, or the refusal."""
    parts = ("ff", "fb", "both")
    head = ("<tr><th>model</th><th>rms / noise floor</th>" + "".join(f"<th>{p} predicted (dB)</th>" for p in parts)
            + ("<th>both achieved (dB)</th>" if achieved else "") + "</tr>")
    rows = []
    for i, step in enumerate(steps):
        ratio = "" if step.rms_ratio is None else f"{step.rms_ratio:.2f}"
        if step.controller is None:
            cells = f'<td colspan="{len(parts) + bool(achieved)}">refused: {escape(step.refused or "")}</td>'
        else:
            cells = "".join(f"<td>{step.mean_db(p):.1f}</td>" for p in parts)
            if achieved:
                cells += "<td></td>" if achieved[i] is None else f"<td>{achieved[i]:.1f}</td>"
        rows.append(f"<tr><td>{escape(step.label)}</td><td>{ratio}</td>{cells}</tr>")
    return '<table class="numbers">' + head + "".join(rows) + "</table>"


def control_section(controller: Controller, achieved: dict[str, list[float]] | None = None, steps=None,
                    dpi: float = 100.0, achieved_note: str = "") -> str:
    """HTML body of the control section: attenuation table, margins, notes, the figures (attenuation
    predicted vs achieved, sensitivity, Nyquist with the uncertainty discs) and, with ``steps``
    (``anc.refinement.attenuation_along``), the refinement table and figure."""
    parts = ("ff", "fb", "both")
    limits = controller.limits or {}
    bounds = [(key, label) for key, label in (("causal_ff_db", "causal ff bound"),
                                              ("causal_ff_ruled_db", "causal ff bound within the rules"),
                                              ("coherence_db", "coherence bound"), ("feedback_db", "feedback bound"))
              if limits.get(key) is not None]
    head = "<tr><th>band (Hz)</th>" + "".join(f"<th>{p} predicted (dB)</th>" for p in parts)
    head += "".join(f"<th>{p} achieved (dB)</th>" for p in parts if achieved and p in achieved)
    head += "".join(f"<th>{label} (dB)</th>" for _, label in bounds) + ("<th>what limits it</th>" if limits else "")
    head += "</tr>"
    rows = "".join(f"<tr><td>{c:g}</td>" + "".join(f"<td>{controller.predicted_attenuation_db[p][i]:.1f}</td>"
                                                  for p in parts)
                   + "".join(f"<td>{achieved[p][i]:.1f}</td>" for p in parts if achieved and p in achieved)
                   + "".join(_cell(limits[key][i]) for key, _ in bounds)
                   + (f'<td class="text">{escape(_reasons(controller, i))}</td>' if limits else "") + "</tr>"
                   for i, c in enumerate(controller.bands_hz))
    margins = _margin_items(controller.margins)
    notes = "".join(f"<li>{escape(n)}</li>" for n in controller.notes)
    sign = ("<p>Attenuation in dB, positive = quieter at the ear. The limits are those the paths allow for the "
            "design's noise at its latency, as the controller records them.</p>")
    figures = [_img(attenuation_figure(controller, achieved, dpi), dpi,
                    "Attenuation per third-octave band: predicted (lines)" + (", achieved (markers)" if achieved else "")
                    + (", against the limits (dashed, dotted)" if limits else ""))]
    if controller.fb is not None:
        figures += [_img(sensitivity_figure(controller, dpi), dpi, "Sensitivity |1 + G Q| and robustness usage"),
                    _img(nyquist_figure(controller, dpi), dpi, "Nyquist plot of the loop with the 95 % uncertainty discs")]
    body = sign + (f"<p>{escape(achieved_note)}</p>" if achieved_note else "") + (
        '<div class="scroll"><table class="numbers">' + head + rows + "</table></div>"
        f"<h3>Margins</h3><ul>{margins}</ul><h3>Notes</h3><ul>{notes}</ul>" + "".join(figures))
    if steps:
        body += ("<h3>Refinement and control</h3><p>Per model of the refinement history: a design on that model "
                 "(its own uncertainty band) and the attenuation it predicts on it, mean over 50 Hz - 1 kHz.</p>"
                 + refinement_table_html(steps)
                 + _img(refinement_figure(steps, dpi), dpi, "Predicted attenuation (both) per band, per refinement step"))
    return body


def control_page(controller: Controller, achieved: dict[str, list[float]] | None = None, dpi: float = 100.0) -> str:
    """Standalone HTML page (``design --report``): ``control_section`` with the report's generator tag."""
    return ('<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8"><meta name="generator" content="helmet-anc">'
            "<title>helmet-anc control</title></head><body><h1>Control</h1>"
            + control_section(controller, achieved, dpi=dpi) + "</body></html>\n")
