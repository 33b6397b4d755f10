"""Random, physically plausible helmet sound paths as true plants of synthetic sessions.

A helmet path is drawn as a continuous-time acoustic modal sum (Kinsler & Frey,
"Fundamentals of Acoustics", 4th ed., sec. 9.7: the pressure response of an enclosure
to a volume-velocity source is a sum of second-order modes with real modal constants)

.. math::

    H(s) = e^{-s \\tau} \\, L(s) \\, P(s) \\sum_{i=1}^{m} a_i
           \\frac{(\\omega_i / Q_i) s}{s^2 + (\\omega_i / Q_i) s + \\omega_i^2}

with m = 1..8 modes at f_i = omega_i / 2 pi in 30 Hz-5 kHz, Q_i in 0.7-50 and real
a_i of either sign (a_i is the mode's own peak gain; opposite signs of neighbouring
modes put zeros between them, some in the right half-plane), an optional
driver/microphone roll-off L(s) (one or two real poles, 2-12 kHz), an optional coupling
high-pass P(s) (one real pole and a zero at s = 0, 10-120 Hz) and a pure delay
tau = 0..64 samples (converter latency and sound path). The peak gain over 20 Hz-4 kHz
is drawn in 0.2-2.

Sampling: the continuous state-space realisation is diagonalised, every first-order mode
r / (s - p) is sampled by zero-order hold on its own (exact, and ZOH commutes with a
change of state basis), and the result is put in real block-diagonal form. Nothing
passes through a transfer-function polynomial, so the discrete plant is as accurate as
float64 allows at any order. The session levels (``simulate_session``) keep the ear
channel below clipping.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.linalg

from .core.errors import HelmetAncError
from .core.lti import block_output_row, real_block_diagonal
from .core.model import PATHS, Model
from .simulate import Session, SessionSpec, simulate_session

__all__ = ["RandomPlant", "random_plant", "random_session", "PLANT_RANGES"]

# Ranges of the drawn parameters (log-uniform unless noted).
PLANT_RANGES = {
    "modes": (1, 8),                 # number of modes (uniform integer)
    "f0_hz": (30.0, 5000.0),
    "q": (0.7, 50.0),
    "residue": (0.1, 1.0),           # |a_i|, relative to the largest mode before gain scaling
    "rolloff_hz": (2000.0, 12000.0),
    "highpass_hz": (10.0, 120.0),
    "delay": (0, 64),                # samples (uniform integer)
    "peak_gain": (0.2, 2.0),         # max |H| over 20 Hz-4 kHz
    "sensor_noise": (1e-4, 1e-3),    # ear-microphone noise RMS (FS)
}
SAMPLE_RATES = (44100.0, 48000.0)
# Neighbouring modes at least this frequency ratio apart (two modes closer than a few per
# cent act as one mode for any recording of seconds; the generator draws distinct modes).
_MIN_MODE_RATIO = 1.04
_BAND_HZ = (20.0, 4000.0)


@dataclass(frozen=True)
class RandomPlant:
    """A drawn helmet path: the discrete model and the parameters it came from.

    ``modes`` holds (f0 in Hz, Q, a) per mode, a being the signed peak gain of the mode
    after gain scaling; ``rolloff_hz`` and ``highpass_hz`` the corner frequencies of the
    roll-off poles and of the coupling high-pass (empty / None when absent); ``delay``
    the pure delay in samples (also ``model.delay``); ``sensor_noise`` the ear-microphone
    noise RMS in FS units a session of this helmet gets.
    """

    seed: int
    path: str
    fs: float
    model: Model
    modes: tuple[tuple[float, float, float], ...]
    rolloff_hz: tuple[float, ...]
    highpass_hz: float | None
    delay: int
    peak_gain: float
    sensor_noise: float

    @property
    def order(self) -> int:
        """State dimension of the LTI core (the delay not counted)."""
        return self.model.order

    @property
    def description(self) -> str:
        """One line such as '3 modes (120 Hz Q 8.0 +0.41, ...), roll-off 6.1 kHz, high-pass 40 Hz, delay 23 samples, 44.1 kHz'."""
        modes = ", ".join(f"{f:.0f} Hz Q {q:.1f} {a:+.2g}" for f, q, a in self.modes)
        parts = [f"{len(self.modes)} mode{'s' if len(self.modes) > 1 else ''} ({modes})"]
        if self.rolloff_hz:
            parts.append("roll-off " + " and ".join(f"{f / 1000:.1f} kHz" for f in self.rolloff_hz))
        if self.highpass_hz is not None:
            parts.append(f"high-pass {self.highpass_hz:.0f} Hz")
        parts.append(f"delay {self.delay} samples")
        parts.append(f"{self.fs / 1000:g} kHz")
        return ", ".join(parts)

    def to_dict(self) -> dict:
        """The generator's parameters, JSON-ready (the ``generator`` entry of truth.json)."""
        return {
            "kind": "random",
            "seed": self.seed,
            "path": self.path,
            "fs": self.fs,
            "modes": [{"f0_hz": f, "q": q, "residue": a} for f, q, a in self.modes],
            "rolloff_hz": list(self.rolloff_hz),
            "highpass_hz": self.highpass_hz,
            "delay": self.delay,
            "peak_gain": self.peak_gain,
            "sensor_noise": self.sensor_noise,
            "order": self.order,
            "description": self.description,
        }


