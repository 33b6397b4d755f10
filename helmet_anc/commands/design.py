"""``helmet-anc design``: feed-forward and feedback controllers from the models, with predictions and limits.

Prints per third-octave band the predicted attenuation of W alone, Q alone and both beside the limits
the paths allow (causal feed-forward, coherence, robust feedback; positive = quieter at the ear) and
what limits each band, then the loop's margins ("no crossover" where the loop gain never reaches 1).
"""

from __future__ import annotations

import argparse
import math
import re
from pathlib import Path

from anc.controller import BOARD_LATENCY_SAMPLES
from anc.limits import AMPLIFICATION_RANGE_DB, MAX_AMPLIFICATION_DB
from sysid.core.errors import HelmetAncError
from sysid.core.files import atomic_write_text, check_output_file
from sysid.core.model import Model
from sysid.io.recordings import load_recording

from .common import add_force_option, parse_max_order

# Width of one part of the reason column (characters); longer causes are cut at a word (in full below the table).
REASON_WIDTH = 40


def _latency(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"must be a whole number of samples; found {text!r}") from None
    if value < 1:
        raise argparse.ArgumentTypeError(f"must be a whole number of samples >= 1; found {value}")
    return value


def _amplification(text: str) -> float:
    low, high = AMPLIFICATION_RANGE_DB
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not low < value <= high:
        raise argparse.ArgumentTypeError(f"must be a number of dB above {low:g} and at most {high:g}; found {text!r}")
    return value


def register(commands) -> None:
    parser = commands.add_parser("design", help="design the ANC controller (feed-forward W, feedback Q) from the models")
    parser.add_argument("--fb", required=True, metavar="FB.json", help="feedback-path model (drive -> ear)")
    parser.add_argument("--ff", metavar="FF.json", help="feed-forward-path model (chin -> ear); gives a W")
    parser.add_argument("--disturbance", metavar="REC.wav",
                        help="recording with ANC off (channel 0 chin, 1 ear): the noise the design minimises; "
                             "default: a wind-and-engine spectrum (anc.disturbance.default_spectrum)")
    parser.add_argument("--latency", type=_latency, default=BOARD_LATENCY_SAMPLES, metavar="L",
                        help=f"samples from measurement to drive (default {BOARD_LATENCY_SAMPLES}: the board's "
                             "control path; generate-firmware refuses less)")
    parser.add_argument("--max-order", metavar="N",
                        help="largest order (states) of Q and of W; default: the orders the design needs, cut to "
                             "what the board's 1750 cycles per sample afford")
    parser.add_argument("--max-amplification", type=_amplification, default=MAX_AMPLIFICATION_DB, metavar="DB",
                        help=f"no band louder than with ANC off by more than this, with Q, W or both (default "
                             f"{MAX_AMPLIFICATION_DB:g} dB; the feedback's waterbed and W's trades are held to it)")
    parser.add_argument("--ignore-drive-limit", action="store_true",
                        help="keep Q and W at full scale even where the drive's peaks exceed the FB model's drive "
                             "limit (its input nonlinearity's harmonics at -20 dB); by default they are scaled to it")
    parser.add_argument("--report", metavar="FILE.html", help="also write the control page (figures, margins)")
    parser.add_argument("-o", "--output", required=True, metavar="controller.json")
    add_force_option(parser)
    parser.set_defaults(handler=run)


def _db(value) -> str:
    return "     -" if value is None or not math.isfinite(float(value)) else f"{float(value):6.1f}"


# Compact forms of the limits' causes for the table (``anc.limits``, ``anc.design``); in full below it.
_COMPACT = ((re.compile(r"^coherence"), lambda m: "coherence"),
            (re.compile(r"chin path is faster than the drive path by (\d+) samples?"),
             lambda m: f"chin path {m.group(1)} samples ahead"),
            (re.compile(r"zero of S outside the unit circle at z = ([0-9.]+)"), lambda m: f"zero of S at z = {m.group(1)}"),
            (re.compile(r"zero of S outside the unit circle at ([0-9.]+) Hz"), lambda m: f"zero of S at {m.group(1)} Hz"),
            (re.compile(r"drive path (\d+) dB below"), lambda m: f"drive path -{m.group(1)} dB"),
            (re.compile(r"^the model's uncertainty"), lambda m: "the model's uncertainty"),
            (re.compile(r"^within the design's rules"), lambda m: "the design's rules"))
# A reason's bound within the design's rules (``anc.limits.RULES_CLAUSE``), whose per-band figure is in the table.
_RULES = "within the design's rules"
# The feedback bound's reasons start with the band and its bound ("501.187 Hz: 5.8 dB, limited by ..."), which the
# table's row already shows.
_PREFIX = re.compile(r"^[0-9.]+ Hz: -?[0-9.]+ dB, limited by ")


def _short(text: str) -> str:
    """A reason in compact form: a known cause's short name, else its words before any parenthesis,
    cut to ``REASON_WIDTH`` characters at a word."""
    text = _PREFIX.sub("", text)
    for pattern, short in _COMPACT:
        found = pattern.search(text)
        if found:
            return short(found)
    text = text.split(" (")[0]
    return text if len(text) <= REASON_WIDTH else text[:REASON_WIDTH - 3].rsplit(" ", 1)[0] + "..."


