"""``helmet-anc design``: feed-forward and feedback controllers from the models, with predictions."""

from __future__ import annotations

from pathlib import Path

from sysid.core.errors import HelmetAncError
from sysid.core.files import atomic_write_text, check_output_file
from sysid.core.model import Model
from sysid.io.recordings import load_recording

from .common import add_force_option

ORDER = 60


def register(commands) -> None:
    parser = commands.add_parser("design", help="design the ANC controller (feed-forward W, feedback Q) from the models")
    parser.add_argument("--fb", required=True, metavar="FB.json", help="feedback-path model (drive -> ear)")
    parser.add_argument("--ff", metavar="FF.json", help="feed-forward-path model (chin -> ear); gives a W")
    parser.add_argument("--disturbance", metavar="REC.wav",
                        help="recording with ANC off (channel 0 chin, 1 ear); default: a wind-and-engine spectrum")
    parser.add_argument("--latency", type=int, default=1, metavar="L",
                        help="samples from measurement to drive on the board (default 1: per-sample control path)")
    parser.add_argument("--report", metavar="FILE.html", help="also write the control page (figures, margins)")
    parser.add_argument("-o", "--output", required=True, metavar="controller.json")
    add_force_option(parser)
    parser.set_defaults(handler=run)


def _table(controller) -> str:
    lines = ["band (Hz)   ff (dB)   fb (dB)  both (dB)" + ("  coherence bound (dB)" if controller.coherence_bound_db else "")]
    for i, centre in enumerate(controller.bands_hz):
        p = controller.predicted_attenuation_db
        line = f"{centre:9.0f} {p['ff'][i]:9.1f} {p['fb'][i]:9.1f} {p['both'][i]:10.1f}"
        if controller.coherence_bound_db:
            line += f" {controller.coherence_bound_db[i]:21.1f}"
        lines.append(line)
    overall = controller.predicted_overall_dba
    lines.append("overall dB(A): " + ", ".join(f"{k} {v:.1f}" for k, v in overall.items()))
    m = controller.margins
    if m:
        gm = "inf" if m["gain_margin_db"] is None else f"{m['gain_margin_db']:.1f} dB"
        lines.append(f"feedback: gain margin {gm}, phase margin {m['phase_margin_deg']:.0f} deg, peak amplification "
                     f"{m['peak_amplification_db']:.1f} dB at {m['peak_amplification_hz']:.0f} Hz, "
                     f"robustness factor {m['robustness_factor']:.2f}")
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
    if args.latency < 1:
        raise HelmetAncError(f"--latency must be a whole number of samples >= 1; found {args.latency}")
    fb = Model.load(args.fb)
    ff = Model.load(args.ff) if args.ff else None
    if args.disturbance:
        disturbance = from_recording(load_recording(args.disturbance), fb.fs)
    else:
        disturbance = default_disturbance(fb.fs, ff)
    provenance = {"fb_model": str(args.fb), "ff_model": args.ff, "disturbance_file": args.disturbance}
    controller = design(fb, ff, disturbance, DesignOptions(latency=args.latency), provenance=provenance)
    controller.save(output)
    if report is not None:
        from report.control_figures import control_page

        atomic_write_text(report, control_page(controller))
        print(f"wrote {report}")
    print(_table(controller))
    print(f"wrote {output}")
    return 0
