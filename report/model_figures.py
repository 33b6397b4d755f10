"""Figures of the final model, as in the seed's figures 4.1-4.6: Bode, pole-zero map, impulse response."""

from __future__ import annotations

import numpy as np

from sysid.core.thresholds import IDENTIFICATION_BAND, TRANSIENT_S
from sysid.estimation.spectra import Spectra, response, smoothed_response

from .style import COLORS, db, log_frequency_axis, new_figure, phase_on_branch

__all__ = ["impulse_response", "impulse_response_figure", "model_bode_figure", "pole_zero_figure", "transient_decay_db"]


def model_bode_figure(model, spectra: Spectra, gamma: int | None = None, band=IDENTIFICATION_BAND,
                      seed_model=None, dpi: float = 100.0):
    """Seed figures 4.1/4.4: the model's Bode plot over the noisy and smoothed estimates.

    The model phase is unwrapped on a 2.5 Hz grid (fine enough for the helmet's
    modes); the estimates are drawn on the model's 360-degree branch, which unwraps
    them wherever they are close to the model and leaves the noise visible elsewhere.
    ``seed_model`` (the seed grid's choice, before refinement) is drawn dashed.
    """
    f_model = np.linspace(band[0], band[1], int((band[1] - band[0]) / 2.5) + 1)
    g_model = model.frequency_response(f_model)
    phase_model = np.degrees(np.unwrap(np.angle(g_model)))
    figure, axes = new_figure(2, 1, height=2.8, sharex=True, dpi=dpi)
    estimates = [("non-smoothed estimate", response(spectra, band), COLORS["measured"], 0.7)]
    if gamma is not None and int(gamma) <= spectra.nperseg // 2:
        estimates.append((f"smoothed, gamma = {int(gamma)}", smoothed_response(spectra, int(gamma), band), COLORS["smoothed"], 1.0))
    for label, frf, color, width in estimates:
        reference = np.interp(frf.frequencies, f_model, phase_model)
        axes[0].plot(frf.frequencies, db(frf.g), color=color, lw=width, label=label)
        axes[1].plot(frf.frequencies, phase_on_branch(frf.g, reference), color=color, lw=width)
    if seed_model is not None:
        g_seed = seed_model.frequency_response(f_model)
        seed_phase = phase_on_branch(g_seed, phase_model)
        axes[0].plot(f_model, db(g_seed), color=COLORS["seed"], ls="--", lw=1.0, label=f"seed grid choice, n = {seed_model.order}")
        axes[1].plot(f_model, seed_phase, color=COLORS["seed"], ls="--", lw=1.0)
    axes[0].plot(f_model, db(g_model), color=COLORS["model"], lw=1.0, label=f"model, n = {model.order}, delay {model.delay}")
    axes[1].plot(f_model, phase_model, color=COLORS["model"], lw=1.0)
    if model.uncertainty is not None:
        # 95 % band |H| (1 +- relative_95) (sysid.estimation.uncertainty); a bound of 100 % or more reaches -60 dB re |H|.
        f_band = np.asarray(model.uncertainty["frequencies_hz"])
        inside = (f_band >= band[0]) & (f_band <= band[1])
        relative = np.asarray(model.uncertainty["relative_95"])[inside]
        magnitude = np.abs(model.frequency_response(f_band[inside]))
        axes[0].fill_between(f_band[inside], db(magnitude * np.maximum(1 - relative, 1e-3)), db(magnitude * (1 + relative)),
                             color=COLORS["model"], alpha=0.25, lw=0, label="model 95 % band")
    axes[0].set_ylabel("magnitude (dB)")
    axes[1].set_ylabel("phase (deg, unwrapped)")
    for ax in axes:
        log_frequency_axis(ax, band, label=ax is axes[-1])
    axes[0].legend(fontsize=7, loc="lower left")
    axes[0].set_title(f"{model.path.upper()} model over the estimates (seed figs. 4.1/4.4)", fontsize=9)
    return figure


def _draw_roots(ax, model) -> None:
    poles, zeros = model.poles(), model.zeros()
    circle = np.exp(1j * np.linspace(0, 2 * np.pi, 721))
    ax.plot(circle.real, circle.imag, color="0.4", lw=0.8)
    ax.axhline(0, color="0.8", lw=0.5)
    ax.axvline(0, color="0.8", lw=0.5)
    ax.plot(poles.real, poles.imag, "x", color=COLORS["model"], ms=8, mew=1.5, label="poles")
    minimum = np.abs(zeros) <= 1.0
    ax.plot(zeros[minimum].real, zeros[minimum].imag, "o", mfc="none", mec="tab:blue", ms=7, label="zeros")
    if np.any(~minimum):
        ax.plot(zeros[~minimum].real, zeros[~minimum].imag, "o", color="tab:red", ms=7, alpha=0.7,
                label="non-minimum-phase zeros (|z| > 1)")
    ax.set_aspect("equal")
    ax.grid(True, alpha=0.3)
    ax.set_xlabel("Re z")