def _reason(controller, i: int) -> str:
    """The band's limiting reasons, compact: 'ff: ...; fb: ...' (parts without a named cause left out)."""
    reasons = (controller.limits or {}).get("reasons", {})
    return "; ".join(f"{name}: {_short(reasons[name][i])}" for name in ("ff", "fb")
                     if reasons.get(name) and reasons[name][i])


def reason_lines(controller) -> list[str]:
    """The limiting reasons in full, each once, with the bands it holds in (consecutive bands as a range)."""
    reasons = (controller.limits or {}).get("reasons", {})
    lines = []
    for name, label in (("ff", "feed-forward"), ("fb", "feedback")):
        runs: list[list] = []
        for centre, text in zip(controller.bands_hz, reasons.get(name) or []):
            # One line per cause: the band's own figures (its bound, the gain without the cause) are in the table.
            main, _, ruled = _PREFIX.sub("", text).partition(_RULES)
            ruled = f"the bound is lower {_RULES} ({ruled.split(' (', 1)[1]}" if ruled else ""
            text = "; ".join(part for part in (main.rstrip("; ").split(" (without")[0], ruled) if part)
            if runs and runs[-1][2] == text:
                runs[-1][1] = centre
            else:
                runs.append([centre, centre, text])
        for lo, hi, text in runs:
            if text:
                where = f"{lo:.0f} Hz" if lo == hi else f"{lo:.0f}-{hi:.0f} Hz"
                lines.append(f"{label} limit, {where}: {text}")
    return lines


def margin_lines(margins: dict) -> list[str]:
    """The feedback loop's margins in words; no phase margin where the loop gain never crosses 1."""
    if not margins:
        return []
    gm = "none (the loop never crosses the negative real axis)" if margins.get("gain_margin_db") is None \
        else f"{margins['gain_margin_db']:.1f} dB"
    pm = "no crossover (loop gain below 1 at every frequency)" if margins.get("phase_margin_deg") is None \
        else f"{margins['phase_margin_deg']:.0f} deg"
    return [f"feedback: gain margin {gm}; phase margin {pm}; peak amplification "
            f"{margins['peak_amplification_db']:.1f} dB at {margins['peak_amplification_hz']:.0f} Hz; "
            f"robustness factor {margins['robustness_factor']:.2f} (>= 1: stable for every path in the model's "
            "95 % band)"]


def table(controller) -> str:
    """The per-band table, the overall figures, the margins and the notes, as printed."""
    limits = controller.limits or {}
    n = len(controller.bands_hz)
    causal = limits.get("causal_ff_db", [None] * n)
    ruled = limits.get("causal_ff_ruled_db") or [None] * n
    coherence = limits.get("coherence_db") or controller.coherence_bound_db or [None] * n
    feedback = limits.get("feedback_db", [None] * n)
    lines = [f"attenuation at the ear per third-octave band, dB (positive = quieter at the ear); latency "
             f"{controller.latency_samples} samples",
             "                predicted              limits",
             "band (Hz)    ff     fb   both    causal ff  in rules  coherence  feedback   what limits it"]
    p = controller.predicted_attenuation_db
    for i, centre in enumerate(controller.bands_hz):
        lines.append(f"{centre:9.0f} {_db(p['ff'][i])} {_db(p['fb'][i])} {_db(p['both'][i])}    "
                     f"{_db(causal[i]):>9} {_db(ruled[i]):>9} {_db(coherence[i]):>10} {_db(feedback[i]):>9}   "
                     f"{_reason(controller, i)}")
    lines += reason_lines(controller)
    overall = controller.predicted_overall_dba
    if overall:
        lines.append("overall dB(A): " + ", ".join(f"{k} {v:.1f}" for k, v in overall.items()))
    lines += margin_lines(controller.margins)
    orders = controller.provenance.get("truncation", {})
    if orders:
        lines.append("orders: " + ", ".join(f"{'W' if k == 'ff' else 'Q'} {v['order']} (of {v['full_order']})"
                                            for k, v in orders.items() if "order" in v))
    lines += [f"note: {n}" for n in controller.notes]
    return "\n".join(lines)


def run(args) -> int:
    from anc import DesignOptions, design
    from anc.disturbance import default_disturbance, from_recording

    inputs = [p for p in (args.fb, args.ff, args.disturbance) if p]
    output = check_output_file(args.output, inputs=inputs, force=args.force, option="-o")
    report = check_output_file(args.report, inputs=inputs, force=args.force, option="--report") if args.report else None
    if report is not None and report.resolve() == Path(args.output).resolve():
        raise HelmetAncError("--report and -o name the same file; give two names")
    fb = Model.load(args.fb)
    ff = Model.load(args.ff) if args.ff else None
    if args.disturbance:
        disturbance = from_recording(load_recording(args.disturbance), fb.fs, ff_model=ff)
    else:
        disturbance = default_disturbance(fb.fs, ff)
    provenance = {"fb_model": str(args.fb), "ff_model": args.ff, "disturbance_file": args.disturbance}
    options = DesignOptions(latency=args.latency, max_order=parse_max_order(args.max_order),
                            drive_limit=not args.ignore_drive_limit, max_amplification_db=args.max_amplification)
    controller = design(fb, ff, disturbance, options, provenance=provenance)
    controller.save(output)
    if report is not None:
        from report.control_figures import control_page

        atomic_write_text(report, control_page(controller))
        print(f"wrote {report}")
    print(table(controller))
    print(f"wrote {output}")
    return 0
