"""Pieces shared by the command modules: recording options, output checks, summaries."""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from report.target import report_file
from sysid.core.errors import HelmetAncError
from sysid.core.files import check_output_file
from sysid.core.model import Model
from sysid.identify import Identification
from sysid.io.channels import check_channel_order
from sysid.io.recordings import load_recording
from sysid.validation.sweeps import check_repeats

__all__ = ["add_recording_options", "add_force_option", "load_sweeps", "check_channels", "load_model", "check_output",
           "check_report_target", "identification_summary", "parse_max_order", "order_curve_lines"]


def add_recording_options(parser: argparse.ArgumentParser, noise: bool = True) -> None:
    if noise:
        parser.add_argument("--noise", required=True, metavar="N.wav", help="white-noise recording (identification)")
    parser.add_argument("--sweep", action="append", required=True, metavar="S.wav",
                        help="swept-sine recording (validation); give it twice")
    parser.add_argument("--input-channel", type=int, default=0, help="channel of the path input (default 0)")
    parser.add_argument("--output-channel", type=int, default=1, help="channel of the ear microphone (default 1)")


def add_force_option(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--force", action="store_true",
                        help="replace an existing output file that helmet-anc did not write (never an input)")


def _inputs(args) -> list[str]:
    """Every input file named on the command line: an output must never be one of them."""
    found = []
    for key in ("model", "noise", "sweep"):
        value = getattr(args, key, None)
        found.extend(value if isinstance(value, list) else [value] if value else [])
    return found


def load_sweeps(args) -> list:
    if len(args.sweep) != 2:
        raise HelmetAncError(f"give --sweep exactly twice (the two repeated sweeps); found {len(args.sweep)}")
    sweeps = [check_channels(load_recording(p, args.input_channel, args.output_channel), args) for p in args.sweep]
    check_repeats(*sweeps)
    return sweeps


def check_channels(recording, args):
    """The recording (in memory), after refusing swapped input and ear channels (sysid.io.channels).

    Every command that reads recordings reads the two sweeps through ``load_sweeps``, so
    the sweeps are where a swapped session is caught; the message names the fix.
    """
    check_channel_order(recording.u, recording.y, recording.fs, recording.path, args.input_channel, args.output_channel)
    return recording


def load_model(path: str) -> Model:
    """The model file's model, refused when unstable (every command here simulates it)."""
    return Model.load(path).check_stable(path)


def check_output(path: str, args=None, option: str = "-o") -> Path:
    """An output file checked before any work: not a folder, not an input, ours or --force, writable folder."""
    return check_output_file(path, inputs=_inputs(args) if args is not None else (),
                             force=bool(getattr(args, "force", False)), option=option)


def check_report_target(path: str | None, args=None, kind: str = "fb", option: str = "--report") -> Path | None:
    """The --report file, checked before any work (as ``-o``): the file given, or ``<folder>/<kind>-report.html``
    for an existing folder (``report.target``: a path ending with a separator is a folder, which must exist)."""
    if path is None:
        return None
    try:
        target = report_file(path, kind)
    except HelmetAncError as exc:
        raise HelmetAncError(f"{option} {exc}") from None
    return check_output(target, args, option)


def parse_max_order(text: str | None) -> int | None:
    """--max-order N as a whole number of states of at least 1 (None when not given); a one-line error otherwise."""
    if text is None:
        return None
    try:
        value = int(text)
    except ValueError:
        value = 0
    if value < 1 or str(text).strip() not in (str(value), f"+{value}"):
        raise HelmetAncError(f"--max-order must be a whole number of states of at least 1; found {text!r}")
    return value


def _columns(curve: dict, count: int = 8) -> list[int]:
    """Indices of at most ``count`` orders of the curve, spread geometrically, the chosen one among them."""
    orders = curve["orders"]
    wanted = np.geomspace(orders[0], orders[-1], count) if len(orders) > count else orders
    picks = {int(np.argmin(np.abs(np.log(np.asarray(orders, float)) - np.log(w)))) for w in wanted}
    if curve.get("chosen") in orders:
        picks.add(orders.index(curve["chosen"]))
    return sorted(picks)


