"""The batch's HTML summary page: per helmet and path, the spread of the members'
frequency responses with the nominal model and its bound, the worst sessions, and the
findings that recur. Figures are PNG embedded as base64; the page needs no network.
"""

from __future__ import annotations

import base64
from collections import Counter
from html import escape

import numpy as np

from report.html import figure_png
from report.style import COLORS, db, log_frequency_axis, new_figure

from .nominal import NominalModel
from .outputs import OutputLayout, atomic_write_text

__all__ = ["render_summary", "write_summary", "WORST_SESSIONS"]

WORST_SESSIONS = 3
_CSS = ("body{font-family:sans-serif;max-width:70em;margin:auto;padding:1em}table{border-collapse:collapse}"
        "td,th{border:1px solid #ccc;padding:2px 6px;text-align:left}.failed{color:#a00}img{max-width:100%}")


def _spread_figure(nominal: NominalModel, dpi: float):
    figure, (ax_mag, ax_bound) = new_figure(2, 1, height=2.8, sharex=True, dpi=dpi)
    f = nominal.frequencies_hz
    for k, response in enumerate(nominal.member_responses):
        ax_mag.plot(f, db(response), color=COLORS["measured"], lw=0.8, label="members" if k == 0 else None)
    nominal_response = nominal.model.frequency_response(f)
    ax_mag.plot(f, db(nominal_response), color=COLORS["model"], lw=1.5, label=f"nominal (order {nominal.model.order})")
    ax_mag.fill_between(f, db(np.abs(nominal_response) * np.maximum(1 - nominal.relative_bound, 1e-3)),
                        db(np.abs(nominal_response) * (1 + nominal.relative_bound)), color=COLORS["bound"], alpha=0.2,
                        label="nominal x (1 +- bound)")
    ax_mag.set_ylabel("|H| (dB)")
    ax_mag.legend(fontsize=8)
    ax_bound.plot(f, nominal.relative_bound, color=COLORS["bound"])
    ax_bound.set_yscale("log")
    ax_bound.set_ylabel("relative bound w(f)")
    for ax in (ax_mag, ax_bound):
        log_frequency_axis(ax, (f[0], f[-1]), label=ax is ax_bound)
    return figure


def _group_html(key: tuple[str, str], rows: list[dict], nominal: NominalModel | None, dpi: float) -> str:
    helmet, path = key
    ok = [r for r in rows if r["status"] == "ok"]
    failed = [r for r in rows if r["status"] != "ok"]
    parts = [f'<section id="{escape(helmet)}-{path}"><h2>Helmet {escape(helmet)}, {path.upper()} path</h2>',
             f"<p>{len(rows)} session(s): {len(ok)} identified, {len(failed)} failed.</p>"]
    if nominal is not None:
        png = base64.b64encode(figure_png(_spread_figure(nominal, dpi), dpi)).decode("ascii")
        info = nominal.model.identification
        parts.append(f'<figure><img alt="spread {escape(helmet)} {path}" src="data:image/png;base64,{png}">'
                     f"<figcaption>Members' responses, the nominal model ({escape(info['source'])}) and the "
                     f"multiplicative bound: mean {info['mean_relative_bound']:.3g}, largest "
                     f"{info['max_relative_bound']:.3g}.</figcaption></figure>")
    elif ok:
        parts.append("<p>No nominal model: it needs at least two identified sessions.</p>")
    worst = sorted(ok, key=lambda r: -(r["rms_over_floor"] or 0.0))[:WORST_SESSIONS]
    if worst:
        parts.append("<h3>Worst sessions (validation rms / noise floor)</h3><table><tr><th>session</th><th>head</th>"
                     "<th>condition</th><th>order</th><th>rms / floor</th><th>findings</th></tr>")
        parts += [f"<tr><td>{escape(r['session'])}</td><td>{escape(r['head'])}</td><td>{escape(r['condition'])}</td>"
                  f"<td>{r['order']}</td><td>{r['rms_over_floor']:.2f}</td><td>{escape(r['findings'] or '')}</td></tr>"
                  for r in worst]
        parts.append("</table>")
    counts = Counter(name for r in ok for name in (r["findings"] or "").split(";") if name)
    if counts:
        parts.append("<h3>Recurring findings</h3><ul>" + "".join(
            f"<li>{escape(name)}: {n} of {len(ok)} sessions</li>" for name, n in counts.most_common()) + "</ul>")
    if failed:
        parts.append("<h3>Failed sessions</h3><ul>" + "".join(
            f'<li class="failed">{escape(r["session"])}: {escape(r["reason"] or "")}</li>' for r in failed) + "</ul>")
    return "\n".join(parts) + "</section>"


def render_summary(rows: list[dict], nominals: dict, dpi: float = 80.0) -> str:
    """The page as HTML text; ``nominals`` maps (helmet, path) to a NominalModel."""
    groups: dict[tuple[str, str], list[dict]] = {}
    for row in rows:
        groups.setdefault((row["helmet"], row["path"]), []).append(row)
    failed = sum(r["status"] != "ok" for r in rows)
    body = [_group_html(key, group, nominals.get(key), dpi) for key, group in sorted(groups.items())]
    title = "helmet-anc batch summary"
    return (f'<!DOCTYPE html>\n<html lang="en"><head><meta charset="utf-8">'
            # The generator tag is how a later batch (sysid.core.files.is_ours) knows the page is ours.
            f'<meta name="generator" content="helmet-anc batch"><title>{title}</title>'
            f"<style>{_CSS}</style></head><body>\n<h1>{title}</h1>\n"
            f"<p>{len(rows)} session(s), {len(rows) - failed} identified, {failed} failed, "
            f"{len(groups)} helmet/path group(s).</p>\n" + "\n".join(body) + "\n</body></html>\n")


def write_summary(layout: OutputLayout, rows: list[dict], nominals: dict, dpi: float = 80.0) -> None:
    atomic_write_text(layout.summary, render_summary(rows, nominals, dpi))
