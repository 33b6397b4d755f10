"""Design a controller from the models: ``design(fb_model, ff_model, disturbance, options)``.

Order of the steps: (1) the uncertainty of S_model (``anc.uncertainty``); (2) the robust IMC
feedback filter Q (``anc.feedback``) for the ear disturbance; (3) the feed-forward filter W
(``anc.feedforward``) for what the feedback leaves of the reference-coherent noise;
(4) both filters as balanced state-space realisations (``codegen.realise``), states with a
Hankel singular value below 1e-9 of the largest dropped; (5) predictions per band
(``anc.prediction``) for W alone, Q alone and both, made with the filters as stored.
"""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass

import numpy as np

from codegen.realise import balanced_realisation
from sysid.errors import HelmetAncError
from sysid.model import Model

from .basis import LaguerreBasis
from .controller import Controller, StateSpaceFilter
from .disturbance import Disturbance, default_disturbance
from .feedback import design_feedback, loop_margins
from .feedforward import design_feedforward
from .prediction import band_attenuation, band_centres, band_grid, coherence_bound, ear_psd, overall_dba
from .uncertainty import Uncertainty, model_uncertainty

__all__ = ["DesignOptions", "design", "predict"]


@dataclass(frozen=True)
class DesignOptions:
    """Design choices. ``latency`` in samples (>= 1: the drive at k uses measurements up to
    k - latency; converter delays are inside the identified S); Laguerre pole ``corner_hz``
    and ``order`` of each filter; the feedback filter's DC-blocking corner ``highpass_hz``; bounds in dB."""

    latency: int = 1
    corner_hz: float = 250.0
    order: int = 24
    # Q's DC-blocking corner (``anc.basis``): two octaves below the 20 Hz band edge.
    highpass_hz: float = 5.0
    max_amplification_db: float = 6.0
    max_ff_gain_db: float = 30.0
    feedback: bool = True
    feedforward: bool = True


def _balanced(basis: LaguerreBasis, coefficients: np.ndarray) -> StateSpaceFilter:
    A, B, C, D = basis.statespace(coefficients)
    hsv_max = float(np.max(np.abs(coefficients[1:]))) if coefficients.size > 1 else 0.0
    if hsv_max == 0.0 and basis.highpass_pole is None:
        return StateSpaceFilter(np.zeros((0, 0)), np.zeros((0, 1)), np.zeros((1, 0)), np.array([[coefficients[0]]]))
    Ab, Bb, Cb, Db, hsv = balanced_realisation(A, B, C, D)
    keep = int(np.sum(hsv > 1e-9 * hsv[0]))
    Ab, Bb, Cb, Db, _ = balanced_realisation(A, B, C, D, order=keep)
    return StateSpaceFilter(Ab, Bb, Cb, np.array([[Db]]))


def predict(s_model: Model, disturbance: Disturbance, latency: int, fb: StateSpaceFilter | None,
            ff: StateSpaceFilter | None) -> tuple[dict[str, list[float]], dict[str, float], list[float] | None]:
    """Per-band attenuation and overall dB(A) of W alone, Q alone and both, and the coherence bound."""
    fs = s_model.fs
    grid = band_grid()
    wide = np.geomspace(20.0, min(10000.0, 0.45 * fs), 2000)
    result, overall = {}, {}
    for frequencies in (grid.reshape(-1), wide):
        G = s_model.frequency_response(frequencies) * np.exp(-2j * np.pi * frequencies * latency / fs)
        spectra = disturbance.at(frequencies)
        loop = None if fb is None else G * fb.frequency_response(frequencies, fs)
        gw = None if ff is None or not spectra.has_reference else G * ff.frequency_response(frequencies, fs)
        off = spectra.ear_psd
        on = {"ff": ear_psd(spectra, None, gw), "fb": ear_psd(spectra, loop, None), "both": ear_psd(spectra, loop, gw)}
        if frequencies is wide:
            overall = {part: overall_dba(frequencies, off, psd) for part, psd in on.items()}
        else:
            result = {part: band_attenuation(off.reshape(grid.shape), psd.reshape(grid.shape)) for part, psd in on.items()}
            bound = coherence_bound(spectra) if spectra.has_reference else None
    return result, overall, bound


