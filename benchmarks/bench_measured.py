"""Benchmark of identify on the measured responses (issue 25), side by side with the plain estimates.

Per measured response (``sysid.core.measured``: the HD 600 headphone transfer function on a KEMAR,
Geier and Erbes, University of Rostock; the FABIAN dummy-head HRIR, Brinkmann et al., TU Berlin;
both CC BY 4.0), in a session as issue 25's tries (23 s noise, two 8 s sweeps, 2e-4 FS ear noise,
16-bit), in one run: identify at the default cap (route, order, validation rms over the noise
floor, largest magnitude error in dB over 50 Hz-2 kHz against the true taps, wall time); the
least-squares FIR of 256 and 1024 taps; a high-order ARX by least squares; the true taps' own
balanced truncation at our order and the order at which it reaches 1.2 times the floor.
Then identify's wall time over the measured responses and random helmets together at the
default cap (median, worst), and for a 600-state model (the HD 600 with its order set to 600).
Every identify call is timed by the wall clock and by the process's CPU time side by side (the
machine may be shared: the load average before and after the run is printed with them).
``--timing-only``: identify's times alone, without the reference estimates (ARX and the true taps'
truncation take minutes on the HD 600).

Run:  python benchmarks/bench_measured.py [--helmets 20] [--timing-only]   (prints a Markdown section)
"""

from __future__ import annotations

import argparse
import os
import statistics
import time

import numpy as np
import scipy.linalg
import scipy.signal

from sysid.core.measured import measured_response
from sysid.estimation.long_response import fir_estimate, system_response
from sysid.estimation.long_route import fir_rms
from sysid.identify import IdentificationOptions, identify
from sysid.random_plant import random_session
from sysid.simulate import measured_session
from sysid.validation.sweeps import noise_floor, rms_from_responses, sweep_spectrum

SESSION = dict(noise_duration=23.0, sweep_duration=8.0)
NAMES = ("hptf_hd600_left", "fabian_left_az60")
F_DB = np.geomspace(50.0, 2000.0, 400)
ARX_ORDER = 100
ARX_SECONDS = 6.0
AT = 1.2


def _largest_db(response: np.ndarray, taps: np.ndarray, fs: float) -> float:
    truth = np.polynomial.polynomial.polyval(np.exp(-2j * np.pi * F_DB / fs), taps)
    return float(np.max(np.abs(20.0 * np.log10(np.abs(response) / np.abs(truth)))))


def _model_response(model, f: np.ndarray) -> np.ndarray:
    z = np.exp(2j * np.pi * f / model.fs)
    return system_response(model.A, model.B, model.C, model.D, z) * z ** (-model.delay)


def _fir_row(taps: np.ndarray, spectra, floor: float, fs: float, truth: np.ndarray) -> tuple[float, float]:
    response = np.polynomial.polynomial.polyval(np.exp(-2j * np.pi * F_DB / fs), taps)
    return fir_rms(taps, spectra) / floor, _largest_db(response, truth, fs)


def _arx(noise, start: int, order: int, seconds: float):
    """ARX(order, order) by least squares on ``seconds`` of the noise recording after ``start``: y[t] + a_1 y[t-1]
    + ... = b_0 u[t] + ... + b_order u[t-order] (Ljung, "System Identification", 2nd ed., sec. 4.2)."""
    n = int(seconds * noise.fs)
    u = noise.u - np.mean(noise.u)
    y = noise.y - np.mean(noise.y)
    t = np.arange(start, start + n)
    columns = [-y[t - k] for k in range(1, order + 1)] + [u[t - k] for k in range(order + 1)]
    theta = scipy.linalg.lstsq(np.column_stack(columns), y[t], lapack_driver="gelsy")[0]
    return np.r_[1.0, theta[:order]], theta[order:]


def _arx_row(a, b, spectra, floor, fs, truth):
    responses = []
    for s in spectra:
        w = np.exp(-2j * np.pi * s.frequencies / s.fs)
        responses.append(np.polynomial.polynomial.polyval(w, b) / np.polynomial.polynomial.polyval(w, a))
    w = np.exp(-2j * np.pi * F_DB / fs)
    stable = bool(np.all(np.abs(np.roots(a)) < 1.0))
    return (rms_from_responses(spectra, responses) / floor,
            _largest_db(np.polynomial.polynomial.polyval(w, b) / np.polynomial.polynomial.polyval(w, a),
                        truth, fs), stable)


class _TrueTruncation:
    """Balanced truncation of the true taps' shift realisation by the Hankel SVD (Kung 1978: controllability
    Gramian I, observability Gramian H^T H), each order's validation rms on the sweeps."""

    def __init__(self, taps, spectra):
        self.taps, self.spectra = taps, spectra
        h = taps[1:]
        m = h.size
        index = np.add.outer(np.arange(m), np.arange(m))
        _, self.s, vt = np.linalg.svd(np.where(index < m, h[np.minimum(index, m - 1)], 0.0))
        self.v = vt.T
        self.measured = {}

    def rms(self, n: int) -> float:
        if n not in self.measured:
            v, root = self.v[:, :n], np.sqrt(self.s[:n])
            shifted = np.vstack((np.zeros((1, n)), v[:-1]))
            A = (v.T @ shifted) * root[:, None] / root[None, :]
            B, C = root * v[0], (self.taps[1:] @ v) / root
            out = np.zeros(4 * self.taps.size)
            out[0], x = self.taps[0], B.copy()
            for k in range(1, out.size):
                out[k] = C @ x
                x = A @ x
            self.measured[n] = fir_rms(out, self.spectra)
        return self.measured[n]

    def order_at(self, limit: float) -> int:
        low, high = 0, self.taps.size - 1
        while high - low > 1:
            middle = (low + high) // 2
            low, high = (low, middle) if self.rms(middle) <= limit else (middle, high)
        return high


