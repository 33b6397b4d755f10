"""HTML tables of a report: summary, model matrices, sections, Hankel singular values, findings.

Numbers are printed with ``%.6g`` (matrices, sections) or fewer digits where they are
read, not reused; the model JSON file holds the exact values.
"""

from __future__ import annotations

import json
from html import escape

import numpy as np

from sysid.core.lti import hankel_singular_values
from sysid.core.sections import second_order_sections

__all__ = [
    "findings_table",
    "hankel_table",
    "history_table",
    "html_table",
    "matrices_html",
    "sections_table",
    "summary_table",
]


def html_table(header: list[str], rows: list[list], css: str = "") -> str:
    """A table with escaped cells; numbers are formatted with %.6g."""
    def cell(value):
        if isinstance(value, (float, np.floating)):
            return f"{value + 0.0:.6g}"  # + 0.0 turns -0.0 into 0
        return escape(str(value))

    head = "".join(f"<th>{escape(h)}</th>" for h in header)
    head = f"<thead><tr>{head}</tr></thead>" if header else ""
    body = "".join("<tr>" + "".join(f"<td>{cell(v)}</td>" for v in row) + "</tr>" for row in rows)
    return f'<table class="{css}">{head}<tbody>{body}</tbody></table>'


def summary_table(data) -> str:
    """Headline figures of the model on this data."""
    model, c = data.model, data.comparison
    rows = [
        ["path", f"{model.path} ({'headphone drive -> ear' if model.path == 'fb' else 'chin microphone -> ear'})"],
        ["sample rate", f"{model.fs:g} Hz"],
        ["order / delay", f"{model.order} states, {model.delay} sample(s) of pure delay"],
        ["stability", (f"{'stable' if model.stable else 'UNSTABLE'}; largest pole radius {model.spectral_radius:.6f} "
                      f"(margin {1 - model.spectral_radius:.2e})")],
        ["validation rms (20 Hz-4 kHz)", f"{c.rms:.3e} FS = {c.rms / c.noise_floor:.2f}x the noise floor ({c.noise_floor:.3e} FS)"],
        ["rms, full band", f"{c.rms_full:.3e} FS"],
        ["fit (NRMSE, as MATLAB compare)", f"{c.fit_percent:.2f} %"],
        ["recordings", ", ".join([data.noise.path, *(s.path for s in data.sweeps)])],
    ]
    if model.input_nonlinearity:
        rows.append(["input polynomial", ", ".join(f"a{k}={a:.4g}" for k, a in enumerate(model.input_nonlinearity, 1))])
    if model.disturbance_frequencies:
        rows.append(["disturbance lines", ", ".join(f"{f:.2f} Hz" for f in model.disturbance_frequencies)])
    return html_table([], rows, "summary")


def _matrix(name: str, matrix: np.ndarray) -> str:
    rows = [[f"{v:.6g}" for v in row] for row in np.atleast_2d(matrix)]
    return f'<div class="matrix"><div class="label">{escape(name)} =</div>{html_table([], rows, "matrix")}</div>'


def matrices_html(model) -> str:
    """A, B, C, D as tables (x(t+1) = A x(t) + B u(t - delay), y(t) = C x(t) + D u(t - delay))."""
    return "".join(_matrix(name, getattr(model, name)) for name in ("A", "B", "C", "D"))


def sections_table(model) -> str:
    """Second-order sections in z^-1 (b0 b1 b2 / 1 a1 a2), poles closest to the unit circle last."""
    rows = []
    for k, s in enumerate(second_order_sections(model), start=1):
        radius = max((abs(p) for p in s.poles), default=0.0)
        frequency = max((abs(np.angle(p)) for p in s.poles), default=0.0) * model.fs / (2 * np.pi)
        rows.append([k, *s.b, *s.a[1:], f"{radius:.6f}", f"{frequency:.1f}"])
    return html_table(["section", "b0", "b1", "b2", "a1", "a2", "pole radius", "pole frequency (Hz)"], rows, "numbers")


def hankel_table(model) -> str:
    """Hankel singular values and their share of the largest, in dB."""
    if not model.stable:
        return "<p>Hankel singular values are defined for stable models only.</p>"
    values = hankel_singular_values(model.A, model.B, model.C)
    rows = [[k, float(v), f"{20 * np.log10(v / values[0]):.1f}" if v > 0 else "-inf"] for k, v in enumerate(values, 1)]
    return html_table(["state", "Hankel singular value", "dB re largest"], rows, "numbers")


def _compact(value) -> str:
    if isinstance(value, float):
        return f"{value:.4g}"
    if isinstance(value, list):
        shown = ", ".join(_compact(v) for v in value[:8])
        return f"[{shown}{', ...' if len(value) > 8 else ''}]"
    return str(value)


def findings_table(findings: list[dict]) -> str:
    """Ranked findings: effect, significance, score, parameters, evidence, explanation, remedy."""
    rows = []
    for f in findings:
        params = "; ".join(f"{k} = {_compact(v)}" for k, v in f["params"].items())
        evidence = "; ".join(f"{k} = {_compact(v)}" for k, v in (f.get("evidence") or {}).items())
        rows.append([f["effect"], "yes" if f["significant"] else "no", f"{f['score']:.2f}", params, evidence,
                     f["explanation"], f["remedy"]])
    return html_table(["effect", "significant", "score", "parameters", "evidence", "explanation", "remedy"], rows,
                      "findings")


def history_table(history: list[dict]) -> str:
    """Refinement steps: effect, parameters, rms before and after (FS)."""
    rows = [[h.get("effect", "?"), json.dumps(h.get("params", {}), sort_keys=True), h.get("rms_before", ""),
             h.get("rms_after", ""), "worse" if h.get("worse") else "better"] for h in history]
    return html_table(["effect added", "parameters", "rms before (FS)", "rms after (FS)", "error"], rows, "numbers")
