"""Data-quality findings straight from the recordings: DC offset and clipping (effects.md).

Neither is a property of the sound path; ``refine`` corrects for both: a DC offset
on the ear signal becomes the model's ``output_offset``, and clipped stretches
(at any level, either channel) are listed in the model's ``excluded`` and left out
of identification and validation. The better remedy is on the recording side.

A preamplifier flat-tops before mains hum or an engine order couples in, and the hum smears
the flat tops: the clipped stretches are read after the session's lines are taken out of the
ear signals (``sysid.io.clipping``). The lines that the input lacks are found in what the model
leaves of the ear signals of every recording (a line the sweep's response hides in one recording
stands out in another; the hum runs through the whole session; ``sysid.io.lines.line_search``).
That search is the session's one line search in a diagnosis (the shared value
``session-lines``): the periodic-disturbance finding judges the lines it found on the noise
recording.
"""

from __future__ import annotations

import numpy as np

from ..io.clipping import channel_clipping, clipped_spans
from ..io.corrections import recording_key
from ..io.data_quality import DC_ABSOLUTE, dc_offset
from ..io.lines import SessionLines, line_search
from . import DiagnosisContext, finding, noise_prediction, provider, uses

__all__ = ["dc_offset_finding", "clipping_finding"]

# The ear offset is read in up to the first LEAD_S of a sweep recording where the input is SILENT
# (relative to its RMS) or less.
LEAD_S = 0.5
SILENT = 0.05


def _recordings(ctx: DiagnosisContext):
    return [ctx.noise, *ctx.sweeps]


@uses()
def dc_offset_finding(ctx: DiagnosisContext) -> dict:
    """Offsets of the input channels, and of the ear channel against the model's prediction.

    The noise excitation and the sweeps are zero-mean, so an input mean is an offset
    (``sysid.io.data_quality.dc_offset``). An ear signal may have a genuine mean (a path
    with large DC gain, a model that lacks a high-pass), so the ear offset is read
    where the path is at rest: the silence before each sweep, where the input is
    ``SILENT`` of its RMS or less; the model's prediction there (its ``output_offset``)
    is subtracted, so what is left is the offset the model misses. It counts when the
    sweeps agree on it and it exceeds ``DC_ABSOLUTE``, 6 standard errors of the mean and the range of the
    model's own prediction over the silence: a model whose gain below the sweeps' band is unconstrained
    answers the input's microvolt mean there (clean random helmet 20 FB: the prediction rose 1e-4 FS over
    the 0.19 s lead, the residual's mean -1.03e-4 FS drifting with it), and that is no offset of the ear.
    """
    body = ctx.body
    channels = [(body.path, "input", *dc_offset(body.u))]
    channels += [(s.path, "input", *dc_offset(s.u)) for s in ctx.sweeps]
    leads = []
    for sweep, record in zip(ctx.sweeps, ctx.comparison.per_sweep):
        level = np.abs(sweep.u - np.median(sweep.u))
        loud = np.flatnonzero(level > SILENT * np.sqrt(np.mean(level**2)))
        lead = min(int(loud[0]) if loud.size else 0, int(round(LEAD_S * ctx.fs)))
        if lead >= 64:
            predicted = record["predicted"][:lead]
            residual = sweep.y[:lead] - predicted
            leads.append((float(np.mean(residual)), float(np.std(residual)) / np.sqrt(lead), float(np.ptp(predicted))))
    ear_offset, ear_significant = 0.0, False
    if leads:
        means = np.array([m for m, _, _ in leads])
        error = float(np.sqrt(np.mean([e**2 for _, e, _ in leads]) / len(leads)))
        ear_offset = float(np.mean(means))
        agree = np.ptp(means) <= max(6 * error * np.sqrt(2), 0.1 * abs(ear_offset))
        # The model's own response in the silence (its gain below the sweeps' band acting on the input's
        # tiny mean) moves the residual as much as an offset would: no offset can be told from it.
        settled = abs(ear_offset) > max(r for _, _, r in leads)
        ear_significant = bool(abs(ear_offset) > max(DC_ABSOLUTE, 6 * error) and agree and settled)
        channels.append(("the sweeps' leading silence", "ear", ear_offset, ear_significant))
    significant = [c for c in channels if c[3]]
    worst = max(channels, key=lambda c: (c[3], abs(c[2])))
    where, level = f"{worst[1]} channel of {worst[0]}", worst[2]
    score = abs(level) / DC_ABSOLUTE
    explanation = (f"the {where} has a mean of {level:.3g} FS the model does not predict: a preamplifier offset or "
                   "microphone bias" if significant else "no channel has a DC offset the model misses")
    remedy = ("refine --add dc-offset (the model's output_offset takes the ear offset in); better, AC-couple the "
              "preamplifier" if significant else "none")
    return finding("dc-offset", bool(significant), max(score, 1.0) if significant else min(score, 0.99),
                   {"offset_fs": level, "ear_offset_fs": ear_offset if ear_significant else 0.0, "channel": where},
                   explanation, remedy, {"means_fs": [round(c[2], 8) for c in channels]})


