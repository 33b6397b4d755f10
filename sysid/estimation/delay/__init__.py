"""The pure delay of a sound path: the one place every rule that decides it lives.

Converter latency and the acoustic path put d samples of pure delay in front of the plant, and
a rational core of modest order imitates delay only with many poles, so the core is fitted on
delay-compensated data (the ear signal advanced by d) and d goes into the model's ``delay``.
The rule, in the order the pipeline applies it:

1. ``onset``: the first reading, the onset of the band-limited H1 impulse response of the
   noise recording, less one (``estimate_latency``). It errs short by the smoothing kernel's
   lead, 1 to 4 samples on most random helmets, and long on a slowly rising response.
2. ``costs``: the core fitted behind that delay says by how much (``refine_delay``): the
   output-error cost with its poles held fixed stays at the noise level for every delay the
   core's spare poles can imitate and rises past the true one; read long, the cost falls
   below the onset's delay and the refitted costs there decide. The ear signal's lines the
   input lacks are taken out first (``without_residual_lines``). The delay detector scans
   the same cost (``fixed_pole_scan``, ``generic_pole_scan``).
3. ``walk``: read short or right, the core refitted one sample of delay at a time settles it
   (``walk_delay``): up from the smallest refitted cost through costs within the noise of it.
   ``decide_delay`` runs 2 and 3: the one decision.
4. ``trials``: the sweeps have the last word. ``identify`` keeps a delay its pick's core decides
   only when a core refitted behind it validates as well as the pick (``moved_delay``).

Short is the safe side throughout: a core behind a delay a sample too short imitates the
sample nearly free, one behind a delay too long cannot be causal. The tunables are in
``sysid.core.thresholds`` (section "The delay").
"""

from __future__ import annotations

from . import costs as _costs
from . import onset as _onset
from . import trials as _trials
from . import walk as _walk
from .costs import *  # noqa: F401,F403
from .onset import *  # noqa: F401,F403
from .trials import *  # noqa: F401,F403
from .walk import *  # noqa: F401,F403

__all__ = [*_onset.__all__, *_costs.__all__, *_walk.__all__, *_trials.__all__]
