"""The helmet-anc model of one sound path and its JSON file (format helmet-anc/model@1).

A model is the chain  u -> [static input nonlinearity] -> [z^-delay] -> (A, B, C, D) -> y
at one sample rate, optionally with a disturbance model (sinusoids at given
frequencies) that explains part of a measured ear signal but is not part of the
plant. ``history`` records every refinement; ``identification`` how the model was
obtained (estimator, gamma, order, validation figures).

``identification`` keys of ``sysid.identify`` besides those (issue 25; all optional when reading):
``max_order`` the user's cap on the states (None: the lowest order at the noise floor);
``route`` the route that made the model ("order search", "long route" or "seed grid") and
``routes`` every route tried (route, order, validation rms in FS, its ratio to the floor);
``long_route`` how the long route made it (FIR taps, the response's length in taps and ms,
the delay's leading taps, order, refinement, the most states its truncation holds ``most_states``, ``dropped`` the order given
that validated worse than the floor's order and its ratio,
the orders tried and their rms over the floor)
and ``long_estimate`` the long FIR behind the curve; ``order_curve`` the order/error/cost
trade-off: ``orders``, their validation ``rms`` (FS) and ``ratio`` to the ``noise_floor``, the
frequency-limited ``hankel_singular_values`` sigma_(n+1) / sigma_1 indexed by n, the board
cost of each order (``sections``, emulated Cortex-M4 instructions per sample ``q15_block`` and
``q15_step``: ``sysid.core.board``), the refined models' ``refined_orders``, ``refined_rms``
and ``refined_ratio``, the ``chosen`` order and the curve's ``source``; ``capped`` (only when
the cap stopped the model above the floor) its ``max_order``, the model's ``ratio``, the
``floor_order`` the data ask for, its ``floor_ratio`` and ``floor_instructions`` per sample.

The static input nonlinearity (a Hammerstein model's) is a parametric form, then a polynomial,
both optional: v = sum_k a_k w^k with w = form(u). JSON ``"input_nonlinearity": null |
{"coefficients": [a1, a2, ...]}`` holds the polynomial; the optional field
``"input_nonlinearity_form": null | {"kind": "tanh", "scale": s, "gain": g, "offset": o}`` (FS
units; absent = none; ``offset`` defaults to 0, ``gain`` to 1) the saturation

    w = g (s tanh((u + o) / s) - s tanh(o / s)),

a soft clipper that saturates at g s (1 -+ tanh(o / s)) and whose offset o makes it asymmetric
(an even part: a second harmonic); w(0) = 0 and its small-signal gain is g / cosh^2(o / s). A
model without the field is simulated, saved and compared exactly as before it existed.
``{"kind": "identity"}`` is w = u (a polynomial alone behind a pre-filter). The form's optional
``"prefilter": {"kind": "highpass" | "lowpass", "order": 1 | 2, "corner_hz": f}`` is a linear block
in front of the static map (a Wiener-Hammerstein model: u -> prefilter -> form -> polynomial -> core),
the factor of ``sysid.core.structures.factor_coefficients`` (unit pass-band gain; f in Hz below fs/2):
a driver's coupling capacitor or a DC-blocking stage ahead of the part that distorts.
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import scipy.signal

from . import lti
from .errors import ModelError
from .structures import factor_coefficients, factor_response
from .files import atomic_write, atomic_write_text

__all__ = ["Model", "MODEL_FORMAT", "PATHS", "atomic_write_text"]

MODEL_FORMAT = "helmet-anc/model@1"
PATHS = ("fb", "ff")
_REQUIRED_KEYS = ("format", "path", "fs", "A", "B", "C", "D")
# Sane limits of a helmet sound path (issue 12, "absurd sizes"): beyond them a model is a
# corrupt or hand-edited file, and simulating it would take minutes and gigabytes.
MAX_ORDER = 1000           # states; measured responses need hundreds (HD 600 on a KEMAR: about 330; issue 25)
MAX_DELAY_S = 1.0          # seconds of pure delay: 340 m of sound path
MAX_COEFFICIENT = 1e8      # largest |entry| of A, B, C, D
MAX_FS = 1e6               # Hz
MAX_MODEL_BYTES = 64e6     # a model of MAX_ORDER states is about 28 MB of JSON (A: 1e6 entries)


def _numeric(value, name: str) -> np.ndarray:
    """``value`` as a float array, or ModelError for text, nesting of unequal lengths, or objects."""
    if isinstance(value, (str, bytes, dict)):
        raise ModelError(f"{name} matrix is not numeric")
    try:
        array = np.array(value, dtype=float)
    except (TypeError, ValueError, OverflowError):
        raise ModelError(f"{name} matrix is not numeric, or its rows have different lengths") from None
    if array.ndim > 2:
        raise ModelError(f"{name} matrix has {array.ndim} dimensions; expected 2")
    if not np.all(np.isfinite(array)):
        raise ModelError(f"{name} matrix has non-finite entries (NaN or infinity)")
    return array


def _matrix(value, name: str, shape: tuple[int, int]) -> np.ndarray:
    try:
        array = np.array(value, dtype=float)
    except (TypeError, ValueError, OverflowError):
        raise ModelError(f"{name} matrix is not numeric") from None
    if array.ndim == 0 and shape == (1, 1):
        array = array.reshape(1, 1)
    if array.size == 0 and 0 in shape:
        return np.zeros(shape)
    if array.ndim != 2 or array.shape != shape:
        raise ModelError(f"Incompatible dimensions of {name} matrix; expected {shape} but found {array.shape}")
    if not np.all(np.isfinite(array)):
        raise ModelError(f"{name} matrix has non-finite entries")
    return array


FORM_KINDS = ("tanh", "identity")
PREFILTER_KINDS = ("highpass", "lowpass")


def _prefilter(value, fs: float) -> dict | None:
    """The form's ``prefilter`` checked: null or {"kind": "highpass" | "lowpass", "order": 1 | 2, "corner_hz": f}."""
    if value is None:
        return None
    try:
        kind, order, corner = value["kind"], value.get("order", 1), float(value["corner_hz"])
    except (TypeError, KeyError, ValueError):
        kind, order, corner = None, None, math.nan
    if kind not in PREFILTER_KINDS or order not in (1, 2) or isinstance(order, bool) or not 0 < corner < fs / 2:
        raise ModelError(f'input_nonlinearity_form prefilter must be {{"kind": one of {", ".join(PREFILTER_KINDS)}, '
                         f'"order": 1 or 2, "corner_hz": between 0 and fs/2}}; found {value!r}')
    return {"kind": kind, "order": int(order), "corner_hz": corner}