@provider("session-lines")
def session_line_search(ctx: DiagnosisContext) -> SessionLines:
    """The shared value ``session-lines``: ``line_search`` on the noise recording then the sweeps, the
    predictions without the model's lines (every line is fitted anew on each recording), the model's
    disturbance known."""
    predictions = [noise_prediction(ctx)] + [record["linear"] for record in ctx.comparison.per_sweep]
    return line_search(_recordings(ctx), predictions, ctx.model.disturbance_frequencies)


@uses("noise-prediction", "session-lines")
def clipping_finding(ctx: DiagnosisContext) -> dict:
    """Clipping at any level on either channel of any recording (``sysid.io.data_quality.clipped_samples``;
    on the ear channel also against the model's prediction, where noise after the clipper hides the
    flat tops from the histogram), after the session's lines are taken out of the ear signals
    (``sysid.io.clipping.ear_without_lines``: a hum added after the clipper smears the flat tops)."""
    worst, where, levels = 0.0, "", []
    fractions, excluded = {}, {}
    # The predictions without the model's lines: every line is fitted anew on each recording.
    predictions = [noise_prediction(ctx)] + [record["linear"] for record in ctx.comparison.per_sweep]
    lines = list(ctx.value("session-lines").frequencies)
    for recording, predicted in zip(_recordings(ctx), predictions):
        channels = channel_clipping(recording, predicted, lines)
        for label, (clipping, _) in channels.items():
            fractions[f"{recording.path}:{label}"] = clipping.fraction
            if clipping.fraction > worst:
                worst, where, levels = clipping.fraction, f"{label} channel of {recording.path}", clipping.levels
        # The stretches come from the same masks: a recording without a clipped sample has none.
        spans = clipped_spans(recording, channels)
        if spans:
            excluded[recording_key(recording)] = spans
    already = bool(ctx.model.excluded) and all(ctx.model.excluded.get(k) for k in excluded)
    significant = worst > 0.0 and not already
    level_text = ", ".join(f"{v:+.3g}" for v in levels)
    explanation = (f"{100 * worst:.3g} % of the samples of the {where} sit flat at {level_text} FS: the converter, "
                   "amplifier or preamplifier clipped, and no linear model explains those stretches"
                   if worst > 0 else "no channel clips")
    if already:
        explanation += "; the model already leaves the clipped stretches out"
    # Any clipping is significant; the score grows with the clipped fraction (1 at 0.1 %).
    score = max(worst / 1e-3, 1.0) if significant else 0.0
    return finding("clipping", significant, score,
                   {"fraction": worst, "channel": where, "levels_fs": list(levels),
                    "excluded_s": sum(b - a for spans in excluded.values() for a, b in spans)},
                   explanation,
                   "refine --add clipping (leaves the clipped stretches out of identification and validation); "
                   "better, re-record with 3-6 dB less gain on that channel" if significant else "none",
                   {"fractions": list(fractions.values()), "excluded": excluded})