def pole_zero_figure(model, dpi: float = 100.0):
    """Seed figures 4.2/4.5: poles (x) and zeros (o) with the unit circle; a zoom near z = 1.

    Zeros outside the unit circle (non-minimum phase) are filled red. The zoom shows the
    poles close to z = 1 (the audio band at 44.1 kHz), each labelled with its frequency
    in Hz, angle(p) fs / (2 pi).
    """
    figure, axes = new_figure(1, 2, height=4.0, dpi=dpi)
    roots = np.concatenate([model.poles(), model.zeros()])
    for ax in axes:
        _draw_roots(ax, model)
    extent = max(1.15, 1.05 * float(np.max(np.abs(roots)))) if roots.size else 1.15
    axes[0].set_xlim(-extent, extent)
    axes[0].set_ylim(-extent, extent)
    axes[0].set_ylabel("Im z")
    axes[0].legend(fontsize=7, loc="lower left")
    near = roots[np.abs(roots - 1.0) < 0.5]
    if near.size:
        half = max(0.02, 1.2 * float(np.max(np.abs(near - 1.0))))
        axes[1].set_xlim(1.0 - half, 1.0 + half)
        axes[1].set_ylim(-half, half)
        for p in model.poles():
            if p.imag > 0 and abs(p - 1.0) < half:
                axes[1].annotate(f"{np.angle(p) * model.fs / (2 * np.pi):.0f} Hz", (p.real, p.imag), fontsize=7,
                                 xytext=(4, 4), textcoords="offset points")
    axes[1].set_title("zoom near z = 1", fontsize=8)
    axes[0].set_title(f"{model.path.upper()} poles and zeros; largest pole radius {model.spectral_radius:.5f}", fontsize=9)
    return figure


def impulse_response(model, seconds: float) -> np.ndarray:
    """The model's impulse response over ``seconds`` (s), delay included, in FS per unit impulse."""
    n = max(2, round(seconds * model.fs))
    impulse = np.zeros(n)
    impulse[0] = 1.0
    return model.simulate(impulse)


# Below this the response is zero to double precision (2^-52 relative is -313 dB): a figure
# such as "-6401 dB" is rounding noise, not a decay.
NUMERICAL_FLOOR_DB = -300.0


def decay_label(decay_db: float) -> str:
    """A decay in words: '72 dB below its peak', or 'more than 300 dB below its peak' at the numerical floor."""
    if not decay_db > NUMERICAL_FLOOR_DB:
        return f"more than {-NUMERICAL_FLOOR_DB:.0f} dB below its peak"
    return f"{-decay_db:.0f} dB below its peak" if decay_db <= 0 else f"{decay_db:.0f} dB above its peak"


def transient_decay_db(model, transient_s: float = TRANSIENT_S, response: np.ndarray | None = None) -> float:
    """Envelope of the impulse response at transient_s (s), in dB relative to its peak.

    The envelope is the largest |h| in the 10 ms ending at transient_s; the
    identification drops the first transient_s of the noise recording, which is
    justified when this is far below the ear channel's noise (e.g. < -60 dB).
    """
    h = impulse_response(model, transient_s) if response is None else response
    end = min(h.size, round(transient_s * model.fs))
    window = h[max(0, end - int(0.01 * model.fs)):end]
    peak = float(np.max(np.abs(h)))
    if peak == 0.0:
        return -np.inf
    return float(db(np.max(np.abs(window)) / peak))


def impulse_response_figure(model, transient_s: float = TRANSIENT_S, short_ms: float = 5.0, dpi: float = 100.0):
    """Seed figures 4.3/4.6: short-term impulse response, and the long-term decay in dB.

    The long-term panel draws 20 log10 |h| relative to the peak up to 1.2 transient_s,
    the pole-radius bound r^k (the slowest mode) and the level at transient_s.
    """
    long = impulse_response(model, 1.2 * transient_s)
    t = np.arange(long.size) / model.fs
    short = round(short_ms * 1e-3 * model.fs)
    figure, axes = new_figure(1, 2, height=3.2, dpi=dpi)
    axes[0].plot(1e3 * t[:short], long[:short], color=COLORS["model"], lw=1.0, marker=".", ms=2)
    axes[0].axhline(0, color="0.6", lw=0.5)
    axes[0].set_xlabel("time (ms)")
    axes[0].set_ylabel("h(t) (FS per unit impulse)")
    axes[0].set_title(f"first {short_ms:g} ms", fontsize=9)
    axes[0].grid(True, alpha=0.3)
    peak = float(np.max(np.abs(long)))
    level = db(long / peak) if peak > 0 else np.full(long.size, -np.inf)
    step = max(1, long.size // 4000)
    # Envelope per block so the decay reads as a band, not as 150 000 oscillations.
    blocks = level[: (level.size // step) * step].reshape(-1, step).max(axis=1)
    axes[1].plot(t[: blocks.size * step: step], blocks, color=COLORS["model"], lw=0.8, label="|h| (envelope)")
    radius = model.spectral_radius
    if 0 < radius < 1:
        axes[1].plot(t, np.arange(t.size) * 20 * np.log10(radius), color=COLORS["bound"], ls="--", lw=1.0,
                     label=f"slowest mode r^k, r = {radius:.5f}")
    decay = transient_decay_db(model, transient_s, long)
    axes[1].axvline(transient_s, color="0.3", ls=":", lw=1.0)
    shown = max(decay, NUMERICAL_FLOOR_DB)
    axes[1].annotate(f"{shown:.0f} dB at {transient_s:g} s", (transient_s, shown), fontsize=8, xytext=(-90, 12),
                     textcoords="offset points", arrowprops={"arrowstyle": "->", "lw": 0.6})
    finite = blocks[np.isfinite(blocks)]
    axes[1].set_ylim(max(-320.0, float(finite.min()) - 10 if finite.size else -200.0), 5)
    axes[1].set_xlabel("time (s)")
    axes[1].set_ylabel("|h| re peak (dB)")
    axes[1].set_title(f"long term: is the transient gone after {transient_s:g} s?", fontsize=9)
    axes[1].grid(True, alpha=0.3)
    axes[1].legend(fontsize=7, loc="upper right")
    return figure