def _nonlinearity_form(value, fs: float) -> dict | None:
    """The ``input_nonlinearity_form`` field checked: null, {"kind": "tanh", "scale": s > 0, "gain", "offset"}
    or {"kind": "identity"}, either with an optional ``prefilter``."""
    if value is None:
        return None
    if not isinstance(value, dict) or value.get("kind") not in FORM_KINDS:
        raise ModelError(f'input_nonlinearity_form must be null or an object {{"kind": one of {", ".join(FORM_KINDS)}, '
                         '"scale": s, "gain": g, "offset": o}')
    prefilter = _prefilter(value.get("prefilter"), fs)
    if value["kind"] == "identity":
        return {"kind": "identity", **({"prefilter": prefilter} if prefilter else {})}
    try:
        scale, gain, offset = (float(value.get(key, default)) for key, default in
                               (("scale", math.nan), ("gain", 1.0), ("offset", 0.0)))
    except (TypeError, ValueError):
        raise ModelError("input_nonlinearity_form scale, gain and offset must be numbers") from None
    if not (math.isfinite(scale) and 0 < scale <= MAX_COEFFICIENT):
        raise ModelError(f"input_nonlinearity_form scale must be a positive amplitude (FS); found {value.get('scale')!r}")
    if not (math.isfinite(gain) and abs(gain) <= MAX_COEFFICIENT and math.isfinite(offset) and abs(offset) <= 10 * scale):
        raise ModelError("input_nonlinearity_form gain must be finite and offset within ten times the scale")
    return {**value, "kind": value["kind"], "scale": scale, "gain": gain, "offset": offset,
            **({"prefilter": prefilter} if prefilter else {})}


