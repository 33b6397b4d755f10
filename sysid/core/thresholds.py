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

# Output-error refinement (sysid.estimation.output_error, sysid.estimation.modal_parametrisation).
# A pole counts as at the radius bound when its decay rate -ln|p| is within this fraction above
# the bound's (``at_radius_bound``).
AT_RADIUS_BOUND = 0.01
# A pair whose angle is below NEAR_REAL_PAIR times its decay rate is refined as two real poles
# (``split_near_real_pairs``), of decay rates NEAR_REAL_SPLIT above and below the pair's.
NEAR_REAL_PAIR = 1e-3
NEAR_REAL_SPLIT = 0.1
__all__ += ["AT_RADIUS_BOUND", "NEAR_REAL_PAIR", "NEAR_REAL_SPLIT"]



# ---------------------------------------------------------------------------------------------------------------------
# The delay (sysid.estimation.delay: the one place it is decided).
# ---------------------------------------------------------------------------------------------------------------------



# ---------------------------------------------------------------------------------------------------------------------
# Validation on the sweeps (sysid.validation).
# ---------------------------------------------------------------------------------------------------------------------



# ---------------------------------------------------------------------------------------------------------------------
# Recordings and their data quality (sysid.io).
# ---------------------------------------------------------------------------------------------------------------------

# The ear channel heard (sysid.io.ear_channel). An ear channel below half a 16-bit LSB (RMS) is
# digital silence: nothing is connected.
SILENT_RMS = 2.0**-16
# Median magnitude-squared coherence between input and ear channel, in EAR_COHERENCE_BAND_HZ, below
# which the ear microphone does not hear the path at all. It is estimated on stretches short enough
# that an ear clock off by up to a few hundred ppm (effects.md, clock drift) slips by no more than
# a few samples inside one: over a whole recording such a slip turns the cross-spectrum's phase
# and the averaged coherence of a healthy channel collapses above a few hundred Hz (60 ppm over
# 20 s: median 0.01). A sweep, whose every frequency is excited only briefly, is judged over the
# whole recording instead (a stretch of it excites a few bins only): the larger of the two counts.
UNCORRELATED_COHERENCE = 0.1
EAR_COHERENCE_BAND_HZ = (100.0, 4000.0)
# Welch segment of that coherence (samples), and up to EAR_COHERENCE_STRETCHES stretches of
# EAR_COHERENCE_STRETCH samples spread over the recording.
EAR_COHERENCE_SEGMENT = 512
EAR_COHERENCE_STRETCH = 32 * EAR_COHERENCE_SEGMENT
EAR_COHERENCE_STRETCHES = 8

# Which channel is the input (sysid.io.channels: the direction of the path's group delay).
# Segment of the spectra: 2048 samples resolve 21.5 Hz at 44.1 kHz, enough to unwrap the
# phase of a path delayed by up to 1024 samples (23 ms, 8 m of sound path).
CHANNEL_ORDER_SEGMENT = 2048
# Band (Hz) of the group delay: the sweeps' band less its lowest octaves, where a high-pass leaves
# little coherence.
CHANNEL_ORDER_BAND_HZ = (100.0, 4000.0)
# Bins whose magnitude-squared coherence is below this carry no usable phase.
CHANNEL_ORDER_COHERENT = 0.5
# Fewer coherent bins than this: no judgement (the ear checks of sysid.io.ear_channel apply).
CHANNEL_ORDER_MIN_BINS = 16
# A mean group delay of at least this many samples (either sign) tells the order.
CHANNEL_ORDER_LEAD_SAMPLES = 1.0
# At most this much of a recording is examined (s): the direction does not change along it.
CHANNEL_ORDER_EXCERPT_S = 10.0
__all__ += ["SILENT_RMS", "UNCORRELATED_COHERENCE", "EAR_COHERENCE_BAND_HZ", "EAR_COHERENCE_SEGMENT",
            "EAR_COHERENCE_STRETCH", "EAR_COHERENCE_STRETCHES", "CHANNEL_ORDER_SEGMENT", "CHANNEL_ORDER_BAND_HZ",
            "CHANNEL_ORDER_COHERENT", "CHANNEL_ORDER_MIN_BINS", "CHANNEL_ORDER_LEAD_SAMPLES", "CHANNEL_ORDER_EXCERPT_S"]



# ---------------------------------------------------------------------------------------------------------------------
# Detectors (sysid.findings), one block per detector module.
# ---------------------------------------------------------------------------------------------------------------------



# ---------------------------------------------------------------------------------------------------------------------
# Refinement: the structures and data corrections refine adds (sysid.refits).
# ---------------------------------------------------------------------------------------------------------------------
