"""Sample-by-sample Python twins of the generated filters and of the board's control loop.

:class:`FixedStepper` and :class:`Float32Stepper` run a generated filter one block at a
time with its state carried over (a closed loop needs each output before the next input):
the Q15 one chains :func:`codegen.reference.fixed_section`, the specification of the
generated code; the float32 one performs the operations of
:func:`codegen.reference.float32_reference` (which takes whole signals) in the same order.
:func:`board_loop` is the twin of ``firmware/closed_loop.c`` running
``firmware/anc_control.c``: the quantised controller against a simulated true plant, in
the codec's frame order, with the same limiter; its Q15 run equals the C bit for bit.

Beside the steps of firmware generation: it imports the designs and the references, and
takes a controller's plan (:class:`codegen.controller.ControllerPlan`) as an argument.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from sysid.core.model import Model

from .fixedpoint import FixedDesign
from .float32 import FloatDesign
from .reference import fixed_input, fixed_section, q31_to_q15_output

__all__ = ["BoardRun", "FixedStepper", "Float32Stepper", "Limits", "board_loop"]

_f32 = np.float32


class FixedStepper:
    """The generated Q15 filter of ``design`` (module :mod:`codegen.fixedpoint`), block by block:
    :func:`codegen.reference.fixed_section` per section with its state carried over."""

    def __init__(self, design: FixedDesign):
        self.design = design
        # The delay line is kept here; the input polynomial is memoryless.
        self._undelayed = replace(design, delay=0)
        self.reset()

    def reset(self) -> None:
        self.states = [None] * len(self.design.sections)
        self.line = [0] * self.design.delay
        self.pos = 0

    def process(self, block) -> list[int]:
        """Q15 input words -> Q15 output words."""
        delay = self.design.delay
        words = [int(u) for u in block]
        if delay:
            for i, u in enumerate(words):
                words[i], self.line[self.pos] = self.line[self.pos], u
                self.pos = 0 if self.pos + 1 == delay else self.pos + 1
        x = fixed_input(self._undelayed, np.array(words, np.int16))
        for k, section in enumerate(self.design.sections):
            x, self.states[k] = fixed_section(section, x, self.design.quantiser, self.states[k])
        return q31_to_q15_output(x).tolist()


class Float32Stepper:
    """The generated float32 filter of ``design`` (module :mod:`codegen.float32`), sample by sample."""

    def __init__(self, design: FloatDesign):
        self.design = design
        self.sections = []
        for s in design.sections:
            b0, m1, m2 = (_f32(v) for v in s.b)
            numerator = {3: [(b0, "dd"), (m1, "v1"), (m2, "d1")], 2: [(b0, "d0"), (m1, "v1")], 1: [(b0, "v0")],
                         0: []}[s.taps]
            numerator = [(c, role) for c, role in numerator if c != 0.0]
            if s.order == 2:
                output = [(_f32(c), i) for i, c in enumerate(s.c) if c != 0.0]
                rows = [[(_f32(c), j) for j, c in enumerate(s.n[2 * i: 2 * i + 2]) if c != 0.0]
                        + ([(_f32(s.g[i]), "input")] if s.g[i] != 0.0 else []) for i in range(2)]
                poles = (output, rows)
            else:
                poles = _f32(s.c[0]) if s.order == 1 and s.c[0] != 0.0 else None
            self.sections.append((s.order, numerator, poles))
        self.reset()

    def reset(self) -> None:
        zero = _f32(0.0)
        self.h = [[zero, zero] for _ in range(len(self.sections) + 1)]
        self.s = [[zero, zero] for _ in self.sections]
        self.line = [zero] * self.design.delay
        self.pos = 0

    def step(self, u) -> np.float32:
        design = self.design
        u = _f32(u)
        if design.delay:
            u, self.line[self.pos] = self.line[self.pos], u
            self.pos = 0 if self.pos + 1 == design.delay else self.pos + 1
        if design.polynomial is None:
            v = u
        else:
            p = _f32(design.polynomial[-1])
            for a in design.polynomial[-2::-1]:
                p = _f32(a) + p * u
            v = p * u
        h = self.h
        d = v - h[0][0]
        for k, (order, numerator, poles) in enumerate(self.sections):
            v1, d1 = h[k]
            w1 = h[k + 1][0]
            h[k] = [v, d]
            values = {"dd": d - d1, "v1": v1, "d1": d1, "d0": d, "v0": v}
            f = numerator[0][0] * values[numerator[0][1]] if numerator else _f32(0.0)
            for c, role in numerator[1:]:
                f = f + c * values[role]
            if order == 2:
                output, rows = poles
                states = self.s[k]
                w = f
                for c, i in output:
                    w = w + c * states[i]
                new = []
                for i, row in enumerate(rows):
                    if not row:
                        new.append(states[i])
                        continue
                    terms = [c * (v if j == "input" else states[j]) for c, j in row]
                    increment = terms[0]
                    for term in terms[1:]:
                        increment = increment + term
                    new.append(states[i] + increment)
                self.s[k] = new
                v, d = w, w - w1
            elif order == 1:
                t = f if poles is None else f + poles * w1
                v, d = w1 + t, t
            else:
                v, d = f, f - w1
        h[-1] = [v, d]
        return v

    def process(self, block) -> list:
        return [self.step(u) for u in block]


@dataclass(frozen=True)
class Limits:
    """The limiter's parameters (``firmware/anc_control.h``, ANC_LIMIT_*), frames and LSB."""

    rail_samples: int = 64
    window: int = 1024
    growth_windows: int = 3
    floor: int = 64