def _uncertainty_band(value) -> dict | None:
    """The ``uncertainty`` field checked: null or {"frequencies_hz", "relative_95", ...} (sysid.estimation.uncertainty)."""
    if value is None:
        return None
    if not isinstance(value, dict):
        raise ModelError('uncertainty must be null or an object {"frequencies_hz": [..], "relative_95": [..]}')
    for key in ("frequencies_hz", "relative_95"):
        if key not in value:
            raise ModelError(f"uncertainty is missing {key!r}")
    try:
        frequencies = np.asarray(value["frequencies_hz"], dtype=float).reshape(-1)
        relative = np.asarray(value["relative_95"], dtype=float).reshape(-1)
    except (TypeError, ValueError):
        raise ModelError("uncertainty frequencies_hz and relative_95 must be lists of numbers") from None
    if frequencies.size != relative.size:
        raise ModelError(f"uncertainty frequencies_hz and relative_95 must have the same length; found "
                         f"{frequencies.size} and {relative.size}")
    if not (np.all(np.isfinite(frequencies)) and np.all(np.isfinite(relative))):
        raise ModelError("uncertainty frequencies_hz and relative_95 must be finite")
    if np.any(relative < 0):
        raise ModelError("uncertainty relative_95 must be non-negative")
    if np.any(np.diff(frequencies) <= 0) or np.any(frequencies < 0):
        raise ModelError("uncertainty frequencies_hz must be non-negative and increasing")
    return {**value, "frequencies_hz": frequencies.tolist(), "relative_95": relative.tolist()}


