"""The registry of physical effects: one module per effect, one ``Effect`` object each.

An ``Effect`` holds everything the product knows about one physical effect a
low-order model misses (effects.md): its name, its parameters with units and
ranges (``sysid.core.effect_spec.ParameterSpec``) for ``simulate --effect`` and for
``refine --add``, how ``simulate`` adds it (a series factor, or the session
simulator's own code for the effects that act on the recordings), its detector
(score, significance, estimates, explanation, remedy; ``sysid.findings``), the
detectors whose findings it reads (``needs``), the model structure or data
correction ``refine`` adds (``build``), the finding parameters ``refine --auto``
passes on (``auto_params``), and the kind of figure the report draws for it.

``simulate``, ``diagnose``, ``refine`` and the report look effects up here; an
effect a user writes is one module that builds an ``Effect`` and calls
``register`` (README, "Your own effect"), and is then simulated, diagnosed and
refined like the built-in ones. The built-in effects register on import of this
package, in the order below, which is also the order their detectors run in
when ``needs`` does not say otherwise. They name their detectors and builders by
reference (``"sysid.refits:add_delay"``, ``sysid.effects.references``), resolved
when first read: the registry loads neither ``sysid.findings`` nor ``sysid.refits``
until ``diagnose`` or ``refine`` asks for them, so ``sysid.simulate`` stands without
the estimation stack.
"""

from __future__ import annotations

from . import registry as _registry
from .registry import *  # noqa: F401,F403

__all__ = list(_registry.__all__)


def _load_builtin() -> None:
    # One module per effect; importing it registers its Effect.
    # the order is that of the detectors: data quality, the series factors, the delay (which settles
    # a tie with them), then what the plant's misfit leaves, the reverberant tail, under-modelled last.
    from . import dc_offset, clipping  # noqa: F401
    from . import resonance, highpass, lowpass  # noqa: F401
    from . import delay, input_nonlinearity, periodic_disturbance, input_noise  # noqa: F401
    from . import clock_drift, time_variation, reverberant_tail, under_modelled  # noqa: F401


_load_builtin()

