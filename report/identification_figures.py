"""Figures of the identification steps, as in the seed's figures 3.1, 3.3/3.4 and appendices B, C.

Each function takes the data of one step (a noise recording, ``Spectra``, singular
values, a ``GridResult``) and returns a matplotlib Figure; nothing is computed here
that the pipeline does not compute itself, except where a function says so.
"""

from __future__ import annotations

import numpy as np
from matplotlib.colors import LogNorm
from matplotlib.ticker import MaxNLocator

from sysid.core.thresholds import IDENTIFICATION_BAND, TRANSIENT_S
from sysid.estimation.spectra import Spectra, response, segment_length, smoothed_response
from sysid.estimation.subspace import SubspaceDecomposition
from sysid.io.recordings import Recording

from .signals import min_max_envelope
from .style import COLORS, db, log_frequency_axis, new_figure, phase_on_branch

__all__ = [
    "DEFAULT_SMOOTHING_WIDTHS",
    "averaged_spectra_figure",
    "order_singular_values",
    "rms_heatmap_figure",
    "singular_values_figure",
    "smoothed_estimates_figure",
]

# Little, medium and a lot of smoothing (small gamma = wide frequency window).
DEFAULT_SMOOTHING_WIDTHS = (10, 50, 200, 1000)


def averaged_spectra_figure(noise: Recording, transient_s: float = TRANSIENT_S, band=IDENTIFICATION_BAND, dpi: float = 100.0):
    """Seed figure 3.1: DFT of the whole noise recording vs the mean of its segment DFTs.

    Both are scaled by 1/length (the seed's convention), so the curves are amplitudes in
    full-scale units per bin, drawn in dB FS, for the input channel and the ear channel.
    """
    body = noise.trimmed(transient_s)
    n = segment_length(body.fs)
    segments = body.u.size // n
    figure, axes = new_figure(2, 1, height=2.6, sharex=True, dpi=dpi)
    for ax, (label, x) in zip(axes, (("input channel", body.u), ("ear channel", body.y))):
        x = x[: segments * n] - np.mean(x)
        whole = np.fft.rfft(x) / x.size
        f_whole = np.fft.rfftfreq(x.size, 1.0 / body.fs)
        averaged = np.fft.rfft(x.reshape(segments, n), axis=1).mean(axis=0) / n
        f_avg = np.fft.rfftfreq(n, 1.0 / body.fs)
        keep = (f_whole >= band[0]) & (f_whole <= band[1])
        ax.plot(*min_max_envelope(f_whole[keep], db(whole[keep]), 3000), color=COLORS["noisy"], lw=0.3,
                label=f"complete recording ({x.size / body.fs:.1f} s)")
        keep = (f_avg >= band[0]) & (f_avg <= band[1])
        ax.plot(f_avg[keep], db(averaged[keep]), color=COLORS["smoothed"], lw=0.9,
                label=f"mean of {segments} segment DFTs (N = {n})")
        ax.set_ylabel(f"{label}\n|DFT| (dB FS)")
        log_frequency_axis(ax, band, label=ax is axes[-1])
        ax.legend(loc="lower left", fontsize=7)
    axes[0].set_title("Noise recording after the transient: averaged vs non-averaged DFT (seed fig. 3.1)", fontsize=9)
    return figure


