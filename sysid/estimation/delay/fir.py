"""The long route's delay: the leading taps of the least-squares FIR that the data cannot tell from zero.

A measured response rises slowly (a dummy head's HRIR climbs over several samples to its peak,
a headphone's pre-ringing sits 40-60 dB below it), so there is no clean onset to read: a
threshold on the peak reads it short or long by as many samples as the rise lasts. The FIR
estimate of the noise recording (``sysid.estimation.long_response.fir_estimate``) answers
instead what the delay is for: which leading taps can a model leave out. Holding the first d
taps at zero and refitting the others raises the residual by

    Delta(d) = g_d^T [(R^-1)_dd]^-1 g_d,

which over the residual variance sigma^2 is chi-square with d degrees of freedom when those taps
are zero (the F-test of nested linear models; Soederstroem & Stoica, "System Identification",
1989, sec. 11.5), whatever the input's spectrum: the test is in the band the data excite, with
no band-limiting kernel to smear the response's rise backwards or forwards. The delay is the
largest d whose leading taps pass at ``FIR_DELAY_SIGNIFICANCE``.

Leading taps that pass change the ear signal by less than the test resolves: chi-square's
quantile, a few d noise variances over the whole recording, an RMS of about sqrt(d / N) of the
output noise (N samples: 1e-3 of it). A response whose first taps carry any energy the data
can see gets the delay before them, however far below its peak they lie (the FABIAN HRIR's
first ten taps, 45-60 dB below its peak at sample 11, are 160 times the estimate's noise per tap,
and leaving out even the first raises the validation rms 1.9 times: its delay is 0). Erring
short: a delay the test cannot decide between is the shorter one only when a longer passes
nowhere, and the FIR must hold the response (``long_response.response_length``), or the
residual's unmodelled ringing is not the white noise the test assumes.

The model's core has no direct term and adds one sample of its own, so the model's ``delay`` is
d - 1 (d = 0: no delay line, and the core keeps its direct term).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.stats

from ...core.thresholds import FIR_DELAY_SIGNIFICANCE
from ..long_response import FirEstimate

__all__ = ["FirDelay", "fir_delay"]


@dataclass(frozen=True)
class FirDelay:
    """The leading taps (``taps``) of an FIR estimate that the data cannot tell from zero, at ``fs`` Hz.

    ``statistic[d]``: the rise of the residual with the first d taps held at zero, in noise variances;
    ``limit[d]``: its chi-square quantile at ``significance``.
    """

    taps: int
    fs: float
    significance: float
    statistic: np.ndarray
    limit: np.ndarray

    @property
    def samples(self) -> int:
        """The model's delay line (samples): the core's own sample comes after it."""
        return max(self.taps - 1, 0)

    @property
    def feedthrough(self) -> bool:
        """True when the response starts at lag 0: the core needs its direct term."""
        return self.taps == 0

    def to_dict(self) -> dict:
        return {"samples": self.samples, "method": "leading taps of the least-squares FIR the data cannot tell from "
                                                   f"zero (chi-square test of nested fits, p = {self.significance:g})"}


def fir_delay(estimate: FirEstimate, max_delay: int | None = None,
              significance: float = FIR_DELAY_SIGNIFICANCE) -> FirDelay:
    """The delay of ``estimate`` (module docstring), at most ``max_delay`` taps (default: half the estimate's)."""
    limit = estimate.length // 2 if max_delay is None else min(int(max_delay), estimate.length // 2)
    energy = estimate.lead_energy(limit)
    sigma2 = max(estimate.residual_variance, np.finfo(float).tiny)
    statistic = energy / sigma2
    d = np.arange(statistic.size)
    limit = np.where(d > 0, scipy.stats.chi2.isf(significance, np.maximum(d, 1)), 0.0)
    passing = np.flatnonzero(statistic <= limit)
    return FirDelay(int(passing[-1]), estimate.fs, float(significance), statistic, limit)
