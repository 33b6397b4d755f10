"""The thresholds of diagnosis and refinement, and the bands and durations they share, in one place.

Every figure here is a ratio of validation rms values (``sysid.validation.compare``: rms in
band over the noise floor from the two repeated sweeps) unless its name says
otherwise. Detectors and ``refine`` import them from here, so the meaning of
"at the floor" or "explains the error" is the same everywhere.
"""

from __future__ import annotations

__all__ = ["AT_FLOOR", "EXCESS", "UNDER_MODELLED_EXCESS", "EXPLAINS_GAIN", "FACTOR_EXPLAINS", "WORSE",
           "IDENTIFICATION_BAND", "TRANSIENT_S", "MAX_AUTO_STEPS", "RUN_TO_RUN_MIN", "LEADING_PHASE_DEG",
           "LINE_RATIO"]

# Validation rms at most this many times the noise floor counts as at the floor.
AT_FLOOR = 1.2
# Detectors of plant effects look only at models at least this far above the floor.
EXCESS = 1.2
# Above this many times the floor, "nothing significant" is never the answer: under-modelled is.
UNDER_MODELLED_EXCESS = 2.0
# A structure explains the error when it lowers the validation rms by this factor.
EXPLAINS_GAIN = 1.25
# A series factor that brings the sweeps this close to the floor settles a tie with a delay.
FACTOR_EXPLAINS = 2.0
# A missing delay whose excess phase at the top of the validation band exceeds this (degrees) ranks
# first: every detector that judges the residual against the model's linear prediction (the input
# polynomial, more order, a series factor) sees the delay's misfit as well, so it is added first.
LEADING_PHASE_DEG = 90.0
# ``refine --add``: a refinement that raises the validation rms by more than this is called worse.
WORSE = 1.02

# Band (Hz) of the identification and of the detectors that work on the noise recording.
IDENTIFICATION_BAND = (20.0, 5000.0)
# The first seconds of a noise recording are transient (design.md, "Who uses it").
TRANSIENT_S = 3.0

# ``refine --auto``: at most this many steps; a step is kept only if it lowers the validation rms
# by more than the run-to-run noise of that figure, and never by less than this fraction.
MAX_AUTO_STEPS = 8
RUN_TO_RUN_MIN = 0.01

# A spectral line (hum, engine order: ``sysid.io.lines.find_lines``) is a local maximum of the ear's
# periodogram more than this many times the median of its neighbourhood, where the input's is not.
LINE_RATIO = 40.0


# ---------------------------------------------------------------------------------------------------------------------
# Identification: the order search, the settling of a pick, the reduction (sysid.identify, sysid.estimation).
# ---------------------------------------------------------------------------------------------------------------------



# ---------------------------------------------------------------------------------------------------------------------
# The delay (sysid.estimation.delay: the one place it is decided).
# ---------------------------------------------------------------------------------------------------------------------



# ---------------------------------------------------------------------------------------------------------------------
# Validation on the sweeps (sysid.validation).
# ---------------------------------------------------------------------------------------------------------------------



# ---------------------------------------------------------------------------------------------------------------------
# Recordings and their data quality (sysid.io).
# ---------------------------------------------------------------------------------------------------------------------



# ---------------------------------------------------------------------------------------------------------------------
# Detectors (sysid.findings), one block per detector module.
# ---------------------------------------------------------------------------------------------------------------------



# ---------------------------------------------------------------------------------------------------------------------
# Refinement: the structures and data corrections refine adds (sysid.refits).
# ---------------------------------------------------------------------------------------------------------------------
