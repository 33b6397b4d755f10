"""A Hammerstein model's static input nonlinearity and LTI core refined together by output error.

The model is y = L(f(u)) + e with L the linear part (delay and core (A, B, C, D)) and f a static
map: a polynomial sum_k c_k u^k of degree K (odd and even terms), or the saturation
g (s tanh((u + o)/s) - s tanh(o/s)) (``sysid.core.model``). The criterion is the output error on
the noise recording, V = sum_t (y_t - L(f(u))_t)^2 in the identification band, minimised over
f and L together by alternating between the two blocks (Narendra & Gallman, "An iterative method
for the identification of nonlinear systems using a Hammerstein model", IEEE Trans. Autom.
Control 11(3), 1966; the relaxation of Bai, Automatica 34(3), 1998, sec. 3): with the core held,
f by least squares in the time domain (linear in the c_k through the columns L(u^k); the
saturation's s and o by Gauss-Newton, its gain by the same least squares); with f held, the
core by the output-error refinement on the raw DFT of (f(u), y)
(``sysid.estimation.output_error.refine_output_error``), which keeps its order. Each block
lowers V, so the alternation descends; it stops when a round gains less than 0.1 %.

A recording whose ear channel clipped (the model's ``excluded`` stretches, ``sysid.io.corrections``)
is fitted on the samples it keeps only (``keep``): the criterion is then the masked output error of
``sysid.estimation.masked_output_error``, V = sum over kept t of (y_t - L(f(u))_t)^2 with L driven by
the whole input from the recording's start, over the full band (a band-pass of the ear signal would
smear each gap's unknown samples over the 20 Hz edge's settling time, about the spacing of the gaps
on a path whose DC gain clips the channel), the map by least squares over the kept rows and the core
by ``refine_masked``. The gaps are not filled: a fill by the model being fitted (EM for missing
data) pulls the fit towards itself, and a fill by the linear model before the map holds the very
harmonics and DC the map is there to explain.

The polynomial's degree is chosen by Rissanen's minimum description length on the output
error, N ln V_K + K ln N, with N the band's effective number of independent samples (the
band-passed stretch's samples times twice its bandwidth over fs; the kept samples on the full band). The gain between f and L is
not identifiable: f is normalised to unit small-signal slope (c_1 = 1; g = cosh^2(o/s)) and the
core carries the gain.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import scipy.optimize
import scipy.signal

from ..core import lti
from ..core.errors import IdentificationError
from ..core.model import MAX_COEFFICIENT, Model
from ..core.structures import factor_coefficients
from ..core.thresholds import IDENTIFICATION_BAND
from ..io.recordings import Recording
from .input_nonlinearity import tanh_map
from .masked_output_error import refine_masked, refine_masked_inputs
from .output_error import block_data, refine_output_error

__all__ = ["HammersteinFit", "fit_hammerstein", "polynomial_degree", "MAX_DEGREE"]

MAX_DEGREE = 7
# Start of the time-domain stretch (s) left out of the criterion: the simulation from rest settles.
_SETTLE_S = 0.05
_ROUNDS = 4
_GAIN = 1e-3


@dataclass(frozen=True)
class HammersteinFit:
    """The refined core (A, B, C, D), the input map (``coefficients`` of the polynomial in u, a1 = 1, or
    ``form`` the saturation; the other None), the in-band output error before and after (mean square,
    FS^2), the map's free parameters and the rounds of the alternation."""

    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    coefficients: list[float] | None
    form: dict | None
    cost_before: float
    cost_after: float
    parameters: int
    rounds: int

    def model(self, like: Model) -> Model:
        """``like`` with this core and input map (its delay and everything else kept)."""
        fields = {**like.__dict__, "A": self.A, "B": self.B, "C": self.C, "D": self.D,
                  "input_nonlinearity": self.coefficients, "input_nonlinearity_form": self.form,
                  "history": list(like.history), "identification": dict(like.identification), "uncertainty": None}
        return Model(**fields)


