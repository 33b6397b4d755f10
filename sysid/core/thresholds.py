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
__all__ += ["SETTLE_DROPS"]

# Out-of-band poles dropped at most from a pick whose simulation disagrees with the sweeps' spectra
# (``sysid.identify``'s settling of the order search's pick).
SETTLE_DROPS = 4



# ---------------------------------------------------------------------------------------------------------------------
# The delay (sysid.estimation.delay: the one place it is decided).
# ---------------------------------------------------------------------------------------------------------------------
__all__ += ["ONSET_COHERENCE", "ONSET_PEAK_FRACTION", "ONSET_NOISE_MULTIPLE", "DELAY_WINDOW", "DELAY_WIDEST",
            "DELAY_TOLERANCE", "DELAY_DIP", "DELAY_REFIT_ITERATIONS", "WALK_SPAN", "WALK_CLEAR", "WALK_STEP",
            "DELAY_TRIES", "FREED_ORDERS", "SHORTER_BY", "MAX_EXTRA_DELAY"]

# The onset (``estimate_latency``): the band ends where the 9-bin averaged squared coherence falls to
# ONSET_COHERENCE; the onset is the first sample above ONSET_PEAK_FRACTION of the peak and ONSET_NOISE_MULTIPLE
# times the RMS of the response at negative times.
ONSET_COHERENCE = 0.5
ONSET_PEAK_FRACTION = 0.1
ONSET_NOISE_MULTIPLE = 6.0
# ``refine_delay``: the fixed-pole costs' first window, DELAY_WINDOW samples either side of the onset's delay, grown
# by as much at a time up to DELAY_WIDEST; a delay is within the tolerance when its cost is within DELAY_TOLERANCE
# output-noise variances sigma^2 = V / (2 M) (M bins) of the smallest. A cost dip past the answer is refitted when
# within DELAY_DIP of the smallest cost; each refit runs DELAY_REFIT_ITERATIONS output-error iterations (a start near
# the answer converges in a few).
DELAY_WINDOW = 4
DELAY_WIDEST = 12
DELAY_TOLERANCE = 40.0
DELAY_DIP = 0.10
DELAY_REFIT_ITERATIONS = 10
# ``walk_delay``: samples it may move from refine_delay's answer (further when the band's kernel lead is longer);
# it walks up until a cost rises WALK_CLEAR sigma^2 above the smallest (past the true delay the cost rises by 3 %
# to 20x a sample where the response's first sample is not small, thousands of sigma^2), and refits again from the
# best core's poles the delays within it; it decides up from the smallest cost through costs within WALK_STEP
# sigma^2 of it (``_decided``).
WALK_SPAN = 12
WALK_CLEAR = 20.0
WALK_STEP = 2.0
# ``moved_delay``, after identify's order search: delays walked to tried at most on the sweeps, longest first;
# lower orders refitted behind a moved delay (their poles need not imitate it).
DELAY_TRIES = 3
FREED_ORDERS = 2
# ``shorter_delays``, after a data correction's refit: samples the onset may read long (``refine_delay``'s window
# below the onset), the delays the core is identified anew behind.
SHORTER_BY = 4
# The delay detector's fixed-pole scan: total delays up to the model's and this many more.
MAX_EXTRA_DELAY = 120



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
__all__ += ["WARM_ENOUGH", "EIV_MIN_ATTENUATION", "CLIPPING_PASSES", "CLOCK_AR_ORDER", "CLOCK_AR_FLOOR", "CLOCK_PASSES"]

# A warm start within this factor of the noise floor makes the re-identification needless. Stricter
# than AT_FLOOR: a warm start "at the floor" by AT_FLOOR may still lie 20 % above what a fresh fit
# reaches (the README's delay-and-hum example: 1.15x warm, 1.01x re-identified).
WARM_ENOUGH = 1.05
# ``add_input_noise``: the H1 attenuation 1 - P_n / S_uu is not divided out below this (bins where the input
# is mostly its own noise carry next to nothing of the path; dividing by a tiny factor would only amplify noise).
EIV_MIN_ATTENUATION = 0.2
# Passes of the refit on data with excluded stretches: each fills them with the last model's prediction.
CLIPPING_PASSES = 3
# Order of the residual's AR model that whitens the clock ratio's regression (``clock_residual``), and its white
# floor (diagonal loading) relative to the residual's power.
CLOCK_AR_ORDER = 32
CLOCK_AR_FLOOR = 0.01
# Passes of the clock ratio's refinement after a clock correction's refit (``refined_clock``).
CLOCK_PASSES = 2
