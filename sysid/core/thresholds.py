"""The thresholds of diagnosis and refinement, and the bands and durations they share, in one place.

Every figure here is a ratio of validation rms values (``sysid.validation.compare``: rms in
band over the noise floor from the two repeated sweeps) unless its name says
otherwise. Detectors and ``refine`` import them from here, so the meaning of
"at the floor" or "explains the error" is the same everywhere.
"""

from __future__ import annotations

__all__ = ["AT_FLOOR", "EXCESS", "UNDER_MODELLED_EXCESS", "EXPLAINS_GAIN", "FACTOR_EXPLAINS", "WORSE",
           "IDENTIFICATION_BAND", "TRANSIENT_S", "NOISE_AFTER_TRANSIENT_S", "MAX_AUTO_STEPS", "RUN_TO_RUN_MIN", "LEADING_PHASE_DEG",
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
# A noise recording must hold more than this after its transient (s): identify, diagnose and report
# alike (sysid.io.recordings.check_noise_length). The most any of them needs: the time-variation and
# clock-drift detectors compare 8 segments of 4410 samples (10 Hz resolution), 0.8 s at 44.1 kHz;
# identify needs one averaging segment of the 20 Hz grid (0.05 s).
NOISE_AFTER_TRANSIENT_S = 0.8

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
__all__ += ["DEFAULT_GAMMAS", "DEFAULT_ORDERS", "GRID_KEEP_BEST", "START_GAMMAS", "ORDER_AT_FLOOR", "MIN_GAIN",
            "ORDER_PATIENCE", "NEAR_FLOOR", "NEAR_PATIENCE", "INSERT_PATIENCE", "SCAN_ITERATIONS", "REFINED_STARTS",
            "SCREEN_RATIO", "NEW_MODE_Q", "INSERT_FREQUENCIES", "INSERT_Q", "INSERT_REFINED", "INSERT_ROUNDS",
            "START_REAL_POLES", "START_COINCIDE", "START_SEPARATION", "BLOCK_NOISE_SIGMAS", "SETTLE_DROPS",
            "BALANCED_TOLERANCE", "NEGLIGIBLE_HSV", "BOUND_REFIT_ITERATIONS", "TAIL_FRACTIONS", "TRUNCATION_GAIN",
            "POLISH_ITERATIONS"]

# The seed's grid (``sysid.estimation.grid``): smoothing widths gamma and orders n, and the candidates of lowest
# compressed validation rms re-evaluated exactly at every sweep bin.
DEFAULT_GAMMAS = tuple(range(10, 1001, 10))
DEFAULT_ORDERS = tuple(range(1, 21))
GRID_KEEP_BEST = 10
# The order search (``sysid.estimation.order_search``). Smoothing widths whose subspace models start every order,
# besides the grid's best of that order.
START_GAMMAS = (30, 100, 300)
# It ends once a model validates within ORDER_AT_FLOOR times the noise floor; ``identify`` picks the lowest order
# within MIN_GAIN (relative) of the best validation rms, and a trial counts when it validates within MIN_GAIN too.
ORDER_AT_FLOOR = 1.02
MIN_GAIN = 0.03
# It ends after ORDER_PATIENCE orders without 1 % gain, or NEAR_PATIENCE near the floor (within NEAR_FLOOR times
# it, or the residual at the block's noise level); a missed mode is inserted after INSERT_PATIENCE orders without
# gain above NEAR_FLOOR times the floor. Output-error iterations of each refined start: SCAN_ITERATIONS.
ORDER_PATIENCE = 6
NEAR_FLOOR = 1.5
NEAR_PATIENCE = 2
INSERT_PATIENCE = 3
SCAN_ITERATIONS = 20
# Refined starts per order (the best by the fixed-pole cost), the second only when its cost is within SCREEN_RATIO
# of the first's; the quality factor of a mode placed at the largest residual.
REFINED_STARTS = 2
SCREEN_RATIO = 2.0
NEW_MODE_Q = 10.0
# Mode insertion after a stalled scan (``_insert_modes``): a pair of each Q of INSERT_Q at each of
# INSERT_FREQUENCIES log-spaced frequencies across the block's band is screened, the best INSERT_REFINED refined,
# for up to INSERT_ROUNDS rounds while a round gains 1 %.
INSERT_FREQUENCIES = 40
INSERT_Q = (3.0, 20.0)
INSERT_REFINED = 3
INSERT_ROUNDS = 3
# Real poles a start may take for a pole it adds or replaces (``distinct_start``), the usual added pole 0.5 first:
# roll-off corners (a real pole exp(-2 pi f_c / f_s) is 0.07-0.88 for 1-20 kHz at 48 kHz), coupling high-pass
# corners near z = 1, and negative poles for what lies near Nyquist.
START_REAL_POLES = (0.5, 0.3, 0.7, 0.1, 0.85, -0.3, 0.93, 0.97, -0.7, 0.99)
# Distance below which two poles of a start coincide, and the least distance of a placed real pole from every
# other pole of the start.
START_COINCIDE = 1e-6
START_SEPARATION = 1e-2
# A block residual within this many standard deviations of the noise energy the floor predicts is at the block's
# noise level (``block_at_noise``).
BLOCK_NOISE_SIGMAS = 3.0
# Out-of-band poles dropped at most from a pick whose simulation disagrees with the sweeps' spectra
# (``sysid.identify``'s settling of the order search's pick).
SETTLE_DROPS = 4
# The reduction (``sysid.estimation.reduction``). Largest departure of a balanced realisation's Gramians from one
# diagonal matrix, relative to the largest Hankel singular value (the square-root method reaches 1e-9; a
# realisation it gave up on is off by orders of magnitude); Hankel singular values, relative to the largest, below
# which a state is left out when the model cannot be balanced at its full order (a change of the response below
# 2 n 1e-10 of the peak).
BALANCED_TOLERANCE = 1e-6
NEGLIGIBLE_HSV = 1e-10
# Evaluations of the refit without the poles at the radius bound: one, the kept poles held and the rest (B, D,
# the block's transient) refitted by linear least squares. On the final 10 s block an evaluation costs about
# 0.1 s; the thesis-length random helmets 0 and 79 reached the same validation rms with 1 as with 20 (4 used),
# the step's CPU 0.31 -> 0.25 s and 0.55 -> 0.25 s.
BOUND_REFIT_ITERATIONS = 1
# Sums of the removed Hankel singular values, relative to the largest, of the truncations tried (lowest order
# first), and the rise of the validation rms a truncation may cost: a third of the order search's MIN_GAIN, so
# that a model near the 1.2x criterion is not traded for order. Evaluations of the refinement of a truncated
# model on the block (stopped sooner by the noise tolerance).
TAIL_FRACTIONS = (1e-3, 1e-4)
TRUNCATION_GAIN = 0.01
POLISH_ITERATIONS = 20

# Output-error refinement (sysid.estimation.output_error, sysid.estimation.modal_parametrisation).
# A pole counts as at the radius bound when its decay rate -ln|p| is within this fraction above
# the bound's (``at_radius_bound``).
AT_RADIUS_BOUND = 0.01
# A pair whose angle is below NEAR_REAL_PAIR times its decay rate is refined as two real poles
# (``split_near_real_pairs``), of decay rates NEAR_REAL_SPLIT above and below the pair's.
NEAR_REAL_PAIR = 1e-3
NEAR_REAL_SPLIT = 0.1
__all__ += ["AT_RADIUS_BOUND", "NEAR_REAL_PAIR", "NEAR_REAL_SPLIT"]

# The long route (sysid.estimation.long_route: a least-squares FIR of the noise recording, its frequency-limited
# balanced truncation to every order, then output error at the order chosen; sysid.estimation.long_response,
# sysid.estimation.delay.fir). The FIR's length: the fewest taps whose least-squares FIR validates on the sweeps
# within FIR_TAIL_SHARE of the noise floor's power of the best length's (the validation rms within half that share),
# found among FIR_LENGTHS lengths spaced geometrically, then by bisection; estimates of FIR_FIRST_TAPS taps and up, at most FIR_MAX_TAPS, on at most FIR_SECONDS of the noise recording after
# its transient. An estimate whose answer lies beyond FIR_HOLDS of its length does not hold the response.
FIR_TAIL_SHARE = 0.01
FIR_LENGTHS = 20
FIR_FIRST_TAPS = 1024
FIR_MAX_TAPS = 4096
FIR_HOLDS = 0.75
FIR_SECONDS = 20.0
# The long route's delay (sysid.estimation.delay.fir): the largest whose leading taps the data cannot tell from
# zero, by the chi-square test of the nested fits at this probability of calling zero taps a response.
FIR_DELAY_SIGNIFICANCE = 1e-3
__all__ += ["FIR_TAIL_SHARE", "FIR_LENGTHS", "FIR_FIRST_TAPS", "FIR_MAX_TAPS", "FIR_HOLDS", "FIR_SECONDS", "FIR_DELAY_SIGNIFICANCE"]
# The order/error curve (sysid.estimation.order_curve): the truncation ladder's orders, every one up to 12 and then a
# factor LADDER_STEP apart, validated on the sweeps' spectra in cells of at most LADDER_CELL_HZ and 1 / LADDER_CELLS
# of the FIR's resolution; the walk up ends after LADDER_PATIENCE orders without a gain of LADDER_GAIN (relative)
# once within LADDER_NEAR times the noise floor; the lowest order at the floor is found to within LADDER_RESOLUTION.
LADDER_STEP = 1.15
LADDER_CELL_HZ = 2.0
LADDER_CELLS = 40
LADDER_RESOLUTION = 0.02
LADDER_PATIENCE = 3
LADDER_GAIN = 0.01
LADDER_NEAR = 2.0
__all__ += ["LADDER_STEP", "LADDER_CELL_HZ", "LADDER_CELLS", "LADDER_PATIENCE", "LADDER_GAIN", "LADDER_NEAR",
            "LADDER_RESOLUTION"]
# The long route's refinement at the order chosen (sysid.estimation.long_route.refine_long): output error up to
# LONG_OE_ORDER states (above it one linear step, the numerator with the truncation's poles held), LONG_OE_ITERATIONS
# evaluations of a block of LONG_OE_SECONDS of the noise recording. Measured on the HD 600's short session (2 s block,
# 30 evaluations, 2 busy cores): 1.3 s at 30 states, 3.8 s at 60, 9.8 s at 100 and 150 s at 333, where it validated
# worse than the truncation it started from (1.25x against 1.09x).
LONG_OE_ORDER = 60
LONG_OE_ITERATIONS = 30
LONG_OE_SECONDS = 2.0
__all__ += ["LONG_OE_ORDER", "LONG_OE_ITERATIONS", "LONG_OE_SECONDS"]
# The order search's highest order when the caller gives none (sysid.estimation.route): beyond it the long route.
# A long-route model of at most SEARCH_SHORT_ORDER states is a short plant's: the order search runs beside it, up to
# its order, and the fewer states at the floor win.
SEARCH_MAX_ORDER = 30
SEARCH_SHORT_ORDER = 12
# Above this many states a long-route model's 95 % band comes from its FIR (sysid.estimation.long_route.fir_band), not
# from the output-error covariance (sysid.estimation.uncertainty), whose cost grows with the square of the parameters:
# 5.5-7.7 s of CPU at 333 states on a 1-2 s block.
UNCERTAINTY_MAX_ORDER = 60
__all__ += ["SEARCH_MAX_ORDER", "SEARCH_SHORT_ORDER", "UNCERTAINTY_MAX_ORDER"]



# ---------------------------------------------------------------------------------------------------------------------
# The delay (sysid.estimation.delay: the one place it is decided).
# ---------------------------------------------------------------------------------------------------------------------
__all__ += ["ONSET_COHERENCE", "ONSET_PEAK_FRACTION", "ONSET_NOISE_MULTIPLE", "DELAY_WINDOW", "DELAY_WIDEST",
            "DELAY_TOLERANCE", "DELAY_DIP", "DELAY_REFIT_ITERATIONS", "WALK_SPAN", "WALK_CLEAR", "WALK_STEP",
            "DELAY_TRIES", "FREED_ORDERS", "MOVED_HANKEL_GROWTH", "SHORTER_BY", "MAX_EXTRA_DELAY"]

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
# A trial behind a longer delay whose Hankel norm (largest Hankel singular value) exceeds the pick's by more than
# MOVED_HANKEL_GROWTH validates alike only by residues that cancel in band: it imitates a lead (poles toward z = -1).
MOVED_HANKEL_GROWTH = 10.0
# ``shorter_delays``, after a data correction's refit: samples the onset may read long (``refine_delay``'s window
# below the onset), the delays the core is identified anew behind.
SHORTER_BY = 4
# The delay detector's fixed-pole scan: total delays up to the model's and this many more.
MAX_EXTRA_DELAY = 120



# ---------------------------------------------------------------------------------------------------------------------
# Validation on the sweeps (sysid.validation).
# ---------------------------------------------------------------------------------------------------------------------

# The validation band (Hz): the swept sines' band, where a model's validation rms and the noise floor are
# taken (design.md, "Compare"; ``sysid.validation.sweeps``).
VALIDATION_BAND = (20.0, 4000.0)
# Each sweep's first seconds are left out of the validation rms and the noise floor.
SKIP_S = 0.05
# Two sweeps repeat one excitation (sysid.validation.sweeps.check_repeats) when their inputs, aligned,
# correlate at least this much (they share more than the input channel's noise holds apart) and when
# a level difference between them does not make up most of their ear difference: the band rms of
# the difference falls by no more than this factor once the second ear is scaled to the first's level
# (sqrt 2: the level difference's share at most equal to the noise's).
REPEAT_CORRELATION = 0.5
REPEAT_FLOOR_INFLATION = 2.0**0.5

__all__ += ["VALIDATION_BAND", "SKIP_S", "REPEAT_CORRELATION", "REPEAT_FLOOR_INFLATION"]



# ---------------------------------------------------------------------------------------------------------------------
# Recordings and their data quality (sysid.io).
# ---------------------------------------------------------------------------------------------------------------------

# The ear channel heard (sysid.io.ear_channel). An ear channel below half a 16-bit LSB (RMS) is
# digital silence: nothing is connected.
SILENT_RMS = 2.0**-16
# Share of the ear channel's power in EAR_COHERENCE_BAND_HZ that is coherent with the input (the
# coherence weighted by the ear's power spectrum), below which the ear microphone does not hear the
# path at all: judged where the path carries signal, so a path that rolls off below the sensor
# noise above 1-2 kHz is heard (a median over the band's bins read 0.07 for one). It is estimated
# on stretches short enough that an ear clock off by up to a few hundred ppm (effects.md, clock drift) slips by no more than
# a few samples inside one: over a whole recording such a slip turns the cross-spectrum's phase
# and the averaged coherence of a healthy channel collapses above a few hundred Hz (60 ppm over
# 20 s: median 0.01). A sweep, whose every frequency is excited only briefly, is judged over the
# whole recording instead (a stretch of it excites a few bins only): the larger of the two counts.
UNCORRELATED_COHERENCE = 0.1
EAR_COHERENCE_BAND_HZ = (20.0, 4000.0)
# Welch segment of that coherence (samples), and up to EAR_COHERENCE_STRETCHES stretches of
# EAR_COHERENCE_STRETCH samples spread over the recording.
EAR_COHERENCE_SEGMENT = 512
EAR_COHERENCE_STRETCH = 32 * EAR_COHERENCE_SEGMENT
EAR_COHERENCE_STRETCHES = 8
# Over the whole recording the segment is the longest that still gives this many averages (a short
# one biases the coherence of a ringing path low): an unrelated ear shares about 1/64 of its power
# coherently, and a single line's coherence exceeds 0.1 with probability 0.9^63 = 1e-3.
EAR_COHERENCE_AVERAGES = 64

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
            "EAR_COHERENCE_STRETCH", "EAR_COHERENCE_STRETCHES", "EAR_COHERENCE_AVERAGES", "CHANNEL_ORDER_SEGMENT", "CHANNEL_ORDER_BAND_HZ",
            "CHANNEL_ORDER_COHERENT", "CHANNEL_ORDER_MIN_BINS", "CHANNEL_ORDER_LEAD_SAMPLES", "CHANNEL_ORDER_EXCERPT_S"]



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

