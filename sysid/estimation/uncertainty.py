"""A 95 % confidence band of a model's frequency response (design.md, "The model": ``uncertainty``).

The band bounds the relative error |H_model - H_true| / |H_model| at each frequency. It
has two parts, added:

1. Variance (the output-error estimator's own scatter). The model's poles are written
   in the modal parametrisation of ``sysid.estimation.output_error`` (sigma, theta per complex pair,
   xi per real pole) and its numerator, block transient and direct term (B, x_delta, D)
   are re-fitted on the raw DFT bins (U_k, Y_k) of a noise-recording block (input
   delayed by the model's delay, ``delay_aligned_block``), so theta is
   the output-error estimate on that block. The residual e_k(theta) = Y_k - model_k has
   the Jacobian J (poles by central differences, the rest analytically). For the
   unweighted least-squares estimator with independent circular noise V_k of variance
   s_k = E|V_k|^2 the linearised covariance is the sandwich

       Cov(theta) = M^-1 Re(J^H diag(s / 2) J) M^-1,    M = Re(J^H J),

   (Pintelon & Schoukens, "System Identification: A Frequency Domain Approach", 2nd ed.,
   2012, sec. 7.2 and eq. (7-41) for the covariance of frequency-domain estimators; with
   white noise it reduces to sigma^2 (J^H J)^-1). s_k is the residual power averaged over
   ``NOISE_BINS`` neighbouring bins, so coloured sensor noise is allowed. The delta method
   maps it to the response: with g = d[Re H, Im H]/d theta the error of H(e^{jw}) has the
   2x2 covariance g Cov g^T, and the 95 % bound on |dH| is sqrt(chi2_2(0.95) lambda_max),
   the largest radius of the 95 % ellipse (exact for a circular error, conservative by at
   most 25 % for a flat one).
   Assumptions: the model structure holds the truth (no bias), the noise is zero-mean,
   independent between bins and independent of the input, and the estimate is close
   enough to the minimum for the linearisation (the delta method is first order).

2. Misfit (bias, which the variance does not cover where the model is under-modelled or
   stopped short of the minimum). The Welch H1 estimate of the data is compared with the
   H1 estimate of the model's own output on the same input: same samples, segments and
   Hann window, so the estimator's leakage and smoothing bias (large at lightly damped
   modes and in the lowest 20 Hz bins: on a random FB plant H1 read 0.25 where the
   response is 1.03) is the same in both and cancels; the model's output is simulated from
   rest plus its free response fitted to the data (the plant's state at the recording's
   start). Comparing the model's response itself with H1 called H1's leakage "model bias"
   and stated 95 % errors of 1 to 46 times |H| where the true error was below 2 %.
   H1's own variance is E|H1 - H|^2 = (1 - c) / (n_eff c) |H|^2 with c the squared
   coherence and n_eff = averages / 1.056 for Hann windows at 50 % overlap (Bendat &
   Piersol, "Random Data", 4th ed., eq. 9.90; Welch 1967 for the overlap factor). With
   no bias, E|H1_model - H1|^2 = that variance + the model's own E|dH|^2; the excess of
   the mean of |H1_model - H1|^2 over ``MISFIT_BINS`` neighbouring bins above the mean of
   that expectation is a moment estimate of |bias|^2 (seen through the window's kernel),
   and its square root is added to the bound wherever it is positive (the band's
   ``method`` says at how many frequencies). No significance test gates it: a bias below
   the scatter of H1 cannot be detected, and measured on random plants a gate at 99 %
   left it uncovered.
   Not covered: a bias smaller than H1's scatter that is also systematic over many
   bins (e.g. a pure delay imitated by poles) can still leave the band short; a bias
   narrower than a Welch bin (fs / N) is seen only smoothed by the window's kernel.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.ndimage
import scipy.stats

from ..core import lti
from ..core.errors import IdentificationError
from ..core.model import Model
from ..core.thresholds import IDENTIFICATION_BAND
from ..io.recordings import Recording
from .output_error import BlockData, _params_to_poles, _poles_to_params, _Problem, block_data, modal_basis
from .spectra import FrequencyResponse, Spectra, estimate_spectra, response

__all__ = ["UncertaintyBand", "frequency_response_band", "parameter_covariance", "delay_aligned_block", "NOISE_BINS", "MISFIT_BINS"]

# Neighbouring DFT bins over which the output-noise power is averaged (about 13 Hz for 10 s).
NOISE_BINS = 129
# Neighbouring Welch bins (20 Hz apart) over which the model's misfit to H1 is averaged.
MISFIT_BINS = 9
# Bins per chunk of the Jacobian, to keep memory to tens of MB at any block length.
_CHUNK = 8192
# Samples per fine step of the pole powers p^t of the free response (``_pole_powers``).
_POWER_STEP = 512
_CHI2_2_95 = float(scipy.stats.chi2.ppf(0.95, 2))
_WELCH_HANN_50 = 1.056


@dataclass(frozen=True)
class UncertaintyBand:
    """95 % relative bound of |H_model - H_true| / |H_model| at ``frequencies_hz`` (Hz).

    ``relative_95`` = ``variance_95`` (estimator scatter) + ``misfit`` (measured bias,
    zero where the model's misfit to H1 is within H1's own scatter), all relative to
    |H_model|; ``method`` names what went in.
    """

    frequencies_hz: np.ndarray
    relative_95: np.ndarray
    variance_95: np.ndarray
    misfit: np.ndarray
    method: str
    block_seconds: float

    @property
    def median_width(self) -> float:
        """Median of ``relative_95`` over the band's frequencies (dimensionless)."""
        return float(np.median(self.relative_95))

    def covers(self, true_response: np.ndarray, model_response: np.ndarray) -> np.ndarray:
        """Boolean per frequency: |H_model - H_true| <= relative_95 |H_model|."""
        return np.abs(model_response - true_response) <= self.relative_95 * np.abs(model_response)

    def to_dict(self) -> dict:
        """The JSON form of the model's ``uncertainty`` field."""
        return {"frequencies_hz": [float(f) for f in self.frequencies_hz],
                "relative_95": [float(r) for r in self.relative_95],
                "method": self.method, "block_seconds": float(self.block_seconds)}


