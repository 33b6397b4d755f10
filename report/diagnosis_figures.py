"""Evidence of each diagnosis finding, and the error falling through the refinement history.

``finding_figure`` picks the plot that shows a finding's evidence from the figure kind
its effect names in the registry (``sysid.effects``); an effect without a dedicated plot gets the model's
frequency-response mismatch against the measurement, with the finding's frequencies
marked. ``refinement_figure`` draws ``model.history`` as a staircase.

A plot runs no detector: what a detector computed it reads from the diagnosis's context
as the shared value the detector read (``DiagnosisContext.value``: ``"delay-scan"``, the
delay scan's costs; ``"segments"``, the noise recording's per-segment responses), so a
figure shows the numbers its finding was decided on.
"""

from __future__ import annotations

from collections.abc import Mapping

import numpy as np
import scipy.signal

from sysid import effects as registry
from sysid.core import structures
from sysid.core.thresholds import IDENTIFICATION_BAND
from sysid.estimation.spectra import Spectra, response
from sysid.findings import DiagnosisContext

from .signals import instantaneous_frequency
from .style import COLORS, db, log_frequency_axis, new_figure

__all__ = ["FINDING_PLOTS", "FIGURE_KINDS", "finding_figure", "refinement_figure"]

_BAND = IDENTIFICATION_BAND


def _title(ax, finding: dict) -> None:
    state = "significant" if finding["significant"] else "not significant"
    ax.set_title(f"{finding['effect']} ({state}, score {finding['score']:.2f})", fontsize=9)


def _mark_frequencies(axes, frequencies, annotate: bool = False) -> None:
    """Dashed vertical lines at frequencies (Hz) on every axis, labelled on the first if asked."""
    for frequency in frequencies:
        for ax in axes:
            ax.axvline(frequency, color=COLORS["model"], ls="--", lw=0.8)
        if annotate:
            axes[0].annotate(f"{frequency:.1f} Hz", (frequency, 1.0), xycoords=("data", "axes fraction"), fontsize=7,
                             rotation=90, va="top", ha="right")


def _finish_frequency_axes(axes, finding: dict) -> None:
    """Log frequency axes over the identification band, the finding's title on the first."""
    for ax in axes:
        log_frequency_axis(ax, _BAND, label=ax is axes[-1])
    _title(axes[0], finding)


def _delay(ctx: DiagnosisContext, spectra: Spectra, finding: dict, dpi: float):
    """Fixed-pole fit cost against the total delay, and the phase of measurement over model with the delay line.

    The costs are the delay scan's (the shared value ``"delay-scan"``: the best total delay and the
    cost per total delay 0..delay + ``MAX_EXTRA_DELAY``, NaN where the scan did not evaluate it).
    """
    best, costs = ctx.value("delay-scan")
    figure, axes = new_figure(1, 2, height=3.2, dpi=dpi)
    delays = np.flatnonzero(np.isfinite(costs))
    axes[0].semilogy(delays, costs[delays] / costs[delays].min(), ".-", color="black", lw=1.0, ms=3)
    axes[0].axvline(ctx.model.delay, color=COLORS["model"], ls="--", lw=1.0, label=f"model's delay {ctx.model.delay}")
    axes[0].plot(best, 1.0, "*", color=COLORS["seed"], ms=12, label=f"best total delay {best}")
    axes[0].set_xlabel("total delay (samples)")
    axes[0].set_ylabel("fit cost / minimum (poles fixed)")
    axes[0].grid(True, which="both", alpha=0.3)
    axes[0].legend(fontsize=7)
    _title(axes[0], finding)
    frf = response(spectra, _BAND)
    f = frf.frequencies
    # What the model misses: the phase of measurement over model, unwrapped over the band.
    missing = np.degrees(np.unwrap(np.angle(frf.g / ctx.model.frequency_response(f))))
    missing -= 360.0 * np.round(missing[0] / 360.0)
    reliable = frf.coherence > 0.9
    extra = best - ctx.model.delay
    line = -360.0 * f * extra / ctx.model.fs
    offset = 360.0 * np.round(np.median(missing[reliable] - line[reliable]) / 360.0) if np.any(reliable) else 0.0
    axes[1].plot(f[reliable], missing[reliable], ".", color="0.35", ms=3,
                 label="phase of measured / model (coherence > 0.9)")
    axes[1].plot(f, line + offset, color=COLORS["model"], lw=1.0, ls="--",
                 label=f"{extra} more sample(s) of delay: -360 f d / fs")
    axes[1].set_xlabel("frequency (Hz)")
    axes[1].set_ylabel("excess phase (deg)")
    axes[1].grid(True, alpha=0.3)
    axes[1].legend(fontsize=7, loc="lower left")
    axes[1].set_title("phase the model misses, and the delay line", fontsize=9)
    return figure


