"""A static input polynomial (Hammerstein) in front of a model's linear part, by least squares on the sweep residual.

With the model's linear part L (delay and LTI core), the sweep residual e is regressed on
L(u), L(u^2 - mean), L(u^3): a polynomial v = a1 u + a2 u^2 + a3 u^3 in front of L predicts
e = L(v) - L(u), fitted in the validation band (both sides through the same band-pass, so the
regression e = X a holds for the filtered signals). The u^2 and u^3 columns put energy at 2f and
3f of the sweep's instantaneous frequency, where a linear misfit at f has none. Relative to the
linear term the polynomial is u + (a2 / a1) u^2 + (a3 / a1) u^3.

Used by the input-nonlinearity finding (``sysid.findings.nonlinearity``: how much the harmonic
columns explain). The refit fits the map with the core instead (``sysid.estimation.hammerstein``):
with the core held, coefficients read through a linear part that has absorbed part of the
nonlinearity stop short (a tanh on the seed's FB path: 27x the floor).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np
import scipy.signal

from ..core.model import Model
from ..io.recordings import Recording
from ..validation.sweeps import SKIP_S, VALIDATION_BAND

__all__ = ["InputPolynomial", "polynomial_columns", "input_polynomial"]


@dataclass(frozen=True)
class InputPolynomial:
    """The least-squares fit of the sweep residual on the polynomial columns: ``coefficients`` (a1 - 1, a2, a3
    of v = a1 u + a2 u^2 + a3 u^3), the residual energy left by the linear column alone and by all columns
    (FS^2, summed over the band-passed samples) and the number of samples."""

    coefficients: np.ndarray
    energy_linear: float
    energy_full: float
    samples: int

    @property
    def a2(self) -> float:
        """The u^2 coefficient relative to the linear one."""
        return self.coefficients[1] / (1.0 + self.coefficients[0])

    @property
    def a3(self) -> float:
        """The u^3 coefficient relative to the linear one."""
        return self.coefficients[2] / (1.0 + self.coefficients[0])

    @property
    def explained(self) -> float:
        """The fraction of the linear column's residual energy the harmonic columns explain."""
        return (self.energy_linear - self.energy_full) / self.energy_linear if self.energy_linear > 0 else 0.0

    @property
    def chi2(self) -> float:
        """N times the relative gain of the harmonic columns (~chi^2 with 2 degrees of freedom for chance)."""
        if not self.energy_full > 0:
            return 0.0
        return self.samples * (self.energy_linear - self.energy_full) / self.energy_full


def polynomial_columns(model: Model, u: np.ndarray, degree: int = 3,
                       prediction: np.ndarray | None = None) -> np.ndarray:
    """Columns L(u^k) for k = 1..degree (even powers centred), L the model's linear part (delay and core).

    The first column is the model's prediction, which ``prediction`` supplies when known.
    """
    linear = Model(path=model.path, fs=model.fs, A=model.A, B=model.B, C=model.C, D=model.D, delay=model.delay)
    base = model.apply_input_nonlinearity(u)
    columns = [] if prediction is None else [prediction]
    for k in range(len(columns) + 1, degree + 1):
        x = base**k
        if k % 2 == 0:
            x = x - x.mean()
        columns.append(linear.simulate(x))
    return np.stack(columns, axis=1)


def input_polynomial(model: Model, sweeps: list[Recording], per_sweep: list[dict],
                     factor: Callable[[np.ndarray], np.ndarray] | None = None) -> InputPolynomial:
    """The input polynomial of ``model`` from its residual on the ``sweeps`` (see the module docstring).

    ``per_sweep``: the model's comparison on each sweep (``sysid.validation.compare.Comparison.per_sweep``: its
    ``linear`` prediction and ``residual``); the first ``SKIP_S`` of each sweep are left out. ``factor``: a series
    factor the model lacks, applied to every column (the residual then is what the model with the factor leaves).
    """
    first = int(round(SKIP_S * model.fs))
    rows, targets = [], []
    for sweep, record in zip(sweeps, per_sweep):
        columns = polynomial_columns(model, sweep.u, prediction=record["linear"])
        residual = record["residual"]
        if factor is not None:
            filtered = np.stack([factor(c) for c in columns.T], axis=1)
            residual = residual + columns[:, 0] - filtered[:, 0]
            columns = filtered
        rows.append(columns[first:])
        targets.append(residual[first:])
    # Both sides in the validation band (the same linear filter keeps e = X a): the model's misfit above
    # it, where the sweep hardly excites the path, correlates with the harmonic columns by chance and
    # was taken for a nonlinearity (a clean random helmet at 1.01x the floor: 38 % "explained", 0.003 %
    # in band), and a polynomial that explains it could not lower the validation error anyway.
    band = scipy.signal.butter(4, VALIDATION_BAND, "bandpass", fs=model.fs, output="sos")
    X = scipy.signal.sosfilt(band, np.vstack(rows), axis=0)
    e = scipy.signal.sosfilt(band, np.concatenate(targets))
    e = e - e.mean()
    coef_linear, *_ = np.linalg.lstsq(X[:, :1], e, rcond=None)
    energy_linear = float(np.sum((e - X[:, :1] @ coef_linear) ** 2))
    coef, *_ = np.linalg.lstsq(X, e, rcond=None)
    energy_full = float(np.sum((e - X @ coef) ** 2))
    return InputPolynomial(coef, energy_linear, energy_full, e.size)
