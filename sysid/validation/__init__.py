"""A model against the measured sweeps: the validation error, its noise floor, and the comparison.

``sweeps``: the validation rms of a model on the two repeated swept-sine recordings
and their noise floor; ``compare``: fit, error per band against the floor, residual
tests. The names of both are also importable from here (``sysid.validation`` was one
module before it became this folder).
"""

from . import compare as _compare
from . import sweeps as _sweeps
from .compare import *  # noqa: F401,F403
from .sweeps import *  # noqa: F401,F403

__all__ = [*_sweeps.__all__, *_compare.__all__]
