"""The structures and data corrections ``refine`` adds, one builder per effect (design.md).

Each builder ``add_X(model, noise, sweeps, params, options, transient_s)`` returns (the refined
model, extra parameters for its history entry); the effect registry (``sysid.effects``) names the
builder of each effect (``"sysid.refits:add_delay"``). The model chain is
[input polynomial] -> [z^-delay] -> (A, B, C, D).

- ``structures``: what a builder adds to the model (delay, input polynomial, disturbance, a series
  factor, a mode, more order, the errors-in-variables estimate);
- ``corrections``: what a builder corrects in the data (DC offset, clock drift, clipping), and the
  refit on the corrected data;
- ``long_estimate``: more states from the long least-squares estimate (a reverberant tail);
- ``state_cap``: the state cap refinement holds a model to (``max_order``);
- ``nonlinear_order``: the core's order chosen again behind a fitted input map (``fewest_states``);
- ``machinery``: the warm starts and re-identifications both share (``REFIT_OPTIONS``, ``WARM_ENOUGH``).
"""

from __future__ import annotations

from . import corrections as _corrections
from . import long_estimate as _long_estimate
from . import machinery as _machinery
from . import state_cap as _state_cap
from . import structures as _structures
from .corrections import *  # noqa: F401,F403
from .long_estimate import *  # noqa: F401,F403
from .machinery import *  # noqa: F401,F403
from .state_cap import *  # noqa: F401,F403
from .structures import *  # noqa: F401,F403

__all__ = [*_machinery.__all__, *_structures.__all__, *_corrections.__all__, *_long_estimate.__all__, *_state_cap.__all__]