def _check_seed(seed) -> int:
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise HelmetAncError(f"seed must be a non-negative whole number; found {seed!r}")
    return int(seed)


def _log_uniform(rng: np.random.Generator, bounds: tuple[float, float], size=None):
    low, high = bounds
    return np.exp(rng.uniform(np.log(low), np.log(high), size))


def _draw_frequencies(rng: np.random.Generator, count: int) -> np.ndarray:
    """count mode frequencies, log-uniform, redrawn until neighbours are _MIN_MODE_RATIO apart."""
    while True:
        f = np.sort(_log_uniform(rng, PLANT_RANGES["f0_hz"], count))
        if count == 1 or np.min(f[1:] / f[:-1]) >= _MIN_MODE_RATIO:
            return f


def _continuous_statespace(modes, rolloff_hz, highpass_hz):
    """Continuous (A, B, C) of high-pass -> modal sum -> roll-off in series (D = 0).

    Each mode (w/Q) s / (s^2 + (w/Q) s + w^2) is realised with states (x, x'):
    x'' = -w^2 x - (w/Q) x' + u, y = a (w/Q) x'.
    """
    blocks_A, blocks_B, blocks_C = [], [], []
    for f0, q, a in modes:
        w = 2 * np.pi * f0
        blocks_A.append(np.array([[0.0, 1.0], [-w * w, -w / q]]))
        blocks_B.append(np.array([[0.0], [1.0]]))
        blocks_C.append(np.array([[0.0, a * w / q]]))
    A = scipy.linalg.block_diag(*blocks_A)
    B = np.vstack(blocks_B)
    C = np.hstack(blocks_C)
    D = np.zeros((1, 1))
    if highpass_hz is not None:
        # P(s) = s / (s + wc) = 1 - wc / (s + wc) in front of the modes.
        wc = 2 * np.pi * highpass_hz
        A, B, C, D = _series((np.array([[-wc]]), np.array([[1.0]]), np.array([[-wc]]), np.array([[1.0]])), (A, B, C, D))
    for corner in rolloff_hz:
        # L(s) = wc / (s + wc) after the modes.
        wc = 2 * np.pi * corner
        A, B, C, D = _series((A, B, C, D), (np.array([[-wc]]), np.array([[wc]]), np.array([[1.0]]), np.zeros((1, 1))))
    return A, B, C, D


def _series(first, second):
    """State-space of first followed by second (continuous or discrete alike)."""
    A1, B1, C1, D1 = first
    A2, B2, C2, D2 = second
    n1, n2 = A1.shape[0], A2.shape[0]
    A = np.block([[A1, np.zeros((n1, n2))], [B2 @ C1, A2]])
    B = np.vstack((B1, B2 @ D1))
    C = np.hstack((D2 @ C1, C2))
    return A, B, C, D2 @ D1


def _zoh_modal(A, B, C, D, fs: float):
    """Discrete (A, B, C, D) in real block-diagonal form: each mode r / (s - p) sampled by ZOH.

    A mode x' = p x + b u, y = c x held over T = 1/fs becomes
    x[k+1] = e^{pT} x[k] + b (e^{pT} - 1) / p u[k]; the conjugate pair of a complex mode is
    one real 2x2 block [[Re z, Im z], [-Im z, Re z]] with C = [1, 0] and B = [2 Re rho, -2 Im rho],
    rho = c b (e^{pT} - 1) / p (so that C (qI - A)^-1 B = rho / (q - z) + conj).
    """
    poles, V = np.linalg.eig(A)
    residues = (C[0] @ V) * np.linalg.solve(V, B[:, 0])
    T = 1.0 / fs
    z = np.exp(poles * T)
    rho = residues * (z - 1.0) / poles
    keep = [i for i, p in enumerate(poles) if p.imag >= 0]
    zd, rhod = z[keep], rho[keep]
    Ad = real_block_diagonal(np.concatenate([zd, np.conj(zd[zd.imag > 0])]))
    Cd = block_output_row(Ad)
    Bd = np.zeros((Ad.shape[0], 1))
    # real_block_diagonal keeps the order of first appearance: the kept poles in order.
    i = 0
    for zk, rk in zip(zd, rhod):
        if zk.imag > 0:
            Bd[i, 0], Bd[i + 1, 0] = 2 * rk.real, -2 * rk.imag
            i += 2
        else:
            Bd[i, 0] = rk.real
            i += 1
    return Ad, Bd, Cd, D.copy()