@dataclass
class BoardRun:
    """What ``firmware/closed_loop.c`` writes: the ear words captured, the drive words played
    (int16, one per frame) and the control path's status counters; and ``d_hat``, the
    disturbance estimate of each captured frame (int16)."""

    ear: np.ndarray
    drive: np.ndarray
    muted: int
    trips: int
    muted_at: int
    frames: int
    model_saturations: int
    d_hat: np.ndarray


def _sat16(v: int) -> int:
    return 32767 if v > 32767 else (-32768 if v < -32768 else v)


def _float_to_word(v) -> int:
    """anc_to_word of anc_control.c: floor(32768 v + 1/2) in float32, saturated; NaN -> 0."""
    t = _f32(v) * _f32(32768.0)
    if t != t:
        return 0
    if t >= _f32(32767.0):
        return 32767
    if t <= _f32(-32768.0):
        return -32768
    t = t + _f32(0.5)
    q = int(t)
    return q - 1 if q > t else q


def _adc(e: float) -> int:
    """The ADC of closed_loop.c: floor(32768 e + 1/2), saturated to 16 bits."""
    t = e * 32768.0 + 0.5
    if t >= 32767.0:
        return 32767
    if t <= -32768.0:
        return -32768
    return math.floor(t)


class _Limiter:
    def __init__(self, limits: Limits):
        self.limits = limits
        self.clear()

    def clear(self) -> None:
        self.rail_score = self.fill = self.total = self.previous = self.growth_run = 0

    def update(self, drive: int, d_hat: int) -> int:
        limits = self.limits
        if drive in (32767, -32768) or d_hat in (32767, -32768):
            self.rail_score += 8
        elif self.rail_score:
            self.rail_score -= 1
        if self.rail_score >= 8 * limits.rail_samples:
            return 1
        self.total += abs(d_hat)
        self.fill += 1
        if self.fill == limits.window:
            if self.total // 2 > self.previous and self.total > limits.floor * limits.window:
                self.growth_run += 1
            else:
                self.growth_run = 0
            self.previous, self.total, self.fill = self.total, 0, 0
            if self.growth_run >= limits.growth_windows:
                return 2
        return 0