# Reverberant tail (sysid.findings.tail). The noise recording's least-squares FIR is TAIL_FIRST_S long,
# doubled at most TAIL_DOUBLINGS times while the response rings in its last quarter (at 44.1 kHz 1102 and
# 2204 taps, 46 ms at most; about 1 and 3 s on a 23 s recording: the cost grows as the taps' cube); its
# envelope is averaged over TAIL_ENVELOPE_S and is above the noise while at least TAIL_ABOVE_NOISE_DB above
# the noise's envelope (a 1 ms average of band-limited noise holds about 10 degrees of freedom: 6 dB is out of
# its reach); the tail starts once the direct sound has fallen TAIL_DIRECT_DB below the peak. The ladder's
# target is AT_FLOOR, or TAIL_LADDER_SLACK times the FIR's own ratio when the estimate cannot get there. The tail is the finding when the states it needs
# are TAIL_STATES_RATIO times the model's (counted as the truncation's order that validates as well as the
# model) and TAIL_MIN_EXTRA_STATES more: dense modes, not a few missing modes (under-modelled) nor a missing
# factor of one or two states.
TAIL_FIRST_S = 0.025
TAIL_DOUBLINGS = 1
TAIL_ENVELOPE_S = 0.001
TAIL_ABOVE_NOISE_DB = 6.0
TAIL_DIRECT_DB = 20.0
TAIL_LADDER_SLACK = 1.05
TAIL_STATES_RATIO = 1.5
TAIL_MIN_EXTRA_STATES = 8

__all__ += ["TAIL_FIRST_S", "TAIL_DOUBLINGS", "TAIL_ENVELOPE_S", "TAIL_ABOVE_NOISE_DB", "TAIL_DIRECT_DB",
            "TAIL_LADDER_SLACK", "TAIL_STATES_RATIO", "TAIL_MIN_EXTRA_STATES"]

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
__all__ += ["WARM_ENOUGH", "EIV_MIN_ATTENUATION", "CLIPPING_PASSES", "CLOCK_AR_ORDER", "CLOCK_AR_FLOOR", "CLOCK_PASSES",
            "TAIL_OE_MAX_ORDER"]

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
# ``add_tail``: the long estimate's truncation is refined by output error up to this many states (its
# Jacobian has two columns per state over every bin of the block: beyond it a step takes minutes).
TAIL_OE_MAX_ORDER = 60
