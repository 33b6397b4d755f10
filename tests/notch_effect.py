"""notch: a narrow dip in the path, e.g. a liner's absorber tuned to one frequency (a user's own effect).

A second-order notch (scipy.signal.iirnotch: zeros on the unit circle at f0_hz, -3 dB
width f0_hz / q) in series with the plant. Its detector fits f0 and q to the sweeps
(the measured ear signal against the model's prediction times the notch); the fitted
rms is the validation rms the model would have with the notch in series. ``refine``
adds it as a fixed factor in front of the core (``sysid.refits.series_factor``).
"""

import numpy as np
import scipy.optimize
import scipy.signal

from sysid.core.effect_spec import ParameterSpec
from sysid.core.thresholds import EXCESS, EXPLAINS_GAIN
from sysid.effects import Effect, register
from sysid.findings import finding
from sysid.findings.dynamics import sweep_bins
from sysid.refits import series_factor

F0_RANGE = (30.0, 4000.0)
Q_RANGE = (1.0, 50.0)


def notch(params, fs):
    """(b, a) of the notch at f0_hz (Hz) with quality q."""
    return scipy.signal.iirnotch(params["f0_hz"], params["q"], fs)


def _responses(bins, xs, fs):
    """Responses on the compressed sweep cells of the notches x = (ln f0, ln q), one row each."""
    z1 = np.exp(-2j * np.pi * bins.compressed.frequencies / fs)
    rows = []
    for x in xs:
        b, a = notch({"f0_hz": np.exp(x[0]), "q": np.exp(x[1])}, fs)
        rows.append(np.polyval(b[::-1], z1) / np.polyval(a[::-1], z1))
    return np.array(rows)


def detect(ctx):
    """The notch that best explains the sweeps; significant when it lowers the rms EXPLAINS_GAIN-fold."""
    if ctx.excess < EXCESS:
        return finding("notch", False, 0.0, {}, "not tested: the model is at the noise floor", "none")
    bins = sweep_bins(ctx)
    before = bins.rms()
    # A grid of starts scored together, then a bounded search from the best (as the built-in factors).
    starts = [(np.log(f), np.log(q)) for f in np.geomspace(*F0_RANGE, 60) for q in (2.0, 6.0, 20.0)]
    best = starts[int(np.argmin(bins.compressed.rms(_responses(bins, starts, ctx.fs))))]
    bounds = [tuple(np.log(F0_RANGE)), tuple(np.log(Q_RANGE))]
    x = scipy.optimize.minimize(lambda x: float(bins.compressed.rms(_responses(bins, [x], ctx.fs))[0]), best,
                                method="L-BFGS-B", bounds=bounds).x
    params = {"f0_hz": float(np.exp(x[0])), "q": float(np.exp(x[1]))}
    b, a = notch(params, ctx.fs)
    after = bins.rms(lambda f: scipy.signal.freqz(b, a, worN=f, fs=ctx.fs)[1])
    gain = before / after if after > 0 else 0.0
    significant = gain >= EXPLAINS_GAIN
    explanation = (f"the sweep error has a notch at {params['f0_hz']:.0f} Hz (width {params['f0_hz'] / params['q']:.0f} Hz) "
                   f"that the model lacks; a notch in series lowers the sweep error {gain:.2f}x")
    remedy = f"refine --add notch:f0_hz={params['f0_hz']:.5g},q={params['q']:.4g}" if significant else "none"
    return finding("notch", significant, gain / EXPLAINS_GAIN, params, explanation, remedy,
                   {"rms_gain": gain, "rms_with_factor": after})


NOTCH = register(Effect(
    name="notch", summary="a narrow dip: second-order notch at f0_hz with quality q",
    simulate_params=(ParameterSpec("f0_hz", 1000.0, 20.0, 20000.0), ParameterSpec("q", 5.0, 0.5, 100.0)),
    refine_params=(ParameterSpec("f0_hz", 1000.0, 20.0, 20000.0), ParameterSpec("q", 5.0, 0.5, 100.0)),
    detect=detect, build=series_factor(notch), auto_params=lambda p: {"f0_hz": p["f0_hz"], "q": p["q"]},
    factor=notch, figure="series-factor"), replace=True)