class _Stretch:
    """The noise recording's stretch the time-domain steps read: its input from the recording's start (the
    simulation starts from rest where the recording does, so the plant's state at the stretch is the
    recorded one: a slow mode started from rest at the stretch would misfit for its whole decay), the
    band-passed ear signal over the stretch, the band filter; with ``keep`` (True where the ear signal
    counts), the kept samples of the stretch on the full band instead (see the module docstring)."""

    def __init__(self, u: np.ndarray, y: np.ndarray, fs: float, band, start: int, keep: np.ndarray | None = None):
        self.u, self.fs = u, fs
        self.first = max(start, int(round(_SETTLE_S * fs)))
        self.rows = None if keep is None else np.asarray(keep[self.first:u.size], bool)
        self.band = None if keep is not None else scipy.signal.butter(4, band, "bandpass", fs=fs, output="sos")
        self.y = self.filtered(y)
        self.peak = float(np.max(np.abs(u))) or 1.0
        # Samples of a band-limited signal carry 2 B / fs independent values each (Nyquist).
        self.effective = max(self.y.size * (1.0 if keep is not None else 2.0 * (band[1] - band[0]) / fs), 1.0)

    def filtered(self, x: np.ndarray) -> np.ndarray:
        if self.rows is not None:
            return x[self.first:][self.rows]
        return scipy.signal.sosfilt(self.band, x)[self.first:]

    def through(self, linear: Model, v: np.ndarray) -> np.ndarray:
        return self.filtered(linear.simulate(v))


def _linear(model: Model, core=None) -> Model:
    A, B, C, D = core if core is not None else (model.A, model.B, model.C, model.D)
    return Model(path=model.path, fs=model.fs, A=A, B=B, C=C, D=D, delay=model.delay)


def _polynomial_fits(stretch: _Stretch, linear: Model, max_degree: int):
    """[(degree, relative coefficients c_k / c_1 on u / peak, c_1, mean-square error)] for degrees 1..max_degree."""
    x = stretch.u / stretch.peak
    columns = np.stack([stretch.through(linear, x**k) for k in range(1, max_degree + 1)], axis=1)
    fits = []
    for degree in range(1, max_degree + 1):
        c, *_ = np.linalg.lstsq(columns[:, :degree], stretch.y, rcond=None)
        error = float(np.mean((stretch.y - columns[:, :degree] @ c) ** 2))
        fits.append((degree, c / c[0], float(c[0]), error))
    return fits


def polynomial_degree(fits, effective: float) -> int:
    """The degree of least description length N ln V_K + K ln N among ``fits`` ((degree, _, _, V_K), ...)."""
    return min(fits, key=lambda f: effective * math.log(max(f[3], 1e-300)) + f[0] * math.log(effective))[0]


def _tanh_columns(stretch: _Stretch, linear: Model, theta):
    """The unit-slope saturation of parameters (ln(s / peak), o / s) through the linear part, and its form."""
    scale = stretch.peak * math.exp(float(np.clip(theta[0], -8.0, 8.0)))
    offset = scale * float(np.clip(theta[1], -3.0, 3.0))
    gain = math.cosh(offset / scale) ** 2
    return stretch.through(linear, tanh_map(stretch.u, scale, offset, gain)), {"kind": "tanh", "scale": scale,
                                                                               "gain": gain, "offset": offset}


def _tanh_fit(stretch: _Stretch, linear: Model, starts):
    """(form, gain of the linear part, mean-square error, parameters) of the saturation by Gauss-Newton over
    (s, o), the gain by least squares at every step (variable projection); the best of ``starts``."""
    def residual(theta):
        column, _ = _tanh_columns(stretch, linear, theta)
        g = float(column @ stretch.y) / max(float(column @ column), 1e-300)
        return stretch.y - g * column

    best = None
    for theta0 in starts:
        solution = scipy.optimize.least_squares(residual, theta0, method="trf", x_scale=1.0, max_nfev=40,
                                                diff_step=1e-4, xtol=1e-6, ftol=1e-7)
        error = float(np.mean(solution.fun**2))
        if best is None or error < best[2]:
            column, form = _tanh_columns(stretch, linear, solution.x)
            best = (form, float(column @ stretch.y) / max(float(column @ column), 1e-300), error, solution.x)
    return best


def _tanh_starts(fits, peak: float):
    """Starts of (ln(s / peak), o / s): from the cubic fit's a3 = -1 / (3 s^2) and a2 = -tanh(o/s) / s (the
    Taylor series of the unit-slope saturation), and a saturation at and beyond the stretch's peak."""
    _, c, _, _ = fits[2]
    starts = [np.array([0.0, 0.0]), np.array([math.log(2.0), 0.0])]
    if c[2] < 0:
        ratio = math.sqrt(-1.0 / (3.0 * c[2]))
        starts.insert(0, np.array([math.log(ratio), float(np.arctanh(np.clip(-c[1] * ratio, -0.9, 0.9)))]))
    return starts


