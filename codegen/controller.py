"""C code of a controller (format helmet-anc/controller@1) for the board's control path.

:func:`plan_controller` designs three filters with the model filters' pipeline
(:func:`codegen.plan.plan_firmware`: balanced realisation, sections, scaling, Q15 with error
feedback and float32 variants, the same refusals): ``ctl_s`` the internal model S_model,
``ctl_q`` the feedback filter Q and ``ctl_w`` the feed-forward filter W (each only when the
controller has it). A variant whose predicted SNR misses --min-snr in any of the filters is not
generated for any of them (the control path runs one variant throughout) and the reason is kept
(``ControllerPlan.refused``); only when no requested variant is left is the controller refused. It is the plan step of a controller's firmware: it reads the controller
from :mod:`anc.controller` (below ``codegen``) and imports no step after the plan;
:func:`codegen.api.generate_controller_firmware` renders the filters with the model
templates, adds ``controller_config.h`` (latency and which filters exist, read by
``firmware/anc_control.h``) and writes the folder with its manifest.

Worst-case headroom (:func:`headroom`): for a filter H with impulse response h, a
sequence bounded by 1 in magnitude gives outputs bounded by ||h||_1 = sum |h[n]|, and the
sequence sign(h[N - n]) reaches the bound (the L1 norm is the exact worst case, where the
L-infinity scaling of the sections covers sines only). Per filter and per section output
this gives the largest input peak (dBFS) that no input of that peak can saturate; for the
drive y = Q d_hat + W x, ||Q||_1 + ||W||_1; for the disturbance estimate
d_hat = e - S_model y, 1 + ||S_model||_1 ||y||_inf. Beyond these levels the generated
code saturates (never wraps) and the limiter of the control path watches the rails.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass, field, replace

import numpy as np
import scipy.signal

from anc.controller import BOARD_LATENCY_SAMPLES, Controller
from sysid.core.model import Model

from .errors import CodegenError, PrecisionError
from .plan import Plan, plan_firmware
from .targets import get_target, refusal_reason

__all__ = ["CONTROL_BLOCK_MAX", "CONTROLLER_MIN_SNR_DB", "FILTER_NAMES", "ControllerPlan", "format_headroom_table",
           "headroom", "plan_controller"]

# Names of the generated filters: the runtime's control path includes them by these names.
FILTER_NAMES = {"model": "ctl_s", "fb": "ctl_q", "ff": "ctl_w"}
# The control path's processing latency is 2 blocks of 1 to 4 frames (firmware/anc_control.h).
CONTROL_BLOCK_MAX = 4
# A controller's filters are refused below this predicted SNR unless --min-snr says otherwise (dB).
CONTROLLER_MIN_SNR_DB = 30.0
PROCESSING_LATENCY_MIN = BOARD_LATENCY_SAMPLES
_LABELS = {"model": "internal model S", "fb": "controller Q", "ff": "controller W"}


@dataclass
class ControllerPlan:
    """The plans of the controller's filters (keys 'model', 'fb', 'ff'), its latency and headroom.

    ``refused`` maps a requested variant that is not generated ('q15', 'float') to the one-line
    reason (the first filter whose predicted SNR misses --min-snr in it); the plans hold only the
    variants generated.
    """

    controller: Controller
    plans: dict[str, Plan]
    latency_samples: int
    controller_file: str | None = None
    headroom: dict = field(default_factory=dict)
    refused: dict[str, str] = field(default_factory=dict)

    @property
    def variants(self) -> list[str]:
        """The variants generated (keys of the generic target, in its order)."""
        return list(next(iter(self.plans.values())).predictions)

    def fixed(self, part: str):
        return self.plans[part].fixed if part in self.plans else None

    def floating(self, part: str):
        return self.plans[part].floating if part in self.plans else None

    def controller_hash(self) -> str:
        """sha256 (hex) of the controller's canonical JSON, which names it in generated files."""
        text = json.dumps(self.controller.to_dict(), sort_keys=True)
        return hashlib.sha256(text.encode("utf-8")).hexdigest()

    def provenance(self, part: str, controller_hash: str) -> dict:
        """The provenance the generated code of filter ``part`` states: the internal model's own, or,
        for Q and W, their label and the controller's hash."""
        provenance = dict(self.plans[part].provenance)
        if part != "model":
            provenance.update(path=_LABELS[part].replace(" ", "_"), hash=controller_hash)
        return provenance


def _filter_model(filt, fs: float, path: str) -> Model:
    return Model(path=path, fs=fs, A=np.asarray(filt.A, float), B=np.asarray(filt.B, float),
                 C=np.asarray(filt.C, float), D=np.asarray(filt.D, float))


def _db(value: float) -> float:
    return 20.0 * math.log10(value) if value > 0 else float("-inf")


def _l1_gain(sections) -> float:
    """sum |h[n]| of a section cascade, the impulse response simulated in lengths doubling from
    4096 samples until the sum stops changing (1e-9 relative, at most 2^22 samples).
    Clustered poles (a Laguerre controller's) decay far slower than their radius alone says,
    so a length from the slowest pole's radius, as :func:`codegen.sections.impulse_l1` takes,
    can stop short."""
    sos = np.array([list(s.b) + list(s.a) for s in sections])
    length, previous = 4096, None
    while True:
        impulse = np.zeros(length)
        impulse[0] = 1.0
        total = float(np.sum(np.abs(scipy.signal.sosfilt(sos, impulse))))
        if previous is not None and abs(total - previous) <= 1e-9 * total or length >= 2**22:
            return total
        previous, length = total, 2 * length


