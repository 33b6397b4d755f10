"""Control test cases: plant pairs, road noise recorded with ANC off, and the judge that closes the loop.

The judge is independent of the design: it runs a controller sample by sample on the TRUE plants
(``anc.closed_loop.run_closed_loop``) against a fresh realisation of the noise, and measures the
attenuation per third-octave band from the ear signals (``anc.closed_loop.measured_attenuation``).
The noise the designs are given is a recording with ANC off, as a user makes one: the chin
microphone x (pink noise 20 Hz-2 kHz) and the ear d = P_true x + u, u not coherent with the chin,
``INCOHERENT_DB`` below the chin-coherent ear noise in every band (a 40 dB coherence bound).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np

from anc.closed_loop import measured_attenuation, run_closed_loop
from anc.prediction import band_centres
from sysid.core.model import Model
from sysid.core.plants import appendix_a_model
from sysid.identify import identify
from sysid.io.recordings import Recording
from sysid.random_plant import random_plant, random_session
from sysid.simulate import SessionSpec, simulate_session

from conftest import FAST_OPTIONS, SHORT

INCOHERENT_DB = -40.0
# The judge's noise (s): a band cancelled 24 dB deep reads within about +-0.7 dB of itself from one realisation to the
# next over 4 s (random pair 7/1012's 50 Hz band, 11.6 Hz wide: 25.1, 24.0 dB over 4 s, 23.7 over 8 s), a third of
# the 2 dB the predictions are held to; 8 s halves its variance.
JUDGE_SECONDS = 8.0
PINK_BAND_HZ = (20.0, 2000.0)
# The bands every judgement averages over: third-octave centres 50 Hz-1 kHz.
JUDGED_HZ = (50.0, 1000.0)
CENTRES = np.array(band_centres())
JUDGED = (CENTRES >= JUDGED_HZ[0]) & (CENTRES <= JUDGED_HZ[1])
# Random FB seeds of the project's generator; each is paired with the first FF seed from seed + 1000 at its rate.
RANDOM_FB_SEEDS = (3, 5, 11, 12, 1, 2, 4, 6, 7, 8, 9, 10, 13)


@dataclass(frozen=True)
class PlantPair:
    """A helmet's two true paths: ``s`` the FB path (drive -> ear), ``p`` the FF path (chin -> ear)."""

    name: str
    s: Model
    p: Model
    fb_seed: int | None = None
    ff_seed: int | None = None


def seed_pair() -> PlantPair:
    """The seed thesis's appendix-A plants."""
    return PlantPair("seed appendix A", appendix_a_model("fb"), appendix_a_model("ff"))


def random_pair(fb_seed: int) -> PlantPair:
    """Random FB path ``fb_seed`` with the first random FF path from ``fb_seed + 1000`` at the same sample rate."""
    s = random_plant(fb_seed, "fb")
    ff_seed = fb_seed + 1000
    while random_plant(ff_seed, "ff").fs != s.fs:
        ff_seed += 1
    return PlantPair(f"random {fb_seed}/{ff_seed}", s.model, random_plant(ff_seed, "ff").model, fb_seed, ff_seed)


@lru_cache(maxsize=None)
def identified(pair_name: str) -> tuple[Model, Model]:
    """(S, P) identified on short synthetic sessions of the pair ``pair_name`` ("seed" or "random N")."""
    if pair_name == "seed":
        s_session = simulate_session(SessionSpec(path="fb", seed=11, **SHORT))
        p_session = simulate_session(SessionSpec(path="ff", seed=11, **SHORT))
    else:
        pair = random_pair(int(pair_name.split()[1]))
        s_session = random_session(pair.fb_seed, "fb", **SHORT)
        p_session = random_session(pair.ff_seed, "ff", **SHORT)
    return (identify(s_session.noise, s_session.sweeps, "fb", FAST_OPTIONS).model,
            identify(p_session.noise, p_session.sweeps, "ff", FAST_OPTIONS).model)


def pink_noise(n: int, fs: float, rng: np.random.Generator, band=PINK_BAND_HZ) -> np.ndarray:
    """Unit-variance noise with a 1/f power spectrum inside ``band`` (Hz) and none outside (circular shaping)."""
    spectrum = np.fft.rfft(rng.standard_normal(n))
    f = np.fft.rfftfreq(n, 1.0 / fs)
    gain = np.where((f >= band[0]) & (f <= band[1]), 1.0 / np.sqrt(np.maximum(f, band[0])), 0.0)
    x = np.fft.irfft(spectrum * gain, n)
    return x / np.std(x)


def road_noise(p_true: Model, seconds: float, seed: int, level: float = 0.05,
               incoherent_db: float = INCOHERENT_DB) -> tuple[np.ndarray, np.ndarray]:
    """(x, d): the chin microphone (pink, ``level`` FS rms) and the ear with ANC off, d = P_true x + u, with u
    ``incoherent_db`` below P_true x in every band (u = P_true x' for an independent pink x', scaled)."""
    fs = p_true.fs
    n = int(round(seconds * fs))
    rng = np.random.default_rng(seed)
    x = level * pink_noise(n, fs, rng)
    other = level * pink_noise(n, fs, rng)
    u = 10.0 ** (incoherent_db / 20.0) * p_true.simulate(other)
    return x, p_true.simulate(x) + u


def recording_with_anc_off(p_true: Model, seconds: float = 6.0, seed: int = 1) -> Recording:
    """The road noise as a user records it with ANC off: input channel = chin, output = ear."""
    x, d = road_noise(p_true, seconds, seed)
    return Recording(x, d, p_true.fs, f"road-noise-{seed}.wav", (0.0, 0.0), (0.0, 0.0))


