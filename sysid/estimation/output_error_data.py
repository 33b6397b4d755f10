"""The data of output-error refinement: the DFT bins of one block of a noise recording inside the band.

For a block of L samples of input u and ear signal y (channel means removed), the
DFTs U_k, Y_k at z_k = e^{j 2 pi k / L} inside the identification band are what
``sysid.estimation.output_error`` fits (McKelvey, "Frequency domain identification
methods", Circuits Systems Signal Process. 21(1), 2002, eq. 7). The block is the first
``max_seconds`` of the recording after its transient; its length L also bounds how slow a
refined pole may be (``sysid.estimation.modal_parametrisation.decay_bound``).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..core.errors import IdentificationError
from ..core.thresholds import IDENTIFICATION_BAND
from ..io.recordings import Recording
from ..validation.sweeps import rfft_pair

__all__ = ["BlockData", "block_data"]


@dataclass
class BlockData:
    """DFT bins of one data block inside the band: z_k, U_k, Y_k, and the block length."""

    z: np.ndarray
    U: np.ndarray
    Y: np.ndarray
    length: int
    fs: float


def block_data(noise: Recording, band=IDENTIFICATION_BAND, max_seconds: float | None = 10.0) -> BlockData:
    """The band's DFT bins of (at most max_seconds of) a noise recording after its transient."""
    n = noise.u.size if max_seconds is None else min(noise.u.size, int(round(max_seconds * noise.fs)))
    if n < 16:
        raise IdentificationError(f"{noise.path}: too short for output-error refinement")
    f = np.fft.rfftfreq(n, 1 / noise.fs)
    inside = (f >= band[0]) & (f <= band[1])
    u = noise.u[:n] - noise.u[:n].mean()
    y = noise.y[:n] - noise.y[:n].mean()
    U, Y = rfft_pair(u, y)
    return BlockData(np.exp(2j * np.pi * f[inside] / noise.fs), U[inside], Y[inside], n, noise.fs)
