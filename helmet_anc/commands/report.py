"""``helmet-anc report``: one self-contained HTML page of a model on its recordings."""

from __future__ import annotations

from report.data import GRID_CHOICES
from sysid.core.errors import HelmetAncError
from sysid.io.recordings import load_recording

from ..progress import busy
from .common import add_force_option, add_recording_options, check_report_target, load_model, load_sweeps

ORDER = 60


def register(commands) -> None:
    parser = commands.add_parser("report", help="write an HTML report: identification, validation, diagnosis, tables")
    parser.add_argument("model", metavar="MODEL.json", help="model file (helmet-anc/model@1)")
    add_recording_options(parser)
    parser.add_argument("--grid", choices=GRID_CHOICES, default="modest",
                        help="recompute the (gamma, order) grid over a modest range, or skip it (default modest)")
    parser.add_argument("--dpi", type=float, default=100.0, help="resolution of the embedded figures (default 100)")
    parser.add_argument("--controller", metavar="controller.json",
                        help="add a control section for this controller (helmet-anc design): attenuation predicted on "
                             "its model vs achieved on this report's model, sensitivity, Nyquist, refinement table")
    parser.add_argument("-o", "--output", required=True, metavar="report.html",
                        help="the report file, or a folder (existing, or written with a trailing /) for <fb|ff>-report.html")
    add_force_option(parser)
    parser.set_defaults(handler=run)


def control_section(path: str, model, dpi: float) -> tuple[str, str, str]:
    """("control", heading, HTML) for --controller: the controller's predictions on its internal model
    against the closed loop run sample by sample on this report's model (for an FB model: Q on it;
    for an FF model: W and Q with it as the reference path and the internal model as S), beside the limits
    the controller records. Nothing is designed here: a design takes minutes, and the section shows the
    controller as it was designed."""
    from anc import Controller
    from anc.closed_loop import predicted_and_achieved
    from report.control_figures import control_section as section_html

    controller = Controller.load(path)
    if controller.fs != model.fs:
        raise HelmetAncError(f"--controller {path}: designed at {controller.fs:g} Hz, the model is at {model.fs:g} Hz; "
                             "give the controller designed for this helmet")
    s_true, p_true = (model, None) if model.path == "fb" else (controller.internal_model, model)
    predicted, achieved = predicted_and_achieved(controller, s_true, p_true)
    controller.predicted_attenuation_db.update(predicted)
    note = ("Predicted: on the controller's internal model with the default wind-and-engine spectrum"
            + (" and this FF model as the reference path" if p_true is not None else " (no reference: feedback only)")
            + "; achieved: the same controller run sample by sample (float64, its latency) on "
            + ("this report's FB model." if p_true is None else "its internal FB model with this report's FF model."))
    return "control", "6. Control", section_html(controller, achieved, None, dpi, note)


def run(args) -> int:
    if not 20.0 <= args.dpi <= 400.0:
        raise HelmetAncError(f"--dpi must be between 20 and 400; found {args.dpi:g}")
    model = load_model(args.model)
    # A folder (existing, or named with a trailing separator) gets <fb|ff>-report.html (report.target).
    output = check_report_target(args.output, args, model.path, "-o")
    noise = load_recording(args.noise, args.input_channel, args.output_channel)
    sweeps = load_sweeps(args)
    from report.html import write_report

    with busy("report: grid, diagnosis and figures", args.quiet):
        extra = [control_section(args.controller, model, args.dpi)] if args.controller else []
        written = write_report(output, model, noise, sweeps, grid=args.grid, dpi=args.dpi, extra_sections=extra)
    print(f"wrote {written}")
    return 0