def design(fb_model: Model, ff_model: Model | None = None, disturbance: Disturbance | None = None,
           options: DesignOptions | None = None, uncertainty: Uncertainty | None = None,
           provenance: dict | None = None) -> Controller:
    """Controller for the FB model (S) and optionally the FF model (P); see the module docstring.

    ``disturbance`` defaults to ``default_disturbance(fs, ff_model)``; ``uncertainty`` to the
    FB model's own (``model_uncertainty``). Without a reference (no FF model and a disturbance
    without chin spectra) there is no W.
    """
    options = options or DesignOptions()
    started = time.process_time()
    if fb_model.path != "fb":
        raise HelmetAncError(f"the feedback model must be an FB model (drive -> ear); found path {fb_model.path!r}")
    if not fb_model.stable:
        raise HelmetAncError(f"the FB model is unstable (largest pole radius {fb_model.spectral_radius:.6f}); "
                             "identify or refine it again before designing a controller")
    if ff_model is not None:
        if ff_model.path != "ff":
            raise HelmetAncError(f"the feed-forward model must be an FF model (chin -> ear); found path {ff_model.path!r}")
        if ff_model.fs != fb_model.fs:
            raise HelmetAncError(f"FF model at {ff_model.fs:g} Hz, FB model at {fb_model.fs:g} Hz: identify both at one rate")
        if not ff_model.stable:
            raise HelmetAncError("the FF model is unstable; identify or refine it again before designing a controller")
    if not (isinstance(options.latency, int) and options.latency >= 1):
        raise HelmetAncError(f"latency must be a whole number of samples >= 1; found {options.latency!r}")
    if ff_model is not None:
        model_uncertainty(ff_model)  # refuses an FF model whose error is unknown, as for the FB model
    disturbance = disturbance or default_disturbance(fb_model.fs, ff_model)
    uncertainty = uncertainty or model_uncertainty(fb_model)
    basis = LaguerreBasis.at(options.corner_hz, options.order, fb_model.fs)
    fb_basis = LaguerreBasis.at(options.corner_hz, options.order, fb_model.fs, options.highpass_hz)
    notes: list[str] = []
    fb = ff = None
    margins: dict = {}
    loop_fn = None
    if options.feedback:
        fb_design = design_feedback(fb_model, disturbance, options.latency, uncertainty, fb_basis,
                                    options.max_amplification_db)
        fb = _balanced(fb_basis, fb_design.coefficients)
        # Margins of the stored (balanced, truncated) filter, not of the coefficients.
        f = fb_design.frequencies_hz
        G = fb_model.frequency_response(f) * np.exp(-2j * np.pi * f * options.latency / fb_model.fs)
        loop = G * fb.frequency_response(f, fb_model.fs)
        margins = loop_margins(loop, f, fb_design.relative_95, loop)
        notes += fb_design.notes

        def loop_fn(frequencies):
            Gf = fb_model.frequency_response(frequencies) * np.exp(-2j * np.pi * frequencies * options.latency / fb_model.fs)
            return Gf * fb.frequency_response(frequencies, fb_model.fs)

    if options.feedforward and disturbance.has_reference:
        ff_design = design_feedforward(fb_model, disturbance, options.latency, uncertainty, basis, loop_fn,
                                       options.max_ff_gain_db, options.max_amplification_db)
        ff = _balanced(basis, ff_design.coefficients)
        notes += ff_design.notes
    elif options.feedforward:
        notes.append("no feed-forward filter: no FF model and no chin-microphone spectrum")
    predicted, overall, bound = predict(fb_model, disturbance, options.latency, fb, ff)
    info = {
        "fb_model": fb_model.identification.get("noise_file") or fb_model.identification.get("source"),
        "ff_model": None if ff_model is None else (ff_model.identification.get("noise_file")
                                                   or ff_model.identification.get("source")),
        "disturbance": disturbance.source,
        "uncertainty": uncertainty.to_dict(),
        "options": asdict(options),
        "basis": {"kind": "Laguerre", "pole": basis.pole, "order": basis.order,
                  "feedback_highpass_pole": fb_basis.highpass_pole},
        "design_seconds_cpu": time.process_time() - started,
    }
    info.update(provenance or {})
    return Controller(fb_model.fs, fb_model, ff, fb, options.latency, band_centres(), predicted, margins, bound,
                      overall, notes, info)