@dataclass(frozen=True)
class Judgement:
    """Attenuation per third-octave band (dB, ``anc.prediction.band_centres``) of each configuration the
    controller has ("ff", "fb", "both"), measured on the true plants, and their means over ``JUDGED_HZ``."""

    per_band: dict[str, np.ndarray]

    def mean(self, part: str) -> float:
        return float(np.mean(self.per_band[part][JUDGED]))


def judge(controller, pair: PlantPair, seconds: float = JUDGE_SECONDS, seed: int = 7) -> Judgement:
    """The controller on the TRUE plants of ``pair`` against a fresh realisation of the road noise."""
    x, d = road_noise(pair.p, seconds, seed)
    parts = {}
    for part, use_ff, use_fb in (("ff", True, False), ("fb", False, True), ("both", True, True)):
        if (use_ff and controller.ff is None) or (use_fb and controller.fb is None):
            continue
        run = run_closed_loop(controller, pair.s, d, x, use_ff, use_fb)
        parts[part] = np.array(measured_attenuation(d, run.e, pair.s.fs))
    return Judgement(parts)


def small_controller(latency: int | None = None, limits: dict | None = None):
    """A controller with first-order W and Q on the seed's FB model at ``latency`` (default the board's,
    ``anc.controller.BOARD_LATENCY_SAMPLES``), made without a design (the contract's checks need a
    controller, not a good one)."""
    from anc.controller import BOARD_LATENCY_SAMPLES, Controller, StateSpaceFilter

    latency = BOARD_LATENCY_SAMPLES if latency is None else latency
    s = appendix_a_model("fb")
    n = len(band_centres())
    q = StateSpaceFilter(np.array([[0.5]]), np.array([[1.0]]), np.array([[-0.1]]), np.array([[0.0]]))
    w = StateSpaceFilter(np.array([[0.2]]), np.array([[1.0]]), np.array([[0.05]]), np.array([[0.01]]))
    predicted = {part: [float(i % 3) for i in range(n)] for part in ("ff", "fb", "both")}
    margins = {"gain_margin_db": None, "phase_margin_deg": None, "crossovers": 0, "peak_amplification_db": 1.5,
               "peak_amplification_hz": 800.0, "robustness_factor": 2.0}
    return Controller(s.fs, s, w, q, latency, band_centres(), predicted, margins, [40.0] * n, {"both": 3.0}, ["n"],
                      {"source": "test"}, limits=limits)


def predicted_small_controller(s_model: Model, p_model: Model | None, latency: int | None = None):
    """First-order W and a small Q on ``s_model`` with the predictions ``anc.design.predict`` makes for the default
    spectrum (with ``p_model``): a controller whose predictions are real, made in milliseconds without a design."""
    from anc.controller import BOARD_LATENCY_SAMPLES, Controller, StateSpaceFilter
    from anc.design import predict
    from anc.disturbance import default_disturbance

    latency = BOARD_LATENCY_SAMPLES if latency is None else latency
    q = StateSpaceFilter(np.array([[0.9]]), np.array([[1.0]]), np.array([[-0.02]]), np.array([[-0.05]]))
    w = StateSpaceFilter(np.array([[0.5]]), np.array([[1.0]]), np.array([[0.05]]), np.array([[0.02]]))
    predicted, overall, coherence = predict(s_model, default_disturbance(s_model.fs, p_model), latency, q, w)
    return Controller(s_model.fs, s_model, w, q, latency, band_centres(), predicted, {}, coherence, overall)


def board_controller(s_model: Model, p_model: Model | None, latency: int | None = None):
    """A controller of the size the board runs, made without a design (a design takes minutes): Q a 6th-order
    band-pass 50-500 Hz (its zeros at DC, as a designed Q's; 8 dB quieter at 160 Hz with the seed's S), W an
    8th-order low-pass at 1 kHz, both balanced realisations, with the predictions ``anc.design.predict``
    makes for the default spectrum. For the code generator's and the firmware's checks, which need
    filters of a designed controller's kind."""
    import scipy.signal

    from anc.controller import BOARD_LATENCY_SAMPLES, Controller, StateSpaceFilter
    from anc.design import predict
    from anc.disturbance import default_disturbance
    from sysid.core.lti import minimal_balanced_realisation
    from sysid.core.structures import series, tf_to_statespace

    latency = BOARD_LATENCY_SAMPLES if latency is None else latency
    fs = s_model.fs

    def balanced(sos, gain):
        # Section by section in series: one transfer function of the whole is ill-conditioned at these corners.
        system = tf_to_statespace(gain * sos[0, :3], sos[0, 3:])
        for section in sos[1:]:
            system = series(system, tf_to_statespace(section[:3], section[3:]))
        r = minimal_balanced_realisation(*system)
        return StateSpaceFilter(r.A, r.B, r.C, np.array([[float(np.asarray(r.D).reshape(-1)[0])]]))

    q = balanced(scipy.signal.butter(3, [50.0, 500.0], "bandpass", fs=fs, output="sos"), 0.08)
    w = balanced(scipy.signal.butter(8, 1000.0, fs=fs, output="sos"), 0.05)
    predicted, overall, coherence = predict(s_model, default_disturbance(fs, p_model), latency, q, w)
    return Controller(fs, s_model, w, q, latency, band_centres(), predicted, {}, coherence, overall)
