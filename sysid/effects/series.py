"""What the series-factor effects share: parameters left out of ``refine --add`` fitted on the sweeps."""

from __future__ import annotations

from ..core.errors import IdentificationError

__all__ = ["complete_factor"]


def complete_factor(family: str, frequency: str):
    """``complete`` of a built-in factor family: without its frequency, the whole factor is the one
    that best explains the sweeps (``sysid.findings.dynamics.fit_factor``)."""
    def complete(params, ctx, before):
        if params[frequency] is None:
            from ..findings.dynamics import GAIN, fit_factor  # the detectors load when first asked
            fitted = fit_factor(ctx, family)
            if not fitted.interior or fitted.rms * GAIN > before.rms:
                raise IdentificationError(f"--add {family}: the sweeps show no {family} the model lacks; "
                                          f"give {family}:{frequency}=...")
            params.update(fitted.params)
        return params
    return complete