def _filter_headroom(plan: Plan) -> dict:
    """L1 gains of the cascade and of each partial cascade (section outputs), and the
    largest input peak (dBFS) that cannot saturate any of them."""
    sections = plan.cascade.sections
    nodes = [_l1_gain(sections[: k + 1]) for k in range(len(sections))]
    peak = max(nodes)
    return {"l1_gain": nodes[-1], "node_l1_gains": nodes, "peak_gain_linf": plan.cascade.node_gains[-1],
            "safe_input_peak_dbfs": min(0.0, -_db(peak))}


def headroom(plans: dict[str, Plan]) -> dict:
    """Worst-case headroom of the control path (module docstring): per filter and for the
    drive and the disturbance estimate with full-scale microphones."""
    result = {part: _filter_headroom(plan) for part, plan in plans.items()}
    drive = sum(result[p]["l1_gain"] for p in ("fb", "ff") if p in result)
    s_gain = result["model"]["l1_gain"]
    result["drive"] = {"worst_case_peak": drive, "margin_db": -_db(drive) if drive > 0 else float("inf"),
                       "saturates": drive > 1.0}
    estimate = 1.0 + s_gain * min(drive, 1.0)
    result["d_hat"] = {"worst_case_peak": estimate, "margin_db": -_db(estimate), "saturates": estimate > 1.0}
    return result


def plan_controller(controller, *, variant: str = "both", min_snr: float = CONTROLLER_MIN_SNR_DB,
                    quantiser: str = "efb", controller_file: str | None = None) -> ControllerPlan:
    """Plans of S_model, Q and W at the controller's rate; raises a CodegenError on refusal.

    ``controller`` is an :class:`anc.controller.Controller` or a path to its JSON. The
    controller's latency must cover the control path's processing latency (2 samples
    at the least: capture, compute, play; firmware/anc_control.h).
    """
    if not isinstance(controller, Controller):
        controller_file = str(controller)
        controller = Controller.load(controller)
    if controller.fb is None and controller.ff is None:
        raise CodegenError(f"{controller_file or 'controller'}: has neither a feedback (fb) nor a feed-forward (ff) "
                           "filter; there is nothing to run")
    if controller.latency_samples < PROCESSING_LATENCY_MIN:
        raise CodegenError(f"{controller_file or 'controller'}: latency_samples {controller.latency_samples} is below "
                           f"the board's {PROCESSING_LATENCY_MIN}-sample control path (capture, compute, play); design "
                           f"it again with --latency {PROCESSING_LATENCY_MIN}")
    plans = {}
    parts = {"model": controller.internal_model, "fb": controller.fb, "ff": controller.ff}
    for part, source in parts.items():
        if source is None:
            continue
        model = source if part == "model" else _filter_model(source, controller.fs, "fb" if part == "fb" else "ff")
        try:
            # Every variant designed whatever its SNR: a variant is refused for the controller as a whole below.
            plans[part] = plan_firmware(model, variant=variant, min_snr=-math.inf, quantiser=quantiser)
        except CodegenError as exc:
            raise type(exc)(f"{_LABELS[part]}: {exc}") from None
    refused = {}
    for key in get_target("generic").variants:
        for part, plan in plans.items():
            prediction = plan.predictions.get(key)
            if prediction is not None and prediction.snr_db < min_snr:
                refused[key] = f"{_LABELS[part]}: {refusal_reason(f'{key} variant', prediction, min_snr)}"
                break
    kept = [key for key in next(iter(plans.values())).predictions if key not in refused]
    if not kept:
        # Nothing to run: the first filter's first refused variant, as generating that filter alone says it.
        for part, plan in plans.items():
            for key, prediction in plan.predictions.items():
                if prediction.snr_db < min_snr:
                    raise PrecisionError(f"{_LABELS[part]}: {refusal_reason(f'{key} variant', prediction, min_snr)}")
    plans = {part: _keeping(plan, kept, min_snr) for part, plan in plans.items()}
    return ControllerPlan(controller=controller, plans=plans, latency_samples=int(controller.latency_samples),
                          controller_file=controller_file, headroom=headroom(plans), refused=refused)


def _keeping(plan: Plan, keys: list[str], min_snr: float) -> Plan:
    """``plan`` with only the variants ``keys`` (their designs and predictions) and the requested --min-snr."""
    spec = plan.spec
    fields = {spec.variants[key].plan_field for key in keys}
    return replace(plan, designs={f: d for f, d in plan.designs.items() if f in fields},
                   predictions={k: v for k, v in plan.predictions.items() if k in keys}, min_snr_db=float(min_snr))


def format_headroom_table(headroom_data: dict) -> str:
    """Plain-text worst-case headroom table of a controller manifest's ``headroom``."""
    lines = [f"{'signal':<22} {'L1 gain':>10} {'peak gain':>10} {'safe input':>12}",
             "-" * 57]
    for part in ("model", "fb", "ff"):
        if part not in headroom_data:
            continue
        row = headroom_data[part]
        lines.append(f"{FILTER_NAMES[part] + ' (' + _LABELS[part] + ')':<22} {row['l1_gain']:>10.4g} "
                     f"{row['peak_gain_linf']:>10.4g} {row['safe_input_peak_dbfs']:>9.1f}dBFS")
    for key, label in (("drive", "drive Q d_hat + W x"), ("d_hat", "d_hat = e - S y")):
        row = headroom_data[key]
        verdict = "saturates" if row["saturates"] else "never saturates"
        lines.append(f"{label:<22} worst-case peak {row['worst_case_peak']:.4g} of full scale with full-scale "
                     f"inputs ({row['margin_db']:+.1f} dB): {verdict}")
    return "\n".join(lines)