def _nonlinearity(ctx: DiagnosisContext, spectra: Spectra, finding: dict, dpi: float):
    """Spectrogram of the first sweep's error with the sweep's 1st, 2nd and 3rd harmonic traced; below it, on
    exponential sweeps, the harmonic levels measured by Farina's separation against the model's (the finding's)."""
    record = ctx.comparison.per_sweep[0]
    fs = float(record["fs"])
    residual = np.asarray(record["residual"], dtype=float)
    nperseg = 2048
    f, t, power = scipy.signal.spectrogram(residual, fs, nperseg=nperseg, noverlap=nperseg * 3 // 4)
    evidence, params = finding.get("evidence", {}), finding["params"]
    measured = "harmonic_frequencies_hz" in evidence
    figure, axes = new_figure(2 if measured else 1, 1, height=3.6 if not measured else 3.0, dpi=dpi)
    ax = axes[0]
    keep = f <= 3 * 4000.0
    levels = 10 * np.log10(power[keep] + 1e-30)
    top = float(np.max(levels))
    ax.pcolormesh(t, f[keep], levels, shading="auto", cmap="magma", vmin=top - 80, vmax=top, rasterized=True)
    inst = instantaneous_frequency(record["u"], fs)
    time = np.arange(inst.size) / fs
    for k, style in zip((1, 2, 3), ("-", "--", ":")):
        ax.plot(time, k * inst, color="cyan", ls=style, lw=0.8, alpha=0.6, label=f"{k} x sweep frequency")
    ax.set_yscale("log")
    ax.set_ylim(20, f[keep][-1])
    ax.set_xlabel("time (s)")
    ax.set_ylabel("frequency (Hz)")
    ax.legend(fontsize=7, loc="lower right")
    _title(ax, finding)
    if measured:
        ax = axes[1]
        frequencies = np.asarray(evidence["harmonic_frequencies_hz"], dtype=float)
        for k, color in ((2, COLORS["measured"]), (3, COLORS["model"])):
            ax.semilogx(frequencies, evidence[f"measured_h{k}_curve_db"], color=color, lw=1.2,
                        label=f"H{k} measured (sweep, Farina): {params[f'measured_h{k}_db']:.1f} dB")
            ax.axhline(params[f"model_h{k}_db"], color=color, ls="--", lw=0.9,
                       label=f"H{k} of the model: {params[f'model_h{k}_db']:.1f} dB")
        ax.set_xlabel("sweep frequency (Hz)")
        ax.set_ylabel(f"dB re fundamental at {params['sweep_amplitude_fs']:.3g} FS")
        ax.set_ylim(-90, 0)
        ax.legend(fontsize=7, loc="lower left")
    return figure


def _disturbance(ctx: DiagnosisContext, spectra: Spectra, finding: dict, dpi: float):
    """Spectrum of the model's error on the noise recording with the found lines marked; input spectrum below."""
    body = ctx.body
    residual = body.y - ctx.model.simulate(body.u)
    nperseg = int(min(body.u.size, 2 * body.fs))
    f, s_ee = scipy.signal.welch(residual, body.fs, nperseg=nperseg)
    _, s_uu = scipy.signal.welch(body.u, body.fs, nperseg=nperseg)
    figure, axes = new_figure(2, 1, height=2.4, sharex=True, dpi=dpi)
    inside = (f >= _BAND[0]) & (f <= _BAND[1])
    axes[0].plot(f[inside], 10 * np.log10(s_ee[inside] + 1e-30), color="black", lw=0.6)
    axes[1].plot(f[inside], 10 * np.log10(s_uu[inside] + 1e-30), color=COLORS["measured"], lw=0.6)
    _mark_frequencies(axes, finding["params"].get("frequencies_hz") or [], annotate=True)
    axes[0].set_ylabel("error PSD (dB FS^2/Hz)")
    axes[1].set_ylabel("input PSD (dB FS^2/Hz)")
    _finish_frequency_axes(axes, finding)
    return figure


def _input_noise(ctx: DiagnosisContext, spectra: Spectra, finding: dict, dpi: float):
    """H1 and H2 magnitudes: they disagree where the input channel carries noise."""
    frf = response(spectra, _BAND)
    figure, (ax,) = new_figure(1, 1, height=3.0, dpi=dpi)
    ax.plot(frf.frequencies, db(frf.g), color=COLORS["smoothed"], lw=0.8, label="H1 = S_yu / S_uu (biased low)")
    ax.plot(frf.frequencies, db(frf.h2), color=COLORS["seed"], lw=0.8, label="H2 = S_yy / S_uy (biased high)")
    ax.plot(frf.frequencies, db(ctx.model.frequency_response(frf.frequencies)), color=COLORS["model"], lw=1.2, label="model")
    ax.set_ylabel("magnitude (dB)")
    log_frequency_axis(ax, _BAND)
    ax.legend(fontsize=7, loc="lower left")
    _title(ax, finding)
    return figure


def _variation(ctx: DiagnosisContext, spectra: Spectra, finding: dict, dpi: float):
    """Magnitude of the H1 estimate of each segment of the noise recording, and each segment's delay (the
    shared value ``"segments"`` the clock-drift and time-variation detectors read)."""
    f, responses, _, centres = ctx.value("segments")[:4]
    figure, axes = new_figure(1, 2, height=3.2, dpi=dpi)
    inside = (f >= _BAND[0]) & (f <= _BAND[1])
    colours = [(0.1 + 0.8 * k / max(len(responses) - 1, 1), 0.3, 0.6) for k in range(len(responses))]
    for k, (h, colour) in enumerate(zip(responses, colours)):
        axes[0].plot(f[inside], db(h[inside]), color=colour, lw=0.7, label=f"segment {k + 1}" if k in (0, len(responses) - 1) else None)
    axes[0].set_ylabel("magnitude (dB)")
    log_frequency_axis(axes[0], _BAND)
    axes[0].legend(fontsize=7)
    _title(axes[0], finding)
    delays = finding.get("evidence", {}).get("segment_delays")
    if delays:
        seconds = np.asarray(centres[: len(delays)], dtype=float) / ctx.fs
        axes[1].plot(seconds, delays, "o-", color="black", ms=4)
        ppm = finding["params"].get("ppm")
        if ppm is not None:
            # ppm = -1e6 d(delay)/d(sample) (sysid.findings.variation); the line passes through the means.
            samples = seconds * ctx.fs
            line = np.mean(delays) - 1e-6 * ppm * (samples - samples.mean())
            axes[1].plot(seconds, line, color=COLORS["model"], lw=1.0, label=f"drift {ppm:.2f} ppm")
            axes[1].legend(fontsize=7)
        axes[1].set_xlabel("segment centre (s after transient)")
        axes[1].set_ylabel("delay re segment 1 (samples)")
    else:
        ratio = db(responses[-1][inside] / responses[0][inside])
        axes[1].plot(f[inside], ratio, color="black", lw=0.7)
        axes[1].set_ylabel("last / first segment (dB)")
        log_frequency_axis(axes[1], _BAND)
    axes[1].grid(True, alpha=0.3)
    return figure


def _recording_levels(ctx: DiagnosisContext, spectra: Spectra, finding: dict, dpi: float):
    """Per-channel values a data-quality finding rests on (means or clipped fractions), as bars."""
    values = next((v for v in finding.get("evidence", {}).values() if isinstance(v, list)), [])
    recordings = [ctx.noise, *ctx.sweeps]
    labels = [f"{r.path}\n{c}" for r in recordings for c in ("input", "ear")]
    if finding["effect"] == "dc-offset" and len(values) == 2 + len(ctx.sweeps):
        labels = [f"{ctx.noise.path}\ninput", f"{ctx.noise.path}\near"] + [f"{s.path}\ninput" for s in ctx.sweeps]
    figure, (ax,) = new_figure(1, 1, height=2.8, dpi=dpi)
    positions = np.arange(len(values))
    ax.bar(positions, values, color=COLORS["measured"])
    ax.set_xticks(positions, labels[: len(values)] if len(labels) >= len(values) else [str(p) for p in positions], fontsize=7)
    ax.axhline(0, color="0.4", lw=0.5)
    ax.set_ylabel("mean (FS)" if finding["effect"] == "dc-offset" else "fraction of samples")
    ax.grid(True, axis="y", alpha=0.3)
    _title(ax, finding)
    return figure


def _mismatch(ctx: DiagnosisContext, spectra: Spectra, finding: dict, dpi: float):
    """Measured / model response (magnitude in dB, phase in degrees) with the finding's frequencies marked."""
    frf = response(spectra, _BAND)
    ratio = frf.g / ctx.model.frequency_response(frf.frequencies)
    figure, axes = new_figure(2, 1, height=2.4, sharex=True, dpi=dpi)
    axes[0].plot(frf.frequencies, db(ratio), color="black", lw=0.7)
    axes[1].plot(frf.frequencies, np.angle(ratio, deg=True), ".", color="black", ms=1.5)
    _mark_frequencies(axes, [value for key, value in finding["params"].items()
                             if key.endswith("_hz") and isinstance(value, (int, float)) and _BAND[0] <= value <= _BAND[1]])
    axes[0].axhline(0, color="0.6", lw=0.5)
    axes[0].set_ylabel("|measured / model| (dB)")
    axes[1].set_ylabel("phase difference (deg)")
    _finish_frequency_axes(axes, finding)
    return figure


def _series_factor(ctx: DiagnosisContext, spectra: Spectra, finding: dict, dpi: float):
    """Measured / model response with the fitted factor's response over it (an effect with a ``factor``)."""
    figure = _mismatch(ctx, spectra, finding, dpi)
    f = np.geomspace(_BAND[0], _BAND[1], 400)
    h = structures.factor_response(*registry.get(finding["effect"]).factor(finding["params"], ctx.fs), f, ctx.fs)
    figure.axes[0].plot(f, db(h), color=COLORS["model"], lw=1.2, ls="--", label=f"fitted {finding['effect']} factor")
    figure.axes[1].plot(f, np.angle(h, deg=True), color=COLORS["model"], lw=1.2, ls="--")
    figure.axes[0].legend(fontsize=7)
    return figure


def _tail(ctx: DiagnosisContext, spectra: Spectra, finding: dict, dpi: float):
    """The noise recording's impulse-response envelope against the model's and the residual's, in dB over the
    estimate's noise, with the response's length marked (the shared value ``"long-response"``)."""
    response = ctx.value("long-response")
    t_ms = 1e3 * response.times_s
    noise = response.noise ** 2
    figure, (ax,) = new_figure(1, 1, height=3.2, dpi=dpi)
    for envelope, color, label in ((response.envelope, "black", "data (least-squares FIR)"),
                                   (response.model_envelope, COLORS["model"], f"model ({ctx.model.order} states)"),
                                   (response.residual_envelope, COLORS["seed"], "data - model")):
        ax.plot(t_ms, 10 * np.log10(np.maximum(envelope, 1e-6 * noise) / noise), color=color, lw=0.9, label=label)
    ax.axhline(0.0, color=COLORS["noise_floor"], ls="--", lw=1.0, label="the estimate's noise")
    length = 1e3 * response.length_s
    ax.axvline(length, color=COLORS["frequency"], ls=":", lw=1.2,
               label=f"above the noise for {'' if response.complete else 'at least '}{length:.1f} ms")
    if "start_ms" in finding["params"]:
        ax.axvspan(finding["params"]["start_ms"], length, color=COLORS["highlight"], alpha=0.2, label="the tail")
    ax.set_xlabel("time after the input (ms)")
    ax.set_ylabel("envelope over the noise (dB)")
    ax.set_ylim(-10.0, None)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, loc="upper right")
    _title(ax, finding)
    return figure


