"""Where the model fails on the sweeps: prediction, error against the noise floor, residual tests.

The functions read a ``sysid.validation.compare.Comparison`` (or one of its ``per_sweep`` records)
and the noise recording's ``Spectra``; they compute nothing the comparison has not.
"""

from __future__ import annotations

import numpy as np

from sysid.core.thresholds import IDENTIFICATION_BAND
from sysid.estimation.spectra import Spectra, response

from .signals import instantaneous_frequency, min_max_envelope, worst_window
from .style import COLORS, db, log_frequency_axis, new_figure

__all__ = ["coherence_figure", "error_bands_figure", "residual_correlation_figure", "sweep_prediction_figure"]


def _frequency_axis(ax, t: np.ndarray, frequency: np.ndarray):
    """A second y axis with the sweep's instantaneous frequency (Hz, log) over time t."""
    twin = ax.twinx()
    step = max(1, t.size // 4000)
    twin.plot(t[::step], frequency[::step], color=COLORS["frequency"], lw=1.0, ls="--")
    twin.set_ylabel("sweep frequency (Hz)", color=COLORS["frequency"])
    twin.tick_params(axis="y", colors=COLORS["frequency"])
    finite = frequency[np.isfinite(frequency) & (frequency > 0)]
    if finite.size:
        # Percentiles keep the fade-in and fade-out (where the estimate is poor) from setting the scale.
        low, high = np.percentile(finite, [1, 99])
        twin.set_yscale("log")
        twin.set_ylim(max(low / 1.5, 1.0), high * 1.5)
    return twin


def sweep_prediction_figure(record: dict, zoom_s: float = 0.02, dpi: float = 100.0):
    """Measured vs predicted ear signal on one sweep, the error alone, and a zoom where the error peaks.

    ``record`` is one ``Comparison.per_sweep`` entry (keys path, u, measured, linear, predicted,
    residual, fs). In the upper two panels the dashed brown curve (right axis) is the
    sweep's instantaneous frequency, so a burst of error reads as a frequency; in the
    zoom the error has its own scale on the right axis.
    """
    fs = float(record["fs"])
    measured, predicted, residual = (np.asarray(record[k], dtype=float) for k in ("measured", "predicted", "residual"))
    t = np.arange(measured.size) / fs
    frequency = instantaneous_frequency(np.asarray(record["u"], dtype=float), fs)
    start, stop = worst_window(residual, fs, zoom_s)
    zoom = slice(start, stop)
    figure, axes = new_figure(3, 1, height=2.3, dpi=dpi)
    axes[0].plot(*min_max_envelope(t, measured), color=COLORS["measured"], lw=0.8, label="measured")
    axes[0].plot(*min_max_envelope(t, predicted), color=COLORS["model"], lw=0.5, label="predicted")
    axes[0].set_ylabel("ear signal (FS)")
    axes[1].plot(*min_max_envelope(t, residual), color="black", lw=0.5)
    axes[1].set_ylabel("error (FS)")
    for ax in axes[:2]:
        ax.set_xlim(t[0], t[-1])
        ax.grid(True, alpha=0.3)
        ax.axvspan(t[start], t[stop - 1], color=COLORS["highlight"], alpha=0.5)
        _frequency_axis(ax, t, frequency)
    axes[0].legend(fontsize=7, loc="upper left")
    axes[2].plot(t[zoom], measured[zoom], color=COLORS["measured"], lw=1.6, label="measured")
    axes[2].plot(t[zoom], predicted[zoom], color=COLORS["model"], lw=0.9, label="predicted")
    axes[2].set_ylabel("ear signal (FS)")
    axes[2].set_xlim(t[start], t[stop - 1])
    axes[2].grid(True, alpha=0.3)
    error_axis = axes[2].twinx()
    error_axis.plot(t[zoom], residual[zoom], color="black", lw=0.8, label="error (right axis)")
    error_axis.set_ylabel("error (FS)")
    axes[2].legend(handles=axes[2].get_lines() + error_axis.get_lines(), fontsize=7, loc="upper left")
    axes[2].set_xlabel("time (s)")
    centre = frequency[(start + stop) // 2]
    at = f", sweep at {centre:.0f} Hz" if np.isfinite(centre) else ""
    axes[0].set_title(f"{record['path']}: whole sweep (shaded: the zoom below, largest error)", fontsize=9)
    axes[1].set_title("error = measured - predicted", fontsize=9)
    axes[2].set_title(f"zoom: {1e3 * zoom_s:g} ms around {t[(start + stop) // 2]:.3f} s{at}", fontsize=9)
    return figure


def _band_steps(bands: list[dict], key: str) -> tuple[np.ndarray, np.ndarray]:
    """Edges and values for a step curve over third-octave bands."""
    edges = np.array([b["low_hz"] for b in bands] + [bands[-1]["high_hz"]])
    values = np.array([b[key] for b in bands], dtype=float)
    return edges, np.append(values, values[-1])


def error_bands_figure(comparison, dpi: float = 100.0):
    """Error RMS per third-octave band against the noise floor in the same band (dB FS), and their ratio.

    Bands where the error is more than twice the noise (6 dB) are shaded: that is what
    the model misses; elsewhere the data cannot show a better model.
    """
    bands = comparison.bands
    figure, axes = new_figure(2, 1, height=2.5, sharex=True, dpi=dpi)
    edges, error = _band_steps(bands, "error_rms")
    _, noise = _band_steps(bands, "noise_rms")
    axes[0].step(edges, db(error), where="post", color="black", lw=1.2, label="model error")
    axes[0].step(edges, db(noise), where="post", color=COLORS["noise_floor"], lw=1.2, label="noise floor (repeat difference)")
    _, ratio = _band_steps(bands, "ratio")
    axes[1].step(edges, db(ratio), where="post", color="black", lw=1.2)
    axes[1].axhline(0, color=COLORS["noise_floor"], lw=1.0)
    axes[1].axhline(db(2.0), color=COLORS["noise_floor"], lw=0.8, ls="--", label="2x noise (6 dB)")
    for b in bands:
        if b["ratio"] > 2.0:
            for ax in axes:
                ax.axvspan(b["low_hz"], b["high_hz"], color=COLORS["highlight"], alpha=0.3, lw=0)
    axes[0].set_ylabel("RMS in band (dB FS)")
    axes[1].set_ylabel("error / noise (dB)")
    for ax in axes:
        log_frequency_axis(ax, (edges[0], edges[-1]), label=ax is axes[-1])
    axes[0].legend(fontsize=7, loc="upper left")
    axes[1].legend(fontsize=7, loc="upper left")
    axes[0].set_title(f"Error spectrum vs noise floor: rms {comparison.rms:.3g} FS = "
                      f"{comparison.rms / comparison.noise_floor:.3g}x floor, fit {comparison.fit_percent:.1f} %", fontsize=9)
    return figure


def _stems(ax, lags, values, bound) -> None:
    bound = np.broadcast_to(np.asarray(bound, dtype=float), np.shape(values))
    outside = np.abs(values) > bound
    ax.vlines(lags, 0, values, color="0.3", lw=1.2)
    ax.plot(lags[~outside], values[~outside], "o", color="0.3", ms=3)
    ax.plot(lags[outside], values[outside], "o", color=COLORS["model"], ms=4, label="outside the 99 % bound")
    ax.fill_between(lags, -bound, bound, color=COLORS["bound"], alpha=0.15, step="mid", label="99 % bound")
    ax.axhline(0, color="0.6", lw=0.5)
    ax.grid(True, alpha=0.3)
    ax.legend(fontsize=7, loc="upper right")


def residual_correlation_figure(comparison, dpi: float = 100.0):
    """Ljung's residual tests: autocorrelation of the error, and error-input cross-correlation.

    Lag 0 of the autocorrelation is 1 by definition. Points outside the band mean the
    error is not white (unmodelled dynamics or noise colour) or still correlates with
    the input (the model misses part of the path); a peak at a positive lag k is
    input from k samples ago that the model does not pass on, e.g. a missing delay.
    """
    figure, axes = new_figure(2, 1, height=2.4, dpi=dpi)
    lags = np.asarray(comparison.lags)
    _stems(axes[0], lags[1:], np.asarray(comparison.residual_autocorrelation)[1:], comparison.autocorrelation_bound)
    axes[0].set_xlabel("lag k (samples)")
    axes[0].set_ylabel("r_e(k) / r_e(0)")
    axes[0].set_title("Autocorrelation of the sweep error (lag 0 = 1 omitted)", fontsize=9)
    cross = np.asarray(comparison.cross_lags)
    _stems(axes[1], cross, np.asarray(comparison.residual_input_crosscorrelation), comparison.crosscorrelation_bound)
    axes[1].set_xlabel("lag k (samples; positive = input earlier than the error)")
    axes[1].set_ylabel("normalised r_eu(k)")
    axes[1].set_title("Cross-correlation of the error with the input", fontsize=9)
    return figure


def coherence_figure(spectra: Spectra, band=IDENTIFICATION_BAND, dpi: float = 100.0):
    """Squared coherence of the noise recording and the H1/H2 ratio in dB.

    Coherence 1 means the ear signal is a linear function of the input; it drops with
    output noise, nonlinearity or input noise. H1/H2 = coherence for an H1 estimate, so
    a ratio well below 0 dB where the output is loud points at input noise (errors in
    variables: H1 is then biased low).
    """
    frf = response(spectra, band)
    figure, axes = new_figure(2, 1, height=2.3, sharex=True, dpi=dpi)
    axes[0].plot(frf.frequencies, frf.coherence, color=COLORS["smoothed"], lw=0.8)
    axes[0].set_ylim(0, 1.05)
    axes[0].set_ylabel("coherence^2")
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = db(frf.g / frf.h2)
    axes[1].plot(frf.frequencies, ratio, color="black", lw=0.8)
    axes[1].axhline(0, color="0.6", lw=0.5)
    axes[1].set_ylabel("|H1 / H2| (dB)")
    for ax in axes:
        log_frequency_axis(ax, band, label=ax is axes[-1])
    axes[0].set_title(f"Coherence of the noise recording ({spectra.segments} averaged segments)", fontsize=9)
    return figure