def board_loop(plan, plant: Model, d: np.ndarray, chin: np.ndarray, variant: str = "q15", block: int = 1,
               limits: Limits = Limits()) -> BoardRun:
    """The controller of ``plan`` (:class:`codegen.controller.ControllerPlan`) on the true
    FB path ``plant`` with ear noise ``d`` (full scale) and chin words ``chin`` (int16),
    frame by frame as ``firmware/closed_loop.c`` with ``anc_control.c`` built for
    ``variant`` ('q15' or 'float') and ANC_CONTROL_BLOCK = ``block``."""
    fixed = variant == "q15"
    make = (lambda p: FixedStepper(plan.fixed(p))) if fixed else (lambda p: Float32Stepper(plan.floating(p)))
    model = make("model")
    q = make("fb") if "fb" in plan.plans else None
    w = make("ff") if "ff" in plan.plans else None
    extra = plan.latency_samples - 2 * block
    if extra < 0:
        raise ValueError(f"latency_samples {plan.latency_samples} is below the control path's {2 * block}")
    zero = 0 if fixed else _f32(0.0)
    scale = _f32(1.0 / 32768.0)
    d_line, x_line, line_pos = [zero] * extra, [zero] * extra, 0
    limiter = _Limiter(limits)
    muted = trips = muted_at = frames = saturations = 0

    A, B, C = (np.asarray(m, float) for m in (plant.A, plant.B, plant.C))
    order = A.shape[0]
    A_rows = [A[i].tolist() for i in range(order)]
    B_list, C_list, D = B[:, 0].tolist(), C[0].tolist(), float(plant.D[0, 0])
    state = [0.0] * order
    delay_line, pos = [0.0] * plant.delay, 0

    d = np.asarray(d, float).tolist()
    chin = np.asarray(chin, np.int16).tolist()
    n = len(d)
    ear_out = np.zeros(n, np.int16)
    drive_out = np.zeros(n, np.int16)
    d_hat_out = np.zeros(n, np.int16)
    ear_buf = [[0] * block, [0] * block]
    chin_buf = [[0] * block, [0] * block]
    drive_buf = [[0] * block, [0] * block]
    for k in range(n):
        h, slot = (k // block) & 1, k % block
        played = drive_buf[h][slot]
        v = played / 32768.0
        if plant.delay:
            v, delay_line[pos] = delay_line[pos], v
            pos = 0 if pos + 1 == plant.delay else pos + 1
        e = 0.0
        for i in range(order):
            e = e + C_list[i] * state[i]
        e = d[k] + (e + D * v)
        next_state = []
        for i in range(order):
            t = B_list[i] * v
            row = A_rows[i]
            for j in range(order):
                t = t + row[j] * state[j]
            next_state.append(t)
        state = next_state
        ear_buf[h][slot] = _adc(e)
        chin_buf[h][slot] = chin[k]
        ear_out[k], drive_out[k] = ear_buf[h][slot], played
        if slot + 1 < block:
            continue
        # The codec interrupt: anc_control_dma_done(ctl, h).
        if fixed:
            model_out = model.process(drive_buf[h])
        else:
            model_out = model.process([_f32(word) * scale for word in drive_buf[h]])
        q_in, w_in, d_hat = [], [], []
        for i in range(block):
            if fixed:
                dv = _sat16(ear_buf[h][i] - model_out[i])
                xv = chin_buf[h][i]
                saturations += model_out[i] in (32767, -32768)
                d_hat.append(dv)
            else:
                dv = _f32(ear_buf[h][i]) * scale - model_out[i]
                xv = _f32(chin_buf[h][i]) * scale
                saturations += bool(model_out[i] >= 1.0 or model_out[i] <= -1.0)
                d_hat.append(_float_to_word(dv))
            if extra:
                q_in.append(d_line[line_pos])
                w_in.append(x_line[line_pos])
                d_line[line_pos], x_line[line_pos] = dv, xv
                line_pos = 0 if line_pos + 1 == extra else line_pos + 1
            else:
                q_in.append(dv)
                w_in.append(xv)
        q_out = q.process(q_in) if q is not None else [zero] * block
        w_out = w.process(w_in) if w is not None else [zero] * block
        d_hat_out[k + 1 - block: k + 1] = d_hat
        tripped = False
        for i in range(block):
            total = _sat16(q_out[i] + w_out[i]) if fixed else _float_to_word(q_out[i] + w_out[i])
            if not muted:
                reason = limiter.update(total, d_hat[i])
                if reason:
                    muted, trips, muted_at, tripped = reason, trips + 1, frames, True
            drive_buf[h][i] = 0 if muted else total
            frames += 1
        if tripped:
            for stepper in (q, w):
                if stepper is not None:
                    stepper.reset()
            d_line, x_line, line_pos = [zero] * extra, [zero] * extra, 0
    return BoardRun(ear_out, drive_out, muted, trips, muted_at, frames, saturations, d_hat_out)