@dataclass(frozen=True)
class _Linearisation:
    poles: np.ndarray
    params: np.ndarray
    pairs: int
    theta: np.ndarray
    covariance: np.ndarray


def _design(problem: _Problem, poles: np.ndarray, idx: slice) -> np.ndarray:
    """Regressor [basis U, basis z, (U)] of the bins idx: model_k = row_k @ theta."""
    A = lti.real_block_diagonal(poles)
    C = lti.block_output_row(A)
    z = problem.data.z[idx]
    u = problem.u_delayed[idx]
    basis = modal_basis(A, C, z)
    columns = [basis * u[:, None], basis * z[:, None]]
    if problem.feedthrough:
        columns.append(u[:, None])
    return np.hstack(columns)


def _step(params: np.ndarray) -> np.ndarray:
    return 1e-6 * np.maximum(1.0, np.abs(params))


def _pole_jacobian(problem: _Problem, params: np.ndarray, pairs: int, theta: np.ndarray, idx: slice) -> np.ndarray:
    """d model_k / d params at the bins idx by central differences (bins x parameters).

    A parameter moves one pole (a pair's sigma or theta, a real pole's xi), and the model
    is a sum over the modal blocks of ``modal_basis``, so only that block's columns
    change: its difference alone is the difference of the whole model, without the
    others' round-off, at a fraction of the cost of rebuilding the regressor.
    """
    n = params.size  # one parameter per pole: the model's order
    z = problem.data.z[idx]
    u = problem.u_delayed[idx]
    h = _step(params)
    out = np.empty((z.size, params.size), dtype=complex)
    for i in range(params.size):
        up, down = params.copy(), params.copy()
        up[i] += h[i]
        down[i] -= h[i]
        # Pair j (parameters 2j, 2j+1) is the upper pole j and the states 2j, 2j+1; the real pole of
        # parameter i >= 2 pairs is pole i and state i (``_params_to_poles``, ``lti.real_block_diagonal``).
        pair = i < 2 * pairs
        pole = i // 2 if pair else i
        states = slice(2 * pole, 2 * pole + 2) if pair else slice(i, i + 1)
        blocks = []
        for moved in (up, down):
            p = _params_to_poles(moved, pairs)[pole]
            A = lti.real_block_diagonal(np.array([p, np.conj(p)]) if pair else np.array([p]))
            blocks.append(modal_basis(A, lti.block_output_row(A), z))
        difference = (blocks[0] - blocks[1]) / (2 * h[i])
        out[:, i] = (difference @ theta[:n][states]) * u + (difference @ theta[n:2 * n][states]) * z
    return out