def smoothed_estimates_figure(spectra: Spectra, gammas=DEFAULT_SMOOTHING_WIDTHS, band=IDENTIFICATION_BAND, dpi: float = 100.0):
    """Seed figures 3.3/3.4: Bode plot of the non-smoothed FRF and smoothed ones for several gamma.

    The least smoothed (largest gamma) curve's phase is unwrapped; the other curves are
    drawn on its 360-degree branch, so all phases share one reference.
    """
    gammas = [int(g) for g in gammas if int(g) <= spectra.nperseg // 2]
    raw = response(spectra, band)
    figure, axes = new_figure(2, 1, height=2.8, sharex=True, dpi=dpi)
    smoothed = [(g, smoothed_response(spectra, g, band)) for g in gammas]
    reference = np.degrees(np.unwrap(np.angle(smoothed[-1][1].g))) if smoothed else np.zeros(raw.g.size)
    axes[0].plot(raw.frequencies, db(raw.g), color=COLORS["noisy"], lw=0.6, label=f"non-smoothed ({spectra.estimator})")
    axes[1].plot(raw.frequencies, phase_on_branch(raw.g, reference), ".", color=COLORS["noisy"], ms=1.5)
    palette = ("tab:blue", "tab:cyan", "tab:olive", "tab:purple", "tab:pink", "tab:gray")
    for (gamma, frf), color in zip(smoothed, palette):
        axes[0].plot(frf.frequencies, db(frf.g), color=color, lw=1.0, label=f"smoothed, gamma = {gamma}")
        axes[1].plot(frf.frequencies, phase_on_branch(frf.g, reference), color=color, lw=1.0)
    axes[0].set_ylabel("magnitude (dB)")
    axes[1].set_ylabel("phase (deg)")
    for ax in axes:
        log_frequency_axis(ax, band, label=ax is axes[-1])
    axes[0].legend(fontsize=7, loc="lower left")
    axes[0].set_title("Frequency-response estimates: non-smoothed vs Parzen-smoothed (seed figs. 3.3/3.4)", fontsize=9)
    return figure


def order_singular_values(spectra: Spectra, gammas=(10, 100, 1000), band=IDENTIFICATION_BAND, q: int = 30) -> dict[int, np.ndarray]:
    """Singular values of the subspace method (McKelvey et al. 1996, step 3) for each gamma.

    The same decomposition the grid search does, for a few smoothing widths only.
    """
    out = {}
    for gamma in gammas:
        gamma = int(gamma)
        if gamma > spectra.nperseg // 2:
            continue
        frf = smoothed_response(spectra, gamma, band)
        omega = 2 * np.pi * frf.frequencies / spectra.fs
        out[gamma] = SubspaceDecomposition(omega, frf.g, q=q).singular_values
    return out


def _spread(keys: list[int], count: int) -> list[int]:
    """count keys spread evenly over the sorted keys (all of them when there are few)."""
    keys = sorted(keys)
    if len(keys) <= count:
        return keys
    picks = np.unique(np.round(np.linspace(0, len(keys) - 1, count)).astype(int))
    return [keys[i] for i in picks]


def singular_values_figure(singular_values: dict[int, np.ndarray], chosen_order: int | None = None,
                           count: int = 3, max_index: int = 30, dpi: float = 100.0):
    """Appendix B: singular values sigma_i / sigma_1 against i, for little/medium/much smoothing.

    A clear drop after index n would mark order n; the seed found none.
    """
    figure, (ax,) = new_figure(1, 1, height=3.2, dpi=dpi)
    for gamma in _spread(list(singular_values), count):
        values = np.asarray(singular_values[gamma], dtype=float)[:max_index]
        index = np.arange(1, values.size + 1)
        ax.semilogy(index, values / values[0], "o-", ms=3, lw=1.0, label=f"gamma = {gamma}")
    if chosen_order is not None:
        ax.axvline(chosen_order + 0.5, color=COLORS["model"], ls="--", lw=1.0, label=f"chosen order n = {chosen_order}")
    ax.set_xlabel("index i")
    ax.set_ylabel("sigma_i / sigma_1")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    ax.set_title("Singular-value order analysis (seed appendix B)", fontsize=9)
    return figure


def _edges(centres: np.ndarray) -> np.ndarray:
    """Cell edges around sorted cell centres (half-way between neighbours)."""
    centres = np.asarray(centres, dtype=float)
    if centres.size == 1:
        return np.array([centres[0] - 0.5, centres[0] + 0.5])
    middle = (centres[1:] + centres[:-1]) / 2
    return np.concatenate(([2 * centres[0] - middle[0]], middle, [2 * centres[-1] - middle[-1]]))


def rms_heatmap_figure(grid, noise_floor: float | None = None, dpi: float = 100.0):
    """Appendix C: validation rms over (gamma, order) for stable models, chosen point starred.

    With ``noise_floor`` (FS) the colour is rms / noise floor; unstable cells are hatched.
    """
    values = np.asarray(grid.rms, dtype=float)
    scale = noise_floor if noise_floor else 1.0
    shown = np.ma.masked_invalid(values / scale)
    figure, (ax,) = new_figure(1, 1, height=3.6, dpi=dpi)
    ax.set_facecolor("0.92")
    ax.fill_between([0, 1], 0, 1, transform=ax.transAxes, hatch="///", facecolor="none", edgecolor="0.75", lw=0)
    finite = shown.compressed()
    norm = LogNorm(vmin=finite.min(), vmax=finite.max()) if finite.size and finite.max() > finite.min() > 0 else None
    mesh = ax.pcolormesh(_edges(grid.gammas), _edges(grid.orders), shown.T, cmap="viridis_r", norm=norm, shading="flat")
    bar = figure.colorbar(mesh, ax=ax)
    bar.set_label("validation rms / noise floor" if noise_floor else "validation rms (FS)")
    chosen = grid.chosen
    ax.plot(chosen.gamma, chosen.order, marker="*", ms=14, color=COLORS["model"], mec="white",
            label=f"chosen: gamma = {chosen.gamma}, n = {chosen.order}")
    ax.set_xlabel("smoothing width gamma (lags)")
    ax.set_ylabel("model order n")
    ax.yaxis.set_major_locator(MaxNLocator(integer=True))
    ax.legend(fontsize=7, loc="upper right")
    ax.set_title("RMS of the sweep prediction error, stable models only (seed appendix C); hatched = unstable", fontsize=9)
    return figure
