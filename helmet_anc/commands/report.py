"""``helmet-anc report``: one self-contained HTML page of a model on its recordings."""

from __future__ import annotations

from sysid.errors import HelmetAncError
from sysid.recordings import load_recording
from sysid.report.data import GRID_CHOICES
from ..progress import busy
from .common import add_force_option, add_recording_options, check_output, load_model, load_sweeps

ORDER = 60


def register(commands) -> None:
    parser = commands.add_parser("report", help="write an HTML report: identification, validation, diagnosis, tables")
    parser.add_argument("model", metavar="MODEL.json", help="model file (helmet-anc/model@1)")
    add_recording_options(parser)
    parser.add_argument("--grid", choices=GRID_CHOICES, default="modest",
                        help="recompute the (gamma, order) grid over a modest range, or skip it (default modest)")
    parser.add_argument("--dpi", type=float, default=100.0, help="resolution of the embedded figures (default 100)")
    parser.add_argument("-o", "--output", required=True, metavar="report.html")
    add_force_option(parser)
    parser.set_defaults(handler=run)


def run(args) -> int:
    output = check_output(args.output, args)
    if not 20.0 <= args.dpi <= 400.0:
        raise HelmetAncError(f"--dpi must be between 20 and 400; found {args.dpi:g}")
    model = load_model(args.model)
    noise = load_recording(args.noise, args.input_channel, args.output_channel)
    sweeps = load_sweeps(args)
    from sysid.report.html import (
        write_report,  # matplotlib loads only when a report is made
    )

    with busy("report: grid, diagnosis and figures", args.quiet):
        written = write_report(output, model, noise, sweeps, grid=args.grid, dpi=args.dpi)
    print(f"wrote {written}")
    return 0