def parameter_covariance(model: Model, data: BlockData) -> _Linearisation:
    """Linearised covariance of the modal output-error parameters on ``data`` (module docstring, part 1)."""
    if model.order == 0:
        raise IdentificationError("an uncertainty band needs a model of order at least 1")
    poles = np.linalg.eigvals(model.A)
    if np.max(np.abs(poles)) >= 1:
        raise IdentificationError("an uncertainty band needs a stable model")
    params, pairs = _poles_to_params(poles)
    # The parametrisation orders poles as pairs then reals; rebuild them from it so that
    # every perturbed evaluation below uses the same ordering.
    poles = _params_to_poles(params, pairs)
    problem = _Problem(data, model.delay, feedthrough=bool(model.D[0, 0] != 0.0))
    theta = problem.linear(poles)[2]
    p = params.size + theta.size
    bins = data.z.size
    if 2 * bins <= p:
        raise IdentificationError(f"{bins} DFT bins are too few for the {p} parameters of the band")

    # 1. Residual power per bin, then its local average (coloured noise allowed).
    power = np.empty(bins)
    for start in range(0, bins, _CHUNK):
        idx = slice(start, min(start + _CHUNK, bins))
        power[idx] = np.abs(data.Y[idx] - _design(problem, poles, idx) @ theta) ** 2
    # The residual has 2 bins - p degrees of freedom out of 2 bins real components.
    noise = scipy.ndimage.uniform_filter1d(power, size=min(NOISE_BINS, bins), mode="nearest") * (2 * bins) / (2 * bins - p)

    # 2. Sandwich M^-1 Re(J^H S/2 J) M^-1, accumulated chunk by chunk.
    information = np.zeros((p, p))
    meat = np.zeros((p, p))
    for start in range(0, bins, _CHUNK):
        idx = slice(start, min(start + _CHUNK, bins))
        design = _design(problem, poles, idx)
        J = np.hstack([_pole_jacobian(problem, params, pairs, theta, idx), design]) if params.size else design
        information += (J.conj().T @ J).real
        weighted = J * np.sqrt(noise[idx] / 2)[:, None]
        meat += (weighted.conj().T @ weighted).real
    # Poles, numerators and transients differ by decades in scale: invert the equilibrated matrix.
    scale = np.sqrt(np.maximum(np.diag(information), np.finfo(float).tiny))
    with np.errstate(over="ignore", invalid="ignore", divide="ignore"):
        equilibrated = information / np.outer(scale, scale)
        if np.all(np.isfinite(equilibrated)) and np.all(np.isfinite(meat)):
            inverse = np.linalg.pinv(equilibrated, rcond=1e-15, hermitian=True) / np.outer(scale, scale)
            covariance = inverse @ meat @ inverse
        else:
            # A pole numerically at z = 1 overflows the information matrix: no parametric
            # covariance; frequency_response_band falls back to the H1 variance where it is not finite.
            covariance = np.full((p, p), np.nan)
    return _Linearisation(poles, params, pairs, theta, covariance)


def _response(poles: np.ndarray, theta: np.ndarray, n: int, feedthrough: bool, z: np.ndarray) -> np.ndarray:
    A = lti.real_block_diagonal(poles)
    core = modal_basis(A, lti.block_output_row(A), z) @ theta[:n]
    return core + (theta[2 * n] if feedthrough else 0.0)


