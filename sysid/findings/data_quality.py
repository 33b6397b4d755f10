"""Data-quality findings straight from the recordings: DC offset and clipping (effects.md).

Neither is a property of the sound path, so neither is refined into the model:
the pipeline already removes block means (and validates in band, which excludes
DC), and clipped stretches cannot be modelled by a linear path; the remedy is on
the recording side.
"""

from __future__ import annotations

import numpy as np

from . import DiagnosisContext, finding

__all__ = ["dc_offset_finding", "clipping_finding"]

# As in sysid.recordings: a mean above 2 % of the channel's RMS and above a few LSB.
DC_RELATIVE = 0.02
DC_ABSOLUTE = 1e-4
# 16-bit rails in full-scale units; fewer rail samples than this are legitimate peaks.
RAILS = (-1.0, 32767 / 32768.0)
CLIP_MIN_SAMPLES = 3
# The first 20 ms of a sweep recording count as silence when the input there is 40 dB down.
LEAD_S = 0.02
SILENT = 0.01


def _recordings(ctx: DiagnosisContext):
    return [ctx.noise, *ctx.sweeps]


def dc_offset_finding(ctx: DiagnosisContext) -> dict:
    """Means of the input channels, and of the ear channels where the input is silent.

    The noise excitation is zero-mean, so an input mean is an offset. An ear signal
    may have a genuine mean (a path with large DC gain driven by a finite sweep), so
    the ear offset is read in the silence before a sweep (``LEAD_S``), where the path
    is at rest; sweeps without such silence are not used for it.
    """
    worst, where, level = 0.0, "", 0.0
    offsets = {}
    body = ctx.body
    channels = [(body.path, "input", float(np.mean(body.u)), float(np.std(body.u)))]
    channels += [(s.path, "input", float(np.mean(s.u)), float(np.std(s.u))) for s in ctx.sweeps]
    lead = int(round(LEAD_S * ctx.fs))
    for s in ctx.sweeps:
        if np.sqrt(np.mean(s.u[:lead] ** 2)) < SILENT * np.std(s.u):
            channels.append((s.path, "ear", float(np.mean(s.y[:lead])), float(np.std(s.y))))
    for path, label, mean, spread in channels:
        relative = abs(mean) / max(DC_RELATIVE * spread, DC_ABSOLUTE)
        offsets[f"{path}:{label}"] = mean
        if relative > worst:
            worst, where, level = relative, f"{label} channel of {path}", mean
    significant = worst >= 1.0
    explanation = (f"the {where} has a mean of {level:.3g} FS: a preamplifier offset or microphone bias; "
                   "the identification removes block means and validates in band, so the model is not affected"
                   if significant else "no channel has a DC offset above 2 % of its RMS")
    return finding("dc-offset", significant, worst, {"offset_fs": level, "channel": where}, explanation,
                   "remove the offset at the source (AC-couple the preamplifier); no model change is needed",
                   {"means_fs": [round(v, 8) for v in offsets.values()]})


def clipping_finding(ctx: DiagnosisContext) -> dict:
    worst, where = 0.0, ""
    fractions = {}
    for recording in _recordings(ctx):
        for label, x in (("input", recording.u), ("ear", recording.y)):
            count = int(np.count_nonzero((x <= RAILS[0]) | (x >= RAILS[1])))
            fraction = count / x.size if count >= CLIP_MIN_SAMPLES else 0.0
            fractions[f"{recording.path}:{label}"] = fraction
            if fraction > worst:
                worst, where = fraction, f"{label} channel of {recording.path}"
    significant = worst > 0.0
    explanation = (f"{100 * worst:.3g} % of the samples of the {where} sit at full scale: the converter or amplifier "
                   "clipped, and no linear model explains those stretches"
                   if significant else "no channel reaches full scale")
    # Any clipping is significant; the score grows with the clipped fraction (1 at 0.1 %).
    score = max(worst / 1e-3, 1.0) if significant else 0.0
    return finding("clipping", significant, score, {"fraction": worst, "channel": where}, explanation,
                   "re-record with 3-6 dB less gain on that channel; no model change can undo clipping",
                   {"fractions": list(fractions.values())})
