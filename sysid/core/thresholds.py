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

# The validation band (Hz): the swept sines' band, where a model's validation rms and the noise floor are
# taken (design.md, "Compare"; ``sysid.validation.sweeps``).
VALIDATION_BAND = (20.0, 4000.0)
# Each sweep's first seconds are left out of the validation rms and the noise floor.
SKIP_S = 0.05

__all__ += ["VALIDATION_BAND", "SKIP_S"]



# ---------------------------------------------------------------------------------------------------------------------
# Recordings and their data quality (sysid.io).
# ---------------------------------------------------------------------------------------------------------------------



# ---------------------------------------------------------------------------------------------------------------------
# Detectors (sysid.findings), one block per detector module.
# ---------------------------------------------------------------------------------------------------------------------

# Series factors (sysid.findings.dynamics). A family is the finding when its factor lowers the rms by
# EXPLAINS_GAIN, removes FACTOR_SHARE of the error power above the floor and is not held at a bound
# of its parameters (within FACTOR_EDGE of it; frequency and Q fitted as logarithms); among families
# within FACTOR_SIMPLER of each other the one with fewer parameters wins, and a resonance needs
# RESONANCE_MIN_GAIN_DB of peak or dip.
FACTOR_SHARE = 0.8
FACTOR_SIMPLER = 1.03
FACTOR_EDGE = 0.01
RESONANCE_MIN_GAIN_DB = 1.0
# Bounds of the fitted parameters. Q beyond 30 would let a line fit a hum bin; below 1 a "resonance" is
# a broad gain change, not a mode. f0 from 25 Hz to 0.95 of the top of the fitted band. Corners in Hz.
RESONANCE_Q_RANGE = (1.0, 30.0)
RESONANCE_F0_RANGE = (25.0, 0.95)
RESONANCE_GAIN_RANGE_DB = (-30.0, 30.0)
HIGHPASS_RANGE = (1.0, 1000.0)
LOWPASS_RANGE = (150.0, 20000.0)

# Input noise (sysid.findings.input_noise). H1 biased low by at least INPUT_NOISE_BIAS_DB (median over
# INPUT_NOISE_BIAS_BAND, Hz) is the finding; the bound the input noise sets is stated from
# INPUT_NOISE_BOUND_EXCESS times the floor, and bounds the validation error when it carries at least
# INPUT_NOISE_BOUND_SHARE of the error power above the floor, (bound^2 - 1) / (excess^2 - 1): every input
# channel has some noise (61 dB SNR leaves the true path at 1.1x), and a model far above the floor for
# another effect is not bounded by it; that effect is named first and the bound once the error comes
# down to it.
INPUT_NOISE_BIAS_DB = 0.1
INPUT_NOISE_BIAS_BAND = (20.0, 1500.0)
INPUT_NOISE_BOUND_EXCESS = 1.1
INPUT_NOISE_BOUND_SHARE = 0.1

# Clock drift and time variation (sysid.findings.variation). Clock drift: at least DRIFT_PPM, with the
# trend DRIFT_T standard errors from zero. Time variation: the halves of the noise recording differ
# VARIATION_RATIO times more than interleaved segments (median over bins). Between recordings: the low
# band (below VARIATION_LOW_HZ) moves against the band above by VARIATION_CHANGE_DB and
# VARIATION_CHANGE_T standard errors of the noise recording's levels.
DRIFT_PPM = 3.0
DRIFT_T = 10.0
VARIATION_RATIO = 4.0
VARIATION_LOW_HZ = 300.0
VARIATION_CHANGE_DB = 0.3
VARIATION_CHANGE_T = 6.0

# The report's grid (report.data), recomputed for a model without its identification run: the picture
# of the seed's appendix C over a modest range at a fraction of the cost.
MODEST_GAMMAS = tuple(range(10, 1001, 90))
MODEST_ORDERS = tuple(range(1, 13))

__all__ += ["FACTOR_SHARE", "FACTOR_SIMPLER", "FACTOR_EDGE", "RESONANCE_MIN_GAIN_DB", "RESONANCE_Q_RANGE",
            "RESONANCE_F0_RANGE", "RESONANCE_GAIN_RANGE_DB", "HIGHPASS_RANGE", "LOWPASS_RANGE", "INPUT_NOISE_BIAS_DB",
            "INPUT_NOISE_BIAS_BAND", "INPUT_NOISE_BOUND_EXCESS", "INPUT_NOISE_BOUND_SHARE", "DRIFT_PPM", "DRIFT_T",
            "VARIATION_RATIO", "VARIATION_LOW_HZ", "VARIATION_CHANGE_DB", "VARIATION_CHANGE_T", "MODEST_GAMMAS",
            "MODEST_ORDERS"]



# ---------------------------------------------------------------------------------------------------------------------
# Refinement: the structures and data corrections refine adds (sysid.refits).
# ---------------------------------------------------------------------------------------------------------------------