def _variance_bound(model: Model, lin: _Linearisation, f: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """95 % bound on |dH| (absolute) at f Hz by the delta method, and E|dH|^2."""
    z = np.exp(2j * np.pi * f / model.fs)
    n = model.order
    feedthrough = lin.theta.size > 2 * n
    h = _step(lin.params)
    gradient = []
    for i in range(lin.params.size):
        up, down = lin.params.copy(), lin.params.copy()
        up[i] += h[i]
        down[i] -= h[i]
        gradient.append((_response(_params_to_poles(up, lin.pairs), lin.theta, n, feedthrough, z)
                         - _response(_params_to_poles(down, lin.pairs), lin.theta, n, feedthrough, z)) / (2 * h[i]))
    # The pure delay has modulus 1: it rotates dH and leaves its covariance's eigenvalues alone.
    A = lti.real_block_diagonal(lin.poles)
    basis = modal_basis(A, lti.block_output_row(A), z)
    linear = [basis, np.zeros_like(basis)] + ([np.ones((z.size, 1))] if feedthrough else [])
    G = np.hstack([np.stack(gradient, axis=1)] + linear) if gradient else np.hstack(linear)
    real, imag = G.real, G.imag
    # 2x2 covariance of (Re dH, Im dH) per frequency and its largest eigenvalue.
    a = np.einsum("ki,ij,kj->k", real, lin.covariance, real)
    b = np.einsum("ki,ij,kj->k", real, lin.covariance, imag)
    c = np.einsum("ki,ij,kj->k", imag, lin.covariance, imag)
    largest = 0.5 * (a + c) + np.sqrt(0.25 * (a - c) ** 2 + b**2)
    return np.sqrt(_CHI2_2_95 * np.maximum(largest, 0.0)), a + c


def _h1_variance(model_response: np.ndarray, coherence: np.ndarray, averages: int) -> np.ndarray:
    """E|H1 - H|^2 of the Welch H1 estimate, (1 - coh) / (n_eff coh) |H|^2 (Bendat & Piersol, eq. 9.73)."""
    n_eff = averages / _WELCH_HANN_50
    c = np.clip(coherence, 1e-12, 1.0)
    return (1 - c) / (n_eff * c) * np.abs(model_response) ** 2


def _pole_powers(poles: np.ndarray, start: int, count: int) -> np.ndarray:
    """p^t for t = start .. start + count - 1 (rows) and each pole p (columns).

    With t = a L + b (L = ``_POWER_STEP``) p^t = (p^L)^a p^b: one complex power per
    b < L and per a, and one product per sample, where a complex power per sample
    (exp and log each) took 1.6 s of CPU for 15 poles over 10 s at 48 kHz. Each factor
    carries a few ulp of relative error, as p^t itself would.
    """
    first, last = start // _POWER_STEP, (start + count - 1) // _POWER_STEP
    coarse = poles[None, :] ** (np.arange(first, last + 1) * _POWER_STEP)[:, None]
    fine = poles[None, :] ** np.arange(_POWER_STEP)[:, None]
    # Rows a, columns b of (p^L)^a p^b, read in order: t = a L + b from first L on.
    powers = (coarse[:, None, :] * fine[None, :, :]).reshape(-1, poles.size)
    return powers[start - first * _POWER_STEP:start - first * _POWER_STEP + count]


def _free_response_fit(model: Model, residual: np.ndarray) -> np.ndarray:
    """The model's free response C A^t x0 (t = 0, 1, ...) closest to ``residual`` in least squares.

    The data's output carries the plant's state at the recording's start (a lightly damped
    mode rings through the whole record); the model's output simulated from rest does not.
    The free response spans Re p^t and Im p^t for each pole p (x0 free), so its fit is
    linear; it is accumulated over chunks of t to keep memory to tens of MB.
    """
    poles = np.linalg.eigvals(model.A)
    poles = poles[poles.imag >= 0]
    if poles.size == 0:
        return np.zeros_like(residual)

    def columns(start, stop):
        powers = _pole_powers(poles, start, stop - start)
        return np.hstack([powers.real, powers[:, poles.imag > 0].imag])

    gram, rhs = 0.0, 0.0
    for start in range(0, residual.size, _CHUNK * 8):
        stop = min(start + _CHUNK * 8, residual.size)
        X = columns(start, stop)
        gram = gram + X.T @ X
        rhs = rhs + X.T @ residual[start:stop]
    coefficients = np.linalg.lstsq(gram, rhs, rcond=1e-12)[0]
    free = np.empty_like(residual)
    for start in range(0, residual.size, _CHUNK * 8):
        stop = min(start + _CHUNK * 8, residual.size)
        free[start:stop] = columns(start, stop) @ coefficients
    return free


def _model_h1(model: Model, noise: Recording, nperseg: int, band: tuple[float, float]) -> tuple[FrequencyResponse, FrequencyResponse, int]:
    """H1 of the data and H1 of the model's own output on the same input, by one Welch estimator.

    Both come from the same samples of ``noise``, the same segments and the same Hann
    window, so the estimator's leakage and smoothing bias (sharp modes, the lowest bins) is
    the same in both and cancels in their difference; only the model's error, seen through
    the window's kernel, and the measurement noise remain. The model's output is simulated
    from rest plus its free response fitted to the data (``_free_response_fit``), so the
    plant's state at the start is not read as misfit. Returns (data, model, averages).
    """
    simulated = model.simulate(noise.u)
    simulated = simulated + _free_response_fit(model, noise.y - simulated)
    spectra = estimate_spectra(noise, "h1", nperseg)
    own = estimate_spectra(Recording(noise.u, simulated, noise.fs, noise.path), "h1", nperseg)
    return response(spectra, band), response(own, band), spectra.segments


def _misfit(h1_model: np.ndarray, h1: np.ndarray, coherence: np.ndarray, averages: int,
            model_variance: np.ndarray) -> np.ndarray:
    """Moment estimate of the bias |H_model - H_true| (absolute); module docstring, part 2.

    ``h1_model`` is the H1 estimate of the model's own output on the data's input
    (``_model_h1``), not the model's response: compared like with like.
    """
    expected = _h1_variance(h1_model, coherence, averages) + model_variance
    observed = np.abs(h1_model - h1) ** 2
    m = min(MISFIT_BINS, observed.size)
    mean_observed = scipy.ndimage.uniform_filter1d(observed, size=m, mode="nearest")
    mean_expected = scipy.ndimage.uniform_filter1d(expected, size=m, mode="nearest")
    return np.sqrt(np.maximum(mean_observed - mean_expected, 0.0))


def delay_aligned_block(noise: Recording, delay: int, band: tuple[float, float], seconds: float | None) -> BlockData:
    """DFT bins of u(t - delay) and y(t) over (at most) ``seconds`` of a noise recording.

    The input is delayed by taking earlier recorded samples, not by the factor z^-d on
    the block's DFT: a circular shift leaves a transient of d input samples that the
    model's state transient cannot represent, a bias that grows with d.
    """
    if delay:
        noise = Recording(noise.u[:-delay], noise.y[delay:], noise.fs, noise.path)
    return block_data(noise, band, seconds)


def frequency_response_band(model: Model, noise: Recording, spectra: Spectra | None = None,
                            band: tuple[float, float] = IDENTIFICATION_BAND, seconds: float | None = 10.0) -> UncertaintyBand:
    """The 95 % relative band of ``model``'s response from a noise recording and (optionally) its spectra.

    ``noise`` is the noise recording without its transient; the covariance uses its first
    ``seconds`` (the block the output-error refinement uses; None = all of it), inputs
    delayed by the model's delay. ``spectra`` are its Welch spectra
    (``spectra.estimate_spectra``, estimator h1): with them the band is evaluated on their
    grid inside ``band`` (Hz) and widened by the measured misfit, whose H1 estimates of the
    data and of the model's output are both taken from all of ``noise`` with the spectra's
    segment length; without them it is the variance part on a 20 Hz grid.
    """
    data = delay_aligned_block(noise, model.delay, band, seconds)
    core = Model(path=model.path, fs=model.fs, A=model.A, B=model.B, C=model.C, D=model.D)
    lin = parameter_covariance(core, data)
    if spectra is not None:
        frf = response(spectra, band)
        f = frf.frequencies
    else:
        f = np.arange(np.ceil(band[0] / 20.0), np.floor(band[1] / 20.0) + 1) * 20.0
    if f.size == 0:
        raise IdentificationError(f"no frequencies inside the band {band[0]:g}-{band[1]:g} Hz")
    H = model.frequency_response(f)
    magnitude = np.maximum(np.abs(H), np.finfo(float).tiny)
    bound, variance = _variance_bound(core, lin, f)
    method = "output-error covariance (sandwich, local noise power) and delta method, 95 %"
    unknown = ~(np.isfinite(bound) & np.isfinite(variance))
    if np.any(unknown):
        # A pole on (or numerically at) the unit circle makes the information matrix
        # overflow: no parametric variance there. The nonparametric H1 variance at the
        # model's response is the error the data allow at best; the misfit then adds the bias.
        if spectra is None or spectra.estimator != "h1":
            raise IdentificationError("the model's parameter covariance is not finite (a pole on the unit circle?) "
                                      "and no H1 spectra were given for a nonparametric band")
        nonparametric = _h1_variance(H, frf.coherence, spectra.segments)
        variance = np.where(unknown, nonparametric, variance)
        bound = np.where(unknown, np.sqrt(_CHI2_2_95 * nonparametric / 2), bound)
        method += f"; the H1 estimate's variance where the covariance is not finite ({100 * np.mean(unknown):.0f} %)"
    misfit = np.zeros_like(bound)
    if spectra is not None and spectra.estimator == "h1":
        # H1 of the data and of the model's output, both from ``noise`` on the spectra's grid.
        data_h1, model_h1, averages = _model_h1(model, noise, spectra.nperseg, band)
        misfit = _misfit(model_h1.g, data_h1.g, data_h1.coherence, averages, variance)
        if np.any(misfit > 0):
            share = np.mean(misfit > 0)
            method += f"; widened by the measured misfit to H1 at {100 * share:.0f} % of frequencies"
    variance_95 = bound / magnitude
    relative_misfit = misfit / magnitude
    return UncertaintyBand(f, variance_95 + relative_misfit, variance_95, relative_misfit, method, data.length / data.fs)
