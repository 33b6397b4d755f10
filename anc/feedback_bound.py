"""The feedback bound: the most any causal stable IMC filter Q attenuates under stated robustness.

With the runtime's observer d_hat = e - S_model y and y[k] = Q d_hat[k-L], the ear noise is
(1 + G Q) d with G = z^-L S_model: the sensitivity is affine in Q (the Youla / internal model
control parametrisation: Morari & Zafiriou, "Robust Process Control", 1989, ch. 3), so every
design question about Q with bounds on |1 + G Q| and |G Q| is a convex program. Here

.. math::
    \\min_Q \\sum_b \\frac{\\sum_{f \\in b} \\Phi_d(f) |1 + G Q|^2}{\\sum_{f \\in b} \\Phi_d(f)}
    \\quad \\text{subject to} \\quad
    |1 + G Q| \\le 10^{A(f) / 20}, \\quad r_{95}(f) |G Q| \\le \\beta \\quad \\text{at every } f,

the sum running over the third-octave bands ``JUDGED_HZ`` (50 Hz-1 kHz) on the points of
``anc.prediction.band_grid``, each band's sums weighted to integrals over linear frequency
(``band_weights``, as ``anc.design.predict``), Phi_d the ear noise with ANC off:
each band counts by its own power ratio, so no band dominates and none is sacrificed (the
sum of ratios; a mean of decibels would reward deepening bands already deep). A(f) is the
amplification limit of the third-octave band holding f (``amplification_limit``: default
6 dB, settable per band 20 Hz-10 kHz, the edge bands' limits beyond), r95 the model's relative
95 % error (``anc.uncertainty``) and beta = ``ROBUSTNESS_BOUND`` (0.5): the small-gain condition
|Delta Q| < 1 for every path within the model's band, with margin 2.

Q ranges over ``FeedbackFamily``: Q = H S_o^-1 X with S_o the model's outer factor
(``anc.outer_factor``: G Q is then X through the loop's dead time and an all-pass), H a double
zero at DC (the path below the identified band is unknown) and X a combination of a few hundred
orthonormal rational functions with poles log-spaced over 15 Hz-6 kHz (``anc.rational_basis``),
rich enough that doubling it changes the bound by less than 0.1 dB. The constraints hold on a
cutting-plane grid: a log-spaced start, then the points of ``dense_grid`` where the solution
broke a bound, until it breaks none by more than ``GRID_TOLERANCE``. Solved by the barrier
method (``anc.disc_program``: exact discs, global optimum).

What limits each band is measured, not guessed: the bound is computed again with one limit
relaxed at a time (``RELAXATIONS``: the amplification limit 6 dB higher, no model uncertainty,
the zeros of S outside the unit circle reflected inside, the dead time down to one sample), and
a band names every limit whose relaxation gains it more than ``NAMED_GAIN_DB``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from sysid.core.model import Model
from sysid.core.structures import series
from sysid.validation.compare import third_octave_bands

from .disc_program import DiscProgram, solve_disc_program
from .disturbance import Disturbance
from .outer_factor import CIRCLE_MARGIN, OuterFactor, outer_factor
from .prediction import BANDS, band_grid, band_weights
from .rational_basis import RationalBasis, basis_poles
from .uncertainty import Uncertainty

__all__ = ["FeedbackBound", "FeedbackFamily", "FeedbackProblem", "feedback_bound", "amplification_limit",
           "LIMIT_BANDS", "JUDGED_HZ", "ROBUSTNESS_BOUND", "GRID_TOLERANCE", "NAMED_GAIN_DB", "RELAXATIONS",
           "design_grid", "dense_grid"]

ROBUSTNESS_BOUND = 0.5
JUDGED_HZ = (50.0, 1000.0)
# The bands a per-band amplification limit is stated for; below and above them the edge bands' limits hold.
LIMIT_BANDS = third_octave_bands(20.0, 10000.0)
# A bound broken by less than this fraction between the cutting-plane grid's points is left as it is.
GRID_TOLERANCE = 1e-4
NAMED_GAIN_DB = 0.5
RELAXATIONS = ("waterbed", "uncertainty", "nonminimum_phase", "dead_time")
# The free part X: functions, poles log-spaced over these corners (Hz) in cycles of this many. The lowest
# corner and the DC block sit at 15 Hz: the controlled band starts at 20 Hz, and poles within 4e-4 of
# z = 1 (corners at 3-5 Hz) left the board's float32 Q at a predicted round-off SNR of 7 dB (seed pair,
# Q of 57 states); at 15 Hz the seed pair's judged "both" moves 10.05 -> 9.75 dB (mean 50 Hz-1 kHz).
BASIS_SIZE = 160
BASIS_HZ = (15.0, 6000.0)
BASIS_CYCLE = 16
DC_BLOCK_HZ = 15.0
_START_POINTS = 600
_CUTTING_ROUNDS = 8


def design_grid(fs: float, points: int = 4096) -> np.ndarray:
    """Grid (Hz): DC, 32 log-spaced points from 0.5 Hz, then uniform from fs / (2 points) to fs / 2."""
    uniform = np.linspace(fs / (2 * points), fs / 2.0, points)
    return np.concatenate(([0.0], np.geomspace(0.5, uniform[0], 33)[:-1], uniform))


def dense_grid(model: Model, bins: int = 8192) -> np.ndarray:
    """Frequencies (Hz) on which a feedback filter's bounds are verified: every bin of a 2 * ``bins``-point
    FFT (2.9 Hz apart at 48 kHz), ``bins`` log-spaced points from 0.1 Hz (0.15 % apart: the bound where
    nothing is known changes fast below a few tens of hertz) and, around each pole of the model, 41
    points over +-4 half-power bandwidths (|ln r| fs / pi each; at least 1e-6 Hz), where a lightly damped
    mode's peak lies between the bins, and ``design_grid``."""
    fs = model.fs
    points = [np.linspace(0.0, fs / 2.0, bins + 1), np.geomspace(0.1, fs / 2.0, bins)]
    if model.order:
        poles = np.linalg.eigvals(model.A)
        poles = poles[np.abs(poles) > 0]
        centre = np.abs(np.angle(poles)) * fs / (2.0 * np.pi)
        width = np.maximum(np.abs(np.log(np.abs(poles))) * fs / np.pi, 1e-6)
        points.append((centre[:, None] + 4.0 * width[:, None] * np.linspace(-1.0, 1.0, 41)[None, :]).reshape(-1))
    f = np.concatenate(points + [design_grid(fs)])
    return np.unique(f[(f >= 0.0) & (f <= fs / 2.0)])


