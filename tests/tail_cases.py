"""Measured responses capped below the states they need: the reverberant-tail test's and benchmark's models.

A session through a measured response (``sysid.simulate.measured_session``; credits in sysid/core/data) and the
model identify gives under a state cap: the frequency-limited truncation of the session's least-squares FIR at
the cap, balanced, with the cap in its provenance.
"""

from sysid.core import lti
from sysid.core.model import Model
from sysid.core.thresholds import IDENTIFICATION_BAND, TRANSIENT_S
from sysid.estimation.long_response import fir_estimate, frequency_limited_truncation
from sysid.simulate import measured_session

__all__ = ["CAPPED", "capped_session"]

# The cap (states) of each capped model, well below what its response needs, and the FIR it is truncated from.
CAPPED = {"fabian_left_az60": (12, 256), "hptf_hd600_left": (60, 2048)}


def capped_session(name: str, **spec):
    """(session of ``measured_session(name, **spec)``, its model capped at ``CAPPED[name]`` states)."""
    session = measured_session(name, **spec)
    noise = session.noise
    order, length = CAPPED[name]
    taps = fir_estimate(noise.u, noise.y, noise.fs, length, int(TRANSIENT_S * noise.fs)).taps
    system, _ = frequency_limited_truncation(taps, noise.fs, (0.0, IDENTIFICATION_BAND[1])).realisation(order)
    A, B, C, D = lti.balanced_realisation(*system)
    model = Model(path="fb", fs=noise.fs, A=A, B=B, C=C, D=D,
                  identification={"method": "long estimate, frequency-limited truncation", "order": order,
                                  "max_order": order, "noise_file": noise.path})
    return session, model