def _delayed_and_counted(v: np.ndarray, keep: np.ndarray, start: int, delay: int) -> tuple[np.ndarray, np.ndarray]:
    """(v delayed by ``delay`` samples along its first axis, from rest; the kept samples after ``start``): the
    masked criterion's input and the samples it counts."""
    shift = min(delay, v.shape[0])
    delayed = np.concatenate((np.zeros((shift, *v.shape[1:])), v[: v.shape[0] - shift]))
    counted = np.asarray(keep, bool).copy()
    counted[:start] = False
    return delayed, counted


def _masked_core(core, v: np.ndarray, y: np.ndarray, keep: np.ndarray, start: int, delay: int, feedthrough: bool):
    """The core's poles refined by output error over the kept samples after ``start`` of (v delayed, y)
    (``sysid.estimation.masked_output_error``), balanced; None where that fails."""
    delayed, counted = _delayed_and_counted(v, keep, start, delay)
    try:
        fit = refine_masked(core[0], delayed, y, counted, feedthrough=feedthrough)
        A, B, C, D = lti.balanced_realisation(fit.A, fit.B, fit.C, fit.D)
    except (np.linalg.LinAlgError, ValueError):
        return None
    return A, B, C, np.atleast_2d(D)


def _relaxed_core(core, u: np.ndarray, y: np.ndarray, keep: np.ndarray, start: int, delay: int, feedthrough: bool,
                  degree: int):
    """The core's poles refined over the kept samples after ``start`` with a numerator of their own for each
    power (u / peak)^k, k = 1..``degree`` (``refine_masked_inputs``: Bai's relaxation, linear in the
    numerators), and the numerator of the rank-one fit of those (the Hammerstein structure: one core, the
    powers weighted by the map); balanced, or None where that fails. The start of the masked alternation:
    the map and the core move together there, each held while the other moves, so from a core fitted
    without the map (the DC the map makes sets the path's low-frequency gain) the alternation crawls."""
    peak = float(np.max(np.abs(u[start:]))) or 1.0
    x = u / peak
    powers = np.stack([x**k for k in range(1, degree + 1)], axis=1)
    delayed, counted = _delayed_and_counted(powers, keep, start, delay)
    try:
        A, B, C, D = refine_masked_inputs(core[0], delayed, y, counted, feedthrough=feedthrough)
        numerators = np.column_stack((C, D)) if feedthrough else C
        left, values, right = np.linalg.svd(numerators, full_matrices=False)
        first = values[0] * left[0, 0] * right[0]
        n = A.shape[0]
        realised = lti.balanced_realisation(A, B, first[None, :n], np.array([[first[n] if feedthrough else 0.0]]))
    except (np.linalg.LinAlgError, ValueError):
        return None
    return realised[0], realised[1], realised[2], np.atleast_2d(realised[3])