# The figure kinds the registry's effects name (``sysid.effects.FIGURES``).
FIGURE_KINDS = {
    "delay-scan": _delay,
    "series-factor": _series_factor,
    "harmonics": _nonlinearity,
    "lines": _disturbance,
    "h1-h2": _input_noise,
    "segments": _variation,
    "levels": _recording_levels,
    "mismatch": _mismatch,
    "tail": _tail,
}


class _FindingPlots(Mapping):
    """Effect name -> the plot of its figure kind, read live from the registry (``sysid.effects``)."""

    def _table(self) -> dict:
        return {e.name: FIGURE_KINDS[e.figure] for e in registry.effects()}

    def __getitem__(self, name):
        return self._table()[name]

    def __iter__(self):
        return iter(self._table())

    def __len__(self):
        return len(self._table())


FINDING_PLOTS = _FindingPlots()


def finding_figure(finding: dict, context: DiagnosisContext, spectra: Spectra, dpi: float = 100.0):
    """The plot that shows one finding's evidence (see ``FINDING_PLOTS``; others: the response mismatch).

    ``context`` is the ``sysid.findings.DiagnosisContext`` of the model and recordings
    (its comparison included); ``spectra`` those of the noise recording after its transient.
    """
    plot = FINDING_PLOTS.get(finding["effect"], _mismatch)
    if finding["effect"] in registry.names():
        # The detector's module provides the shared values its plot reads ("segments", "long-response"):
        # resolving the reference loads it (runs nothing) when no diagnosis has in this process.
        registry.get(finding["effect"]).detect
    return plot(context, spectra, finding, dpi)