def order_curve_lines(info: dict) -> list[str]:
    """The order/error/board-cost curve of a model's provenance in a few lines, the chosen order marked (*), and
    what a cap left on the table."""
    curve = info.get("order_curve")
    if not curve or not curve.get("orders"):
        return []
    chosen = curve.get("chosen")
    picks = _columns(curve)
    hsv = curve.get("hankel_singular_values", [])
    cells = [("order", [("*" if curve["orders"][i] == chosen else "") + str(curve["orders"][i]) for i in picks]),
             ("rms / floor", [f"{curve['ratio'][i]:.3g}" for i in picks]),
             ("Hankel s(n+1)/s(1)", [f"{hsv[curve['orders'][i]]:.1e}" if curve["orders"][i] < len(hsv) else "0"
                                     for i in picks]),
             ("M4 instr. / sample", [f"{curve['q15_step'][i]:.0f}" for i in picks])]
    lines = [f"  order/error/cost : {curve['source']}; * chosen; M4: Cortex-M4 instructions per sample (Q15 step)"]
    width = max(len(v) for _, values in cells for v in values) + 1
    lines += ["    " + f"{label:<19}" + "".join(f"{v:>{width}}" for v in values) for label, values in cells]
    if chosen is not None and chosen in curve.get("refined_orders", []):
        at = curve["refined_orders"].index(chosen)
        lines.append(f"    refined at order {chosen}: {curve['refined_ratio'][at]:.3g}x the noise floor")
    capped = info.get("capped")
    if capped:
        lines.append(f"  capped at {capped['max_order']} states: {capped['ratio']:.3g}x the noise floor; "
                     f"{capped['floor_order']} states would reach {capped['floor_ratio']:.3g}x "
                     f"({capped['floor_instructions']:.0f} instructions per sample on the board)")
    return lines


def identification_summary(result: Identification) -> str:
    model = result.model
    info = model.identification
    lines = [
        f"path {model.path}: estimator {info['estimator']}, fs {model.fs:g} Hz",
        *([f"  latency          : {result.latency.samples} samples ({result.latency.centimetres:.1f} cm of sound path), "
           f"core fitted on delay-compensated data"] if result.latency is not None else []),
        f"  seed grid choice : gamma {info['seed_choice']['gamma']}, order {info['seed_choice']['order']}, "
        f"rms {result.seed_rms:.3e} FS ({result.seed_rms / result.noise_floor:.2f}x noise floor)",
    ]
    if result.refined_rms is not None and "refinement" in info:
        lines.append(f"  refined (output error on raw data): order {info['refinement']['order']} from "
                     f"{info['refinement'].get('start', 'gamma ' + str(info['refinement']['start_gamma']))}, rms {result.refined_rms:.3e} FS "
                     f"({result.refined_rms / result.noise_floor:.2f}x noise floor)")
    long = info.get("long_route")
    if long is not None:
        lines.append(f"  long route       : least-squares FIR of {long['fir_taps']} taps, the response "
                     f"{long['response_ms']:g} ms long ({long['response_taps']} taps), delay {model.delay} samples; "
                     f"order {long['order']} by {long['refinement']}")
    lines += order_curve_lines(info)
    kind = {"long route": "long route"}.get(info.get("route"), "refined" if info["refined"] else "seed grid")
    gamma = "" if info.get("route") == "long route" else f"gamma {info['gamma']}, "
    refinement = info.get("refinement", {})
    order = f"order {model.order}"
    if info["refined"] and info.get("route") != "long route" and refinement.get("order") not in (None, model.order):
        # The order search's pick, then states the data did not ask for left out (sysid.estimation.reduction).
        order += f" (reduced from {refinement['order']}: {refinement.get('reduced') or 'states left out'})"
    lines.append(f"  chosen model     : {kind}, {gamma}{order}, rms {info['rms']:.3e} FS, "
                 f"noise floor {result.noise_floor:.3e} FS, {'stable' if model.stable else 'UNSTABLE'} "
                 f"(largest pole radius {model.spectral_radius:.6f})")
    return "\n".join(lines)