def fit_hammerstein(model: Model, noise: Recording, kind: str = "polynomial", seconds: float = 2.0,
                    core_seconds: float | None = None, transient_s: float = 0.0, band=IDENTIFICATION_BAND,
                    max_degree: int = MAX_DEGREE, rounds: int = _ROUNDS, prefilter: dict | None = None,
                    keep: np.ndarray | None = None) -> HammersteinFit:
    """The input map of ``kind`` ("polynomial" or "tanh") and the core of ``model`` refined together on
    ``noise`` (the recording as the core sees it: the ear signal without disturbance or offset, the input
    raw) after its first ``transient_s``; see the module docstring. The map is fitted on the first
    ``seconds`` after the transient (simulated from the recording's start), the core on the first
    ``core_seconds`` (default: ``seconds``; the frequency-domain step is cheap, and a core of lightly damped
    modes needs the longer record). ``model``'s own input map is replaced; its delay is kept, and its core
    is the start. A ``prefilter`` (the model form's, ``sysid.core.model``) is held in front of the map
    (a Wiener-Hammerstein model): the map and the core are fitted on the input it filters from the
    recording's start, and the fitted form carries it. ``keep`` (one flag per sample of ``noise``, True
    where its ear signal counts; None or all True: every sample) leaves the excluded samples out of both
    steps (the masked criterion of the module docstring).
    """
    if kind not in ("polynomial", "tanh"):
        raise ValueError(f"kind must be polynomial or tanh; found {kind!r}")
    if model.order == 0:
        raise IdentificationError("a Hammerstein refinement needs a core of order at least 1")
    start = min(int(round(transient_s * noise.fs)), noise.u.size - 1)
    n = min(noise.u.size, start + int(round(seconds * noise.fs)))
    # The input as recorded (the map acts on it so); the band-pass takes the ear signal's mean out.
    filtered = noise.u if prefilter is None else scipy.signal.lfilter(
        *factor_coefficients(prefilter["kind"], prefilter, noise.fs), noise.u)
    u, y = filtered[:n], noise.y[:n]
    if keep is not None and np.all(keep):
        keep = None
    if keep is not None and np.count_nonzero(keep[start:n]) < 10 * (model.order + max_degree + 1):
        raise IdentificationError("too few samples of the noise recording outside its excluded stretches")
    stretch = _Stretch(u, y, noise.fs, band, start, keep)
    cost_before = float(np.mean((stretch.y - stretch.through(_linear(model), model.apply_input_nonlinearity(
        noise.u[:n]))) ** 2))
    m = min(noise.u.size, start + int(round((core_seconds or seconds) * noise.fs)))
    core_u, core_y = filtered[start:m], noise.y[start:m]
    core = (model.A, model.B, model.C, model.D)
    if keep is not None:
        relaxed = _relaxed_core(core, filtered[:m], noise.y[:m], keep[:m], start, model.delay, bool(model.D[0, 0]),
                                min(max_degree, 3))
        if relaxed is not None and np.max(np.abs(np.linalg.eigvals(relaxed[0]))) < 1.0:
            core = relaxed
    history, coefficients, form, parameters, done, theta = [], None, None, 0, 0, None
    for done in range(1, rounds + 1):
        # 1. The map with the core held (its gain moved into the core).
        linear = _linear(model, core)
        fits = _polynomial_fits(stretch, linear, max_degree)
        if kind == "polynomial":
            # Only degrees whose coefficients in FS units a model can hold (a degree-7 term on a drive of
            # 0.06 FS peak is c_7 / 0.06^6: past MAX_COEFFICIENT for any c_7 above 5).
            held = [f for f in fits if np.all(np.isfinite(f[1])) and
                    max(abs(ck) / stretch.peak ** k for k, ck in enumerate(f[1])) <= MAX_COEFFICIENT]
            degree = polynomial_degree(held or fits[:1], stretch.effective)
            _, c, gain, error = fits[degree - 1]
            coefficients = [float(ck / stretch.peak ** (k - 1)) for k, ck in enumerate(c, start=1)]
            parameters = degree - 1
        else:
            # Later rounds start from the last: the core moved little.
            starts = _tanh_starts(fits, stretch.peak) if theta is None else [theta]
            form, gain, error, theta = _tanh_fit(stretch, linear, starts)
            parameters = 2 if form["offset"] else 1

        def mapped(x):
            if form is not None:
                return tanh_map(x, form["scale"], form["offset"], form["gain"])
            return np.polynomial.polynomial.polyval(x, [0.0, *coefficients])
        A, B, C, D = core
        core = (A, B * gain, C, D * gain)
        # 2. The core with the map held: output error on the raw DFT of (f(u), y), the order kept; with
        # excluded samples, the masked output error over the kept ones.
        if keep is None:
            data = block_data(Recording(mapped(core_u), core_y, noise.fs, noise.path), band, None)
            oe = refine_output_error(*core, data, delay=model.delay, feedthrough=bool(model.D[0, 0]),
                                     noise_tolerance=True)
            refined = (oe.A, oe.B, oe.C, oe.D)
        else:
            refined = _masked_core(core, mapped(filtered[:m]), noise.y[:m], keep[:m], start, model.delay,
                                   bool(model.D[0, 0]))
        if refined is not None and np.max(np.abs(np.linalg.eigvals(refined[0]))) < 1.0:
            core = refined
        error = float(np.mean((stretch.y - stretch.through(_linear(model, core), mapped(u))) ** 2))
        history.append(error)
        if len(history) > 1 and history[-2] - error < _GAIN * history[-2]:
            break
    if prefilter is not None:
        form, parameters = {**(form or {"kind": "identity"}), "prefilter": dict(prefilter)}, parameters + 1
    return HammersteinFit(*core, coefficients, form, cost_before, history[-1], parameters, done)