def amplification_limit(frequencies_hz, max_amplification_db) -> np.ndarray:
    """The limit (dB) on |1 + G Q| at frequencies in Hz: a number for every band, or one per band of
    ``LIMIT_BANDS`` (third-octave 20 Hz-10 kHz), the first and last holding beyond them."""
    limits = np.broadcast_to(np.asarray(max_amplification_db, dtype=float), (len(LIMIT_BANDS),))
    if not np.all(np.isfinite(limits)) or np.any(limits <= 0.0):
        raise ValueError(f"amplification limits must be positive numbers of dB (0 dB admits no feedback at all); "
                         f"found {np.asarray(max_amplification_db)}")
    edges = np.array([hi for _, _, hi in LIMIT_BANDS[:-1]])
    return limits[np.searchsorted(edges, np.asarray(frequencies_hz, dtype=float), side="right")]


@dataclass(frozen=True)
class FeedbackFamily:
    """Q = H S_o^-1 X, X = sum c_k phi_k (module docstring): ``outer`` S_o, ``highpass_pole`` b of
    H = ((1 + b) / 2 (1 - z^-1) / (1 - b z^-1))^2 (unit gain at fs / 2) and the ``basis`` of X."""

    outer: OuterFactor
    highpass_pole: float
    basis: RationalBasis

    @classmethod
    def of(cls, model: Model, size: int = BASIS_SIZE, corners_hz=BASIS_HZ, cycle: int = BASIS_CYCLE,
           dc_block_hz: float = DC_BLOCK_HZ) -> "FeedbackFamily":
        poles = basis_poles(model.fs, size, corners_hz[0], min(corners_hz[1], 0.4 * model.fs), cycle)
        return cls(outer_factor(model), float(np.exp(-2.0 * np.pi * dc_block_hz / model.fs)), RationalBasis.of(poles))

    def _highpass(self, frequencies_hz) -> np.ndarray:
        zi = np.exp(-2j * np.pi * np.asarray(frequencies_hz, dtype=float) / self.outer.fs)
        b = self.highpass_pole
        return ((1.0 + b) / 2.0 * (1.0 - zi) / (1.0 - b * zi)) ** 2

    def responses(self, frequencies_hz) -> np.ndarray:
        """(len(f), size) complex: Q's response per coefficient at frequencies in Hz."""
        fixed = self._highpass(frequencies_hz) * self.outer.inverse_response(frequencies_hz)
        return fixed[:, None] * self.basis.responses(frequencies_hz, self.outer.fs)

    def statespace(self, coefficients) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(A, B, C, D) of Q: X, then S_o^-1, then H, in series."""
        b = self.highpass_pole
        g = ((1.0 + b) / 2.0) ** 2
        highpass = (np.array([[2.0 * b, -b * b], [1.0, 0.0]]), np.array([[1.0], [0.0]]),
                    g * np.array([[2.0 * b - 2.0, 1.0 - b * b]]), np.array([[g]]))
        return series(series(self.basis.statespace(coefficients), self.outer.inverse_statespace()), highpass)


@dataclass
class FeedbackProblem:
    """The program's data for one model, noise, latency and robustness: the criterion on the judged bands'
    points (``objective_hz``, one row per band) and the bounds on ``dense_hz`` (``dense_grid`` with the
    criterion's points); Q's responses per coefficient on both, and G = z^-L S_model."""

    family: FeedbackFamily
    latency: int
    bands_hz: np.ndarray
    objective_hz: np.ndarray          # (bands, points)
    weights: np.ndarray               # (bands, points): Phi_d times the band integral's weights / band power
    objective_q: np.ndarray           # (bands * points, size)
    objective_g: np.ndarray
    dense_hz: np.ndarray
    dense_q: np.ndarray               # (dense, size)
    dense_g: np.ndarray
    limit: np.ndarray                 # |1 + G Q| <= limit on dense_hz
    relative_95: np.ndarray           # r95 on dense_hz
    robustness_bound: float

    def band_ratios(self, loop_objective: np.ndarray) -> np.ndarray:
        """Per judged band: ear power with the loop G Q (on the criterion's points) over without."""
        return np.sum(self.weights * np.abs(1.0 + loop_objective.reshape(self.weights.shape)) ** 2, axis=1)

    def solve(self, g_objective=None, g_dense=None, limit=None, robust: bool = True, refine: bool = True,
              start=None) -> np.ndarray:
        """Coefficients of the best Q (module docstring), with G, the amplification limit or the robustness
        bound replaced for a relaxation; ``refine``: cutting planes on the dense grid (else the start grid)."""
        G_obj = self.objective_g if g_objective is None else g_objective
        G = self.dense_g if g_dense is None else g_dense
        limit = self.limit if limit is None else limit
        M = G_obj[:, None] * self.objective_q
        w = self.weights.reshape(-1)
        P = np.real((M.conj().T * w) @ M)
        P += 1e-10 * np.trace(P) / P.shape[0] * np.eye(P.shape[0])
        q = np.real((M.conj().T * w) @ np.ones(w.size))
        radius = self.robustness_bound / np.maximum(self.relative_95, 1e-300) if robust else np.full(G.size, np.inf)
        # The robustness disc |G Q| <= radius cannot bind where it holds the amplification disc's every point.
        needs_robust = radius < limit + 1.0
        active = _start_points(self.dense_hz, self.objective_hz.reshape(-1))
        c = np.zeros(P.shape[0]) if start is None else np.asarray(start, dtype=float)
        for _ in range(_CUTTING_ROUNDS if refine else 1):
            rows = G[active, None] * self.dense_q[active]
            robust_rows = active[needs_robust[active]]
            program = DiscProgram(P, q, np.vstack([rows, G[robust_rows, None] * self.dense_q[robust_rows]]),
                                  np.concatenate([np.ones(active.size), np.zeros(robust_rows.size)]).astype(complex),
                                  np.concatenate([limit[active], radius[robust_rows]]))
            c = solve_disc_program(program, _feasible(program, c))
            if not refine:
                break
            loop = G * (self.dense_q @ c)
            excess = np.maximum(np.abs(1.0 + loop) / limit, np.where(needs_robust, np.abs(loop) / radius, 0.0)) - 1.0
            broken = np.flatnonzero(excess > GRID_TOLERANCE)
            if not broken.size:
                break
            active = np.union1d(active, _local_peaks(excess, broken))
        return c


def _start_points(dense_hz: np.ndarray, objective_hz: np.ndarray) -> np.ndarray:
    """Indices into dense_hz: DC, ``_START_POINTS`` log-spaced from 0.5 Hz, and the criterion's points."""
    targets = np.concatenate(([0.0], np.geomspace(0.5, dense_hz[-1], _START_POINTS), objective_hz))
    index = np.clip(np.searchsorted(dense_hz, targets), 0, dense_hz.size - 1)
    return np.unique(index)


def _local_peaks(excess: np.ndarray, broken: np.ndarray) -> np.ndarray:
    """The broken points that are local maxima of the excess, with their neighbours."""
    left = np.concatenate(([-np.inf], excess[:-1]))
    right = np.concatenate((excess[1:], [-np.inf]))
    peaks = broken[(excess[broken] >= left[broken]) & (excess[broken] >= right[broken])]
    return np.unique(np.clip(np.concatenate((peaks - 1, peaks, peaks + 1)), 0, excess.size - 1))


def _feasible(program: DiscProgram, c: np.ndarray) -> np.ndarray:
    """c scaled towards zero (strictly inside every disc) until strictly inside every disc."""
    for factor in (1.0, 0.95, 0.8, 0.5, 0.2):
        if np.all(program.slack(factor * c) > 0.0):
            return factor * c
    return np.zeros_like(c)


def feedback_problem(s_model: Model, disturbance: Disturbance, latency: int, uncertainty: Uncertainty,
                     max_amplification_db=6.0, robustness_bound: float = ROBUSTNESS_BOUND,
                     family: FeedbackFamily | None = None) -> FeedbackProblem:
    """The program (module docstring) for the model, the ear noise with ANC off, the latency in samples and
    the stated robustness."""
    fs = s_model.fs
    family = family or FeedbackFamily.of(s_model)
    rows = [i for i, (centre, _, _) in enumerate(BANDS) if JUDGED_HZ[0] / 1.05 <= centre <= JUDGED_HZ[1] * 1.05]
    objective_hz = band_grid()[rows]
    f = objective_hz.reshape(-1)
    psd = np.maximum(disturbance.at(f).ear_psd, 0.0)
    psd = np.maximum(psd, 1e-9 * max(float(psd.max()), 1e-300)).reshape(objective_hz.shape)
    power = psd * band_weights()[rows]
    dense = np.union1d(dense_grid(s_model), f)
    delay = lambda hz: np.exp(-2j * np.pi * hz * latency / fs)  # noqa: E731
    return FeedbackProblem(family, latency, np.array([BANDS[i][0] for i in rows]), objective_hz,
                           power / power.sum(axis=1, keepdims=True), family.responses(f),
                           s_model.frequency_response(f) * delay(f), dense, family.responses(dense),
                           s_model.frequency_response(dense) * delay(dense),
                           10.0 ** (amplification_limit(dense, max_amplification_db) / 20.0), uncertainty.at(dense),
                           float(robustness_bound))


@dataclass
class FeedbackBound:
    """The bound (module docstring) per judged third-octave band (``bands_hz``, 50 Hz-1 kHz) and its mean,
    dB; the stated robustness it holds under; what limits each band (``limits``, one line per band, and the
    gain in dB per band of relaxing each of ``RELAXATIONS``); the optimal Q (``family``, ``coefficients``)."""

    bands_hz: np.ndarray
    attenuation_db: np.ndarray
    latency: int
    max_amplification_db: np.ndarray     # per band of LIMIT_BANDS
    robustness_bound: float
    peak_amplification_db: float
    peak_amplification_hz: float
    family: FeedbackFamily
    coefficients: np.ndarray
    relaxation_gain_db: dict = field(default_factory=dict)
    limits: list[str] = field(default_factory=list)

    @property
    def mean_db(self) -> float:
        return float(np.mean(self.attenuation_db))

    def to_dict(self) -> dict:
        """The bound as the controller JSON and the report take it (plain numbers and text)."""
        return {"bands_hz": [float(v) for v in self.bands_hz], "attenuation_db": [float(v) for v in self.attenuation_db],
                "mean_db": self.mean_db, "latency_samples": self.latency,
                "max_amplification_db": {f"{c:g}": float(v) for (c, _, _), v in zip(LIMIT_BANDS, self.max_amplification_db)},
                "robustness_bound": self.robustness_bound, "peak_amplification_db": self.peak_amplification_db,
                "peak_amplification_hz": self.peak_amplification_hz,
                "relaxation_gain_db": {k: [float(v) for v in g] for k, g in self.relaxation_gain_db.items()},
                "limits": list(self.limits)}


def feedback_bound(s_model: Model, disturbance: Disturbance, latency: int, uncertainty: Uncertainty,
                   max_amplification_db=6.0, robustness_bound: float = ROBUSTNESS_BOUND, explain: bool = True,
                   problem: FeedbackProblem | None = None) -> FeedbackBound:
    """The feedback bound (module docstring) for the FB model, the ear noise with ANC off (``disturbance``:
    its ear spectrum), the latency in samples, the model's uncertainty, the amplification limit in dB (one
    number, or one per band of ``LIMIT_BANDS``) and the robustness bound on r95 |G Q|. ``explain``: also
    measure what limits each band (four more solves on the start grid). ``problem``: the program, when
    the caller has built it already (``feedback_problem`` with the same arguments)."""
    problem = problem or feedback_problem(s_model, disturbance, latency, uncertainty, max_amplification_db,
                                          robustness_bound)
    c = problem.solve()
    attenuation = -10.0 * np.log10(problem.band_ratios(problem.objective_g * (problem.objective_q @ c)))
    loop = problem.dense_g * (problem.dense_q @ c)
    amplification = 20.0 * np.log10(np.abs(1.0 + loop))
    peak = int(np.argmax(amplification))
    limits_db = np.broadcast_to(np.asarray(max_amplification_db, dtype=float), (len(LIMIT_BANDS),)).copy()
    bound = FeedbackBound(problem.bands_hz, attenuation, latency, limits_db, float(robustness_bound),
                          float(amplification[peak]), float(problem.dense_hz[peak]), problem.family, c)
    if explain:
        bound.relaxation_gain_db = _relaxation_gains(problem, attenuation, c)
        bound.limits = limit_texts(bound, problem, uncertainty)
    return bound


def _relaxation_gains(problem: FeedbackProblem, attenuation: np.ndarray, c: np.ndarray) -> dict[str, np.ndarray]:
    """Per relaxation of ``RELAXATIONS`` that applies, the bound's gain per judged band (dB), solved on
    the start grid from the bound's own Q."""
    outer = problem.family.outer
    dead = problem.latency + outer.dead_time
    fs = outer.fs

    def advance(f, samples):
        return np.exp(2j * np.pi * np.asarray(f) * samples / fs)

    def blaschke_removed(f):
        # G = z^-(L + d + r) B S_o: without B (the zeros outside reflected inside).
        return outer.response(f) * advance(f, -dead)

    variants = {"waterbed": dict(limit=problem.limit * 10.0 ** (6.0 / 20.0)), "uncertainty": dict(robust=False)}
    if np.any(np.abs(outer.outside) > 1.0 + CIRCLE_MARGIN):
        variants["nonminimum_phase"] = dict(g_objective=blaschke_removed(problem.objective_hz.reshape(-1)),
                                            g_dense=blaschke_removed(problem.dense_hz))
    if dead > 1:
        variants["dead_time"] = dict(g_objective=problem.objective_g * advance(problem.objective_hz.reshape(-1), dead - 1),
                                     g_dense=problem.dense_g * advance(problem.dense_hz, dead - 1))
    gains = {}
    for name, change in variants.items():
        relaxed = problem.solve(refine=False, start=c, **change)
        g_obj = change.get("g_objective", problem.objective_g)
        gains[name] = -10.0 * np.log10(problem.band_ratios(g_obj * (problem.objective_q @ relaxed))) - attenuation
    return gains


def limit_texts(bound: FeedbackBound, problem: FeedbackProblem, uncertainty: Uncertainty) -> list[str]:
    """One line per judged band: its bound and the limits whose relaxation gains it over ``NAMED_GAIN_DB``."""
    outer = problem.family.outer
    dead = bound.latency + outer.dead_time
    fs = outer.fs
    nmp = [(float(hz), complex(z)) for hz, z in zip(outer.nonminimum_phase_hz(), outer.outside)
           if abs(z) > 1.0 + CIRCLE_MARGIN]
    limit_db = float(np.max(bound.max_amplification_db))
    lines = []
    for i, centre in enumerate(bound.bands_hz):
        named = []
        for name, gains in sorted(bound.relaxation_gain_db.items(), key=lambda item: -item[1][i]):
            gain = float(gains[i])
            if gain < NAMED_GAIN_DB:
                continue
            if name == "waterbed":
                named.append(f"the waterbed (Bode's sensitivity integral: what is removed here comes back where "
                             f"|1 + G Q| reaches its {limit_db:g} dB limit; +{gain:.1f} dB with 6 dB more)")
            elif name == "uncertainty":
                r95 = float(uncertainty.at([centre])[0])
                named.append(f"the model's uncertainty (r95 {100 * r95:.2g} % here; r95 |G Q| <= "
                             f"{bound.robustness_bound:g} wherever it is large; +{gain:.1f} dB without it)")
            elif name == "nonminimum_phase":
                hz, z = min(nmp, key=lambda item: abs(np.log(max(item[0], 1e-3) / centre)))
                named.append(f"a zero of S outside the unit circle at {hz:.0f} Hz (z = {z.real:.4f}"
                             f"{z.imag:+.4f}j; +{gain:.1f} dB were it inside)")
            else:
                named.append(f"the dead time of {dead} samples (latency {bound.latency} + the path's "
                             f"{outer.dead_time}): {360.0 * centre * dead / fs:.0f} degrees here; +{gain:.1f} dB "
                             "with one sample")
        reason = "; ".join(named) if named else f"no single limit (each relaxed alone adds under {NAMED_GAIN_DB} dB)"
        lines.append(f"{centre:g} Hz: {bound.attenuation_db[i]:.1f} dB, limited by {reason}")
    return lines