def _peak_gain(A, B, C, D, fs: float) -> float:
    f = np.geomspace(*_BAND_HZ, 4000)
    from .core.lti import frequency_response

    return float(np.max(np.abs(frequency_response(A, B, C, D, np.exp(2j * np.pi * f / fs)))))


def random_plant(seed: int, path: str = "fb") -> RandomPlant:
    """Draw the helmet path number ``seed`` (see the module docstring for the plant family).

    All parameters come from ``numpy.random.default_rng([seed, k])`` with k = 0 for the
    feedback path and 1 for the feed-forward path, so a seed names one helmet's two paths
    and the same seed always gives the same plant.
    """
    seed = _check_seed(seed)
    if path not in PATHS:
        raise HelmetAncError(f"path must be one of {', '.join(PATHS)}; found {path!r}")
    rng = np.random.default_rng([seed, PATHS.index(path)])
    fs = float(SAMPLE_RATES[rng.integers(len(SAMPLE_RATES))])
    count = int(rng.integers(PLANT_RANGES["modes"][0], PLANT_RANGES["modes"][1] + 1))
    f0 = _draw_frequencies(rng, count)
    q = _log_uniform(rng, PLANT_RANGES["q"], count)
    residue = _log_uniform(rng, PLANT_RANGES["residue"], count) * rng.choice([-1.0, 1.0], count)
    rolloff = tuple(float(f) for f in np.sort(_log_uniform(rng, PLANT_RANGES["rolloff_hz"], int(rng.integers(0, 3)))))
    highpass = float(_log_uniform(rng, PLANT_RANGES["highpass_hz"])) if rng.uniform() < 0.5 else None
    delay = int(rng.integers(PLANT_RANGES["delay"][0], PLANT_RANGES["delay"][1] + 1))
    peak = float(_log_uniform(rng, PLANT_RANGES["peak_gain"]))
    sensor_noise = float(_log_uniform(rng, PLANT_RANGES["sensor_noise"]))

    modes = [(float(f), float(qq), float(a)) for f, qq, a in zip(f0, q, residue)]
    A, B, C, D = _zoh_modal(*_continuous_statespace(modes, rolloff, highpass), fs)
    # Scale to the drawn peak gain; the modal constants scale with it.
    scale = peak / _peak_gain(A, B, C, D, fs)
    B = B * scale
    D = D * scale
    modes = tuple((f, qq, a * scale) for f, qq, a in modes)
    model = Model(path=path, fs=fs, A=A, B=B, C=C, D=D, delay=delay,
                  identification={"source": "random plant", "seed": seed})
    return RandomPlant(seed, path, fs, model, modes, rolloff, highpass, delay, peak, sensor_noise)


def random_session(seed: int, path: str = "fb", effects=(), **spec_overrides) -> Session:
    """A synthetic session (``simulate_session``) of the random plant ``random_plant(seed, path)``.

    The session's sample rate and ear-microphone noise are the plant's; ``spec_overrides``
    replace any other ``SessionSpec`` field (e.g. ``noise_duration=5.0``); ``effects`` are
    hidden effects as in ``simulate_session``. ``truth["generator"]`` holds the drawn parameters.
    """
    plant = random_plant(seed, path)
    fields = {"path": path, "seed": plant.seed, "fs": plant.fs, "output_noise": plant.sensor_noise}
    unknown = sorted(set(spec_overrides) - set(SessionSpec.__dataclass_fields__))
    if unknown:
        raise HelmetAncError(f"unknown session setting {unknown[0]!r}; known: {', '.join(SessionSpec.__dataclass_fields__)}")
    if spec_overrides.get("path", path) != path or spec_overrides.get("fs", plant.fs) != plant.fs:
        raise HelmetAncError("path and fs of a random session are the plant's; give path to random_session and leave fs out")
    fields.update(spec_overrides)
    session = simulate_session(SessionSpec(**fields), plant=plant.model, effects=effects)
    session.truth["generator"] = plant.to_dict()
    return session