@dataclass
class Model:
    """One identified sound path; see the module docstring for the signal chain.

    A, B, C, D are real arrays of shapes (n, n), (n, 1), (1, n), (1, 1) for
    x(t+1) = A x(t) + B v(t - delay), y(t) = C x(t) + D v(t - delay), where
    v = sum_k a_k w^k is the input polynomial (v = w when there is none) of w = form(u), the
    parametric input nonlinearity ``input_nonlinearity_form`` (w = u when there is none). Units:
    full-scale signal units in and out, ``fs`` in Hz, ``delay`` in samples.
    """

    path: str
    fs: float
    A: np.ndarray
    B: np.ndarray
    C: np.ndarray
    D: np.ndarray
    delay: int = 0
    input_nonlinearity: list[float] | None = None
    disturbance_frequencies: list[float] | None = None
    history: list[dict] = field(default_factory=list)
    identification: dict = field(default_factory=dict)
    # Data corrections (design.md, "The model"; neutral values when absent from the JSON):
    # output_offset (FS) is added to the ear signal; clock_ratio is ear samples per input sample,
    # the measured ear signal is resampled by it before comparison; excluded maps a recording's
    # file name to its stretches [start_s, stop_s] left out of identification and validation.
    output_offset: float = 0.0
    clock_ratio: float = 1.0
    excluded: dict[str, list[list[float]]] = field(default_factory=dict)
    # 95 % bound on |H_model - H_true| / |H_model| per frequency (sysid.estimation.uncertainty); None when unknown.
    uncertainty: dict | None = None
    # The parametric input nonlinearity in front of the polynomial (module docstring); None when absent.
    input_nonlinearity_form: dict | None = None

    def __post_init__(self):
        if self.path not in PATHS:
            raise ModelError(f"path must be one of {', '.join(PATHS)}; found {self.path!r}")
        try:
            self.fs = float(self.fs)
        except (TypeError, ValueError, OverflowError):
            raise ModelError(f"fs must be a number; found {self.fs!r}") from None
        if not (math.isfinite(self.fs) and self.fs > 0):
            raise ModelError(f"fs must be a positive sample rate in Hz; found {self.fs}")
        if self.fs > MAX_FS:
            raise ModelError(f"fs must be at most {MAX_FS:g} Hz; found {self.fs:g}")
        A = _numeric(self.A, "A")
        A = np.atleast_2d(A) if A.size else np.zeros((0, 0))
        n = A.shape[0]
        if n > MAX_ORDER:
            raise ModelError(f"order {n} is above the limit of {MAX_ORDER} states")
        self.A = _matrix(A, "A", (n, n))
        B, C = _numeric(self.B, "B"), _numeric(self.C, "C")
        self.B = _matrix(B.reshape(-1, 1) if B.size else np.zeros((n, 1)), "B", (n, 1))
        self.C = _matrix(C.reshape(1, -1) if C.size else np.zeros((1, n)), "C", (1, n))
        self.D = _matrix(_numeric(self.D, "D"), "D", (1, 1))
        for label in ("A", "B", "C", "D"):
            largest = float(np.max(np.abs(getattr(self, label)), initial=0.0))
            if largest > MAX_COEFFICIENT:
                raise ModelError(f"{label} matrix has an entry of magnitude {largest:.3g}, above the limit of "
                                 f"{MAX_COEFFICIENT:g}")
        if isinstance(self.delay, bool) or not isinstance(self.delay, (int, float, np.integer, np.floating)) \
                or not math.isfinite(float(min(self.delay, 1e300))) or int(self.delay) != self.delay or self.delay < 0:
            raise ModelError(f"delay must be a non-negative whole number of samples; found {self.delay!r}")
        if self.delay > MAX_DELAY_S * self.fs:
            raise ModelError(f"delay of {int(self.delay)} samples is above the limit of {MAX_DELAY_S:g} s "
                             f"({MAX_DELAY_S * self.fs:.0f} samples at {self.fs:g} Hz)")
        self.delay = int(self.delay)
        if self.input_nonlinearity is not None:
            coefficients = _numeric(self.input_nonlinearity, "input_nonlinearity").reshape(-1)
            if coefficients.size == 0 or np.max(np.abs(coefficients)) > MAX_COEFFICIENT:
                raise ModelError("input_nonlinearity needs finite coefficients [a1, a2, ...]")
            self.input_nonlinearity = [float(c) for c in coefficients]
        if self.disturbance_frequencies is not None:
            frequencies = _numeric(self.disturbance_frequencies, "disturbance frequencies").reshape(-1)
            if np.any(~np.isfinite(frequencies)) or np.any(frequencies <= 0) or np.any(frequencies >= self.fs / 2):
                raise ModelError("disturbance frequencies must lie between 0 and fs/2")
            self.disturbance_frequencies = [float(f) for f in frequencies]
        try:
            self.output_offset = float(self.output_offset)
            self.clock_ratio = float(self.clock_ratio)
        except (TypeError, ValueError):
            raise ModelError("output_offset and clock_ratio must be numbers") from None
        if not math.isfinite(self.output_offset):
            raise ModelError(f"output_offset must be finite; found {self.output_offset}")
        if not (math.isfinite(self.clock_ratio) and 0.9 < self.clock_ratio < 1.1):
            raise ModelError(f"clock_ratio must be near 1 (ear samples per input sample); found {self.clock_ratio}")
        if not isinstance(self.excluded, dict):
            raise ModelError("excluded must be an object {recording: [[start_s, stop_s], ...]}")
        try:
            self.excluded = {str(name): [[float(a), float(b)] for a, b in spans] for name, spans in self.excluded.items()}
        except (TypeError, ValueError):
            raise ModelError("excluded must map each recording to [[start_s, stop_s], ...]") from None
        self.uncertainty = _uncertainty_band(self.uncertainty)
        self.input_nonlinearity_form = _nonlinearity_form(self.input_nonlinearity_form, self.fs)

    # -- properties -------------------------------------------------------------
    @property
    def order(self) -> int:
        return int(self.A.shape[0])

    @property
    def spectral_radius(self) -> float:
        """Largest pole modulus; the stability margin is 1 - spectral_radius."""
        return lti.spectral_radius(self.A)

    @property
    def stable(self) -> bool:
        return self.spectral_radius < 1.0

    def check_stable(self, name: str = "model") -> "Model":
        """This model, or ModelError when a pole lies on or outside the unit circle (its simulation diverges)."""
        if not self.stable:
            raise ModelError(f"{name}: model is unstable (largest pole radius {self.spectral_radius:.6f} >= 1), so "
                             "its simulation diverges; identify it again or refine it from a stable model")
        return self

    def poles(self) -> np.ndarray:
        return np.linalg.eigvals(self.A) if self.order else np.zeros(0, complex)

    def zeros(self) -> np.ndarray:
        """Finite zeros of the LTI core (the delay adds `delay` poles at the origin)."""
        return lti.invariant_zeros(self.A, self.B, self.C, self.D)

    # -- behaviour --------------------------------------------------------------
    def frequency_response(self, frequencies_hz) -> np.ndarray:
        """Complex response of the linear part (delay included) at frequencies in Hz.

        The input nonlinearity contributes its small-signal gain (a1, times g / cosh^2(o / s) of a form)
        and its form's pre-filter.
        """
        f = np.asarray(frequencies_hz, dtype=float)
        z = np.exp(2j * np.pi * f / self.fs)
        response = lti.frequency_response(self.A, self.B, self.C, self.D, z) * z ** (-self.delay)
        if self.input_nonlinearity is not None:
            response = response * self.input_nonlinearity[0]
        form = self.input_nonlinearity_form or {}
        if form.get("kind") == "tanh":
            response = response * form["gain"] / math.cosh(form["offset"] / form["scale"]) ** 2
        if form.get("prefilter"):
            response = response * factor_response(*self.input_prefilter(), f, self.fs)
        return response

    def input_prefilter(self) -> tuple[np.ndarray, np.ndarray] | None:
        """(b, a) of the form's pre-filter (``sysid.core.structures.factor_coefficients``), or None."""
        prefilter = (self.input_nonlinearity_form or {}).get("prefilter")
        return None if prefilter is None else factor_coefficients(prefilter["kind"], prefilter, self.fs)

    def apply_input_nonlinearity(self, u: np.ndarray) -> np.ndarray:
        """The input block on a signal from rest: the form's pre-filter, then the static map
        (``static_input_nonlinearity``); u itself when the model has neither."""
        prefilter = self.input_prefilter()
        u = np.asarray(u, dtype=float)
        return self.static_input_nonlinearity(scipy.signal.lfilter(*prefilter, u) if prefilter else u)

    def static_input_nonlinearity(self, u: np.ndarray) -> np.ndarray:
        """v = a1 w + a2 w^2 + ... of w = form(u) (the module docstring; the pre-filter left out: the map's
        harmonic levels are those of a sine in the pre-filter's pass band)."""
        u = np.asarray(u, dtype=float)
        if (self.input_nonlinearity_form or {}).get("kind") == "tanh":
            form = self.input_nonlinearity_form
            s, o = form["scale"], form["offset"]
            u = form["gain"] * s * (np.tanh((u + o) / s) - math.tanh(o / s))
        if self.input_nonlinearity is None:
            return u
        v = np.zeros_like(u)
        for k, a in enumerate(self.input_nonlinearity, start=1):
            v += a * u**k
        return v

    def simulate(self, u: np.ndarray) -> np.ndarray:
        """Predicted ear signal for input u (full-scale units), from rest."""
        v = self.apply_input_nonlinearity(u)
        if self.delay:
            v = np.concatenate((np.zeros(min(self.delay, v.size)), v[: max(v.size - self.delay, 0)]))
        y = lti.simulate(self.A, self.B, self.C, self.D, v)
        return y + self.output_offset if self.output_offset else y

    # -- conversions ------------------------------------------------------------
    def to_statespace(self):
        """python-control StateSpace of the LTI core with the delay as extra states."""
        import control

        A, B, C, D = self.A, self.B, self.C, self.D
        if self.delay:
            # A chain of `delay` unit delays in front of the core.
            d = self.delay
            shift = np.eye(d, k=-1)
            A = np.block([[shift, np.zeros((d, self.order))], [B @ np.eye(1, d, d - 1), A]])
            B = np.vstack([np.eye(d, 1), np.zeros((self.order, 1))])
            C = np.hstack([D @ np.eye(1, d, d - 1), C])
            D = np.zeros((1, 1))
        return control.ss(A, B, C, D, 1.0 / self.fs)

    def to_dict(self) -> dict:
        return {
            "format": MODEL_FORMAT,
            "path": self.path,
            "fs": self.fs,
            "A": self.A.tolist(),
            "B": self.B.tolist(),
            "C": self.C.tolist(),
            "D": self.D.tolist(),
            "delay": self.delay,
            "input_nonlinearity": None if self.input_nonlinearity is None else {"coefficients": list(self.input_nonlinearity)},
            "disturbance": None if self.disturbance_frequencies is None else {"frequencies": list(self.disturbance_frequencies)},
            "stable": self.stable,
            "history": list(self.history),
            "identification": dict(self.identification),
            **({"output_offset": self.output_offset} if self.output_offset else {}),
            **({"clock_ratio": self.clock_ratio} if self.clock_ratio != 1.0 else {}),
            **({"excluded": dict(self.excluded)} if self.excluded else {}),
            **({"uncertainty": dict(self.uncertainty)} if self.uncertainty is not None else {}),
            **({"input_nonlinearity_form": dict(self.input_nonlinearity_form)}
               if self.input_nonlinearity_form is not None else {}),
        }

    @classmethod
    def from_dict(cls, data: dict) -> "Model":
        if not isinstance(data, dict):
            raise ModelError("model must be a JSON object")
        tag = data.get("format")
        if isinstance(tag, str) and tag.startswith("helmet-anc/") and tag != MODEL_FORMAT:
            # Another of our files (a controller, a comparison, a session's truth): say which, not what it lacks.
            raise ModelError(f"this is a {tag.split('/', 1)[1].split('@')[0]} ({tag}), not a model; give the model "
                             "JSON (e.g. from identify -o)")
        missing = [key for key in _REQUIRED_KEYS if key not in data]
        if missing:
            raise ModelError(f"model is missing key(s): {', '.join(missing)}")
        if data["format"] != MODEL_FORMAT:
            raise ModelError(f"model format must be {MODEL_FORMAT!r}; found {data['format']!r}")
        nonlinearity = data.get("input_nonlinearity")
        if nonlinearity is not None:
            if not isinstance(nonlinearity, dict) or "coefficients" not in nonlinearity:
                raise ModelError("input_nonlinearity must be null or {\"coefficients\": [...]}")
            nonlinearity = nonlinearity["coefficients"]
        disturbance = data.get("disturbance")
        if disturbance is not None:
            if not isinstance(disturbance, dict) or "frequencies" not in disturbance:
                raise ModelError("disturbance must be null or {\"frequencies\": [...]}")
            disturbance = disturbance["frequencies"]
        history = data.get("history", [])
        identification = data.get("identification", {})
        if not isinstance(history, list) or not isinstance(identification, dict):
            raise ModelError("history must be a list and identification an object")
        return cls(
            path=data["path"],
            fs=data["fs"],
            A=data["A"],
            B=data["B"],
            C=data["C"],
            D=data["D"],
            delay=data.get("delay", 0),
            input_nonlinearity=nonlinearity,
            disturbance_frequencies=disturbance,
            history=history,
            identification=identification,
            output_offset=data.get("output_offset", 0.0),
            clock_ratio=data.get("clock_ratio", 1.0),
            excluded=data.get("excluded") or {},
            uncertainty=data.get("uncertainty"),
            input_nonlinearity_form=data.get("input_nonlinearity_form"),
        )

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), indent=2, allow_nan=False) + "\n"

    def save(self, path: str | os.PathLike) -> None:
        """Write the model as JSON atomically."""
        atomic_write_text(path, self.to_json())

    @classmethod
    def load(cls, path: str | os.PathLike) -> "Model":
        if Path(path).is_dir():
            raise ModelError(f"{path}: is a folder; give the model's JSON file")
        try:
            raw = Path(path).read_bytes()
        except OSError as exc:
            raise ModelError(f"{path}: cannot read model ({exc.strerror})") from None
        if raw[:4] in (b"RIFF", b"RIFX", b"RF64"):
            raise ModelError(f"{path}: is a WAV recording, not a model; give the model JSON (e.g. from identify -o)")
        if len(raw) > MAX_MODEL_BYTES:
            raise ModelError(f"{path}: {len(raw) / 1e6:.0f} MB is too large for a model file (limit "
                             f"{MAX_MODEL_BYTES / 1e6:.0f} MB)")
        try:
            data = json.loads(raw.decode("utf-8"))
        except UnicodeDecodeError:
            raise ModelError(f"{path}: not a model JSON file (not UTF-8 text)") from None
        except json.JSONDecodeError as exc:
            raise ModelError(f"{path}: not valid JSON ({exc.msg} at line {exc.lineno})") from None
        except RecursionError:
            raise ModelError(f"{path}: not a model JSON file (nested too deeply)") from None
        try:
            return cls.from_dict(data)
        except ModelError as exc:
            raise ModelError(f"{path}: {exc}") from None

    def save_mat(self, path: str | os.PathLike) -> None:
        """Export A, B, C, D, Ts (s), delay (samples) and path for MATLAB (.mat, v5), atomically.

        ``format`` holds the model format tag, which marks the file as ours (sysid.core.files.is_ours).
        """
        import scipy.io

        variables = {"A": self.A, "B": self.B, "C": self.C, "D": self.D, "Ts": 1.0 / self.fs,
                     "fs": self.fs, "delay": float(self.delay), "path": self.path, "format": MODEL_FORMAT}
        atomic_write(path, lambda tmp: scipy.io.savemat(tmp, variables))