def refinement_figure(history: list[dict], noise_floor: float, current_rms: float | None = None, dpi: float = 100.0):
    """Validation rms (FS) before and after each refinement step, as a staircase over the noise floor.

    Each step of ``history`` is a dict with "effect", "rms_before" and "rms_after" (and,
    from ``sysid.refine``, "noise_floor_before"/"noise_floor_after": removing a
    disturbance lowers the floor too); without those the floor is ``noise_floor``.
    An empty history draws ``current_rms`` alone. Labels give each level in
    multiples of its noise floor.
    """
    labels = ["identified"]
    levels = [history[0]["rms_before"] if history else current_rms]
    floors = [history[0].get("noise_floor_before", noise_floor) if history else noise_floor]
    for step in history:
        labels.append(f"+ {step['effect']}")
        levels.append(step["rms_after"])
        floors.append(step.get("noise_floor_after", noise_floor))
    levels = np.asarray([np.nan if v is None else v for v in levels], dtype=float)
    floors = np.asarray([noise_floor if v is None else v for v in floors], dtype=float)
    positions = np.arange(levels.size)
    edges = np.append(positions, positions[-1] + 1) - 0.5
    figure, (ax,) = new_figure(1, 1, height=3.0, dpi=dpi)
    ax.step(edges, np.append(levels, levels[-1]), where="post", color="black", lw=1.5)
    ax.plot(positions, levels, "o", color=COLORS["model"])
    for x, y, floor in zip(positions, levels, floors):
        if np.isfinite(y):
            ax.annotate(f"{y / floor:.2f}x", (x, y), xytext=(0, 6), textcoords="offset points", ha="center", fontsize=8)
    ax.step(edges, np.append(floors, floors[-1]), where="post", color=COLORS["noise_floor"], lw=1.2, ls="--",
            label=f"noise floor ({floors[-1]:.3g} FS now)")
    ax.set_yscale("log")
    finite = levels[np.isfinite(levels)]
    ax.set_ylim(min(finite.min(initial=floors.min()), floors.min()) / 2, max(finite.max(initial=floors.max()), floors.max()) * 2)
    ax.set_xticks(positions, labels, fontsize=8)
    ax.set_xlim(-0.6, positions[-1] + 0.6)
    ax.set_ylabel("validation rms (FS)")
    ax.grid(True, which="both", axis="y", alpha=0.3)
    ax.legend(fontsize=7, loc="upper right")
    ax.set_title("Error after each refinement step (labels: multiples of the noise floor)", fontsize=9)
    return figure