def _timed_identify(session, options: IdentificationOptions | None = None):
    """(identify's result on the session's FB path, its wall time, its CPU time: s)."""
    t0, c0 = time.perf_counter(), time.process_time()
    result = identify(session.noise, session.sweeps, "fb", options or IdentificationOptions())
    return result, time.perf_counter() - t0, time.process_time() - c0


def _measured(name: str, references: bool = True) -> tuple[list[str], tuple[float, float]]:
    plant = measured_response(name)
    session = measured_session(name, **SESSION)
    sweeps, noise = session.sweeps, session.noise
    spectra = [sweep_spectrum(s) for s in sweeps]
    floor = noise_floor(*sweeps)
    result, wall, cpu = _timed_identify(session)
    model, info = result.model, result.model.identification
    ours = rms_from_responses(spectra, [_model_response(model, s.frequencies) for s in spectra]) / floor
    rows = [f"| {name} | ours: {info.get('route')} | {model.order} | {ours:.3f} | "
            f"{_largest_db(_model_response(model, F_DB), plant.taps, noise.fs):.3f} | {wall:.1f} s ({cpu:.1f} s CPU) |"]
    if not references:
        return rows, (wall, cpu)
    start = int(round(IdentificationOptions().transient_s * noise.fs))
    for taps in (256, 1024):
        t0 = time.perf_counter()
        estimate = fir_estimate(noise.u, noise.y, noise.fs, taps, start)
        ratio, worst = _fir_row(estimate.taps, spectra, floor, noise.fs, plant.taps)
        rows.append(f"| | least-squares FIR | {taps} taps | {ratio:.3f} | {worst:.3f} | "
                    f"{time.perf_counter() - t0:.1f} s |")
    t0 = time.perf_counter()
    a, b = _arx(noise, start, ARX_ORDER, ARX_SECONDS)
    ratio, worst, stable = _arx_row(a, b, spectra, floor, noise.fs, plant.taps)
    rows.append(f"| | ARX({ARX_ORDER},{ARX_ORDER}) least squares, {ARX_SECONDS:g} s | {ARX_ORDER} poles"
                f"{'' if stable else ' (unstable)'} | {ratio:.3f} | {worst:.3f} | {time.perf_counter() - t0:.1f} s |")
    t0 = time.perf_counter()
    truth = _TrueTruncation(plant.taps, spectra)
    needed = truth.order_at(AT * floor)
    rows.append(f"| | true taps' balanced truncation at our order | {model.order} | {truth.rms(model.order) / floor:.3f}"
                f" | | |")
    rows.append(f"| | true taps' balanced truncation, first order at {AT}x | {needed} | "
                f"{truth.rms(needed) / floor:.3f} | | {time.perf_counter() - t0:.1f} s |")
    return rows, (wall, cpu)


def _spread(times: list[float]) -> str:
    return f"median {statistics.median(times):.1f} s, worst {max(times):.1f} s" if times else "none"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--helmets", type=int, default=20)
    parser.add_argument("--timing-only", action="store_true")
    args = parser.parse_args()
    load_before = os.getloadavg()
    lines = ["| response | estimate | order | rms / floor | largest error 50 Hz-2 kHz (dB) | wall time |",
             "|---|---|---|---|---|---|"]
    measured = []
    for name in NAMES:
        rows, times = _measured(name, not args.timing_only)
        lines += rows
        measured.append(times)
        print("\n".join(rows), flush=True)
    helmets = []
    for seed in range(args.helmets):
        result, wall, cpu = _timed_identify(random_session(seed, **SESSION))
        helmets.append((wall, cpu))
        print(f"helmet {seed}: {wall:.1f} s wall, {cpu:.1f} s CPU, order {result.model.order}, "
              f"route {result.model.identification.get('route')}", flush=True)
    hd600 = measured_session("hptf_hd600_left", **SESSION)
    big = []
    for label, options in (("orders (600,), max_order 600", IdentificationOptions(orders=(600,), max_order=600)),
                           ("max_order 700", IdentificationOptions(max_order=700))):
        result, wall, cpu = _timed_identify(hd600, options)
        big.append(f"identify of the HD 600 with {label}: {result.model.order} states, "
                   f"{result.model.identification['rms'] / result.noise_floor:.3f}x the floor, {wall:.1f} s wall, "
                   f"{cpu:.1f} s CPU")
        print(big[-1], flush=True)
    every = measured + helmets
    lines += ["", f"identify at the default cap over the {len(measured)} measured responses and {len(helmets)} random "
                  f"helmets: wall {_spread([w for w, _ in every])}; CPU {_spread([c for _, c in every])} "
                  f"(measured: {', '.join(f'{w:.1f} / {c:.1f}' for w, c in measured)} s wall / CPU; helmets: wall "
                  f"{_spread([w for w, _ in helmets])}, CPU {_spread([c for _, c in helmets])})", *big,
              f"load average (1, 5, 15 min) before the run {', '.join(f'{x:.1f}' for x in load_before)}, after "
              f"{', '.join(f'{x:.1f}' for x in os.getloadavg())}"]
    print("\n".join(lines))


if __name__ == "__main__":
    main()
