"""``helmet-anc identify``: a stable model of one path from a noise recording and two sweeps."""

from __future__ import annotations

from sysid.core.files import atomic_write_text
from sysid.estimation.grid import parse_range, terminal_progress
from sysid.estimation.spectra import ESTIMATORS
from sysid.identify import IdentificationOptions, identify
from sysid.io.recordings import open_recording

from .common import (add_force_option, add_recording_options, check_output, check_report_target, identification_summary,
                     load_sweeps, parse_max_order)

ORDER = 20


def register(commands) -> None:
    parser = commands.add_parser("identify", help="identify a model from a noise recording and two sweeps")
    add_recording_options(parser)
    parser.add_argument("--path", choices=("fb", "ff"), default="fb")
    parser.add_argument("--estimator", choices=ESTIMATORS, default="h1")
    parser.add_argument("--gammas", default="10:1000:10", metavar="A:B:STEP", help="smoothing widths (default 10:1000:10)")
    parser.add_argument("--orders", default="1:20", metavar="A:B", help="model orders (default 1:20)")
    parser.add_argument("--max-order", metavar="N",
                        help="at most N states (what the board can afford); default: the lowest order at the noise floor")
    parser.add_argument("--no-refine", action="store_true", help="stop at the seed's grid choice")
    parser.add_argument("--feedthrough", action="store_true", help="estimate a direct term D (default D = 0)")
    parser.add_argument("--mat", metavar="FILE.mat", help="also export the model for MATLAB")
    parser.add_argument("--report", metavar="PATH", help="also write the HTML report (a file, or a folder for <path>-report.html)")
    parser.add_argument("-o", "--output", required=True, metavar="model.json")
    add_force_option(parser)
    parser.set_defaults(handler=run)


def run(args) -> int:
    output = check_output(args.output, args)
    table = check_output(output.with_name(output.stem + ".grid.csv"), args, "-o (grid table)")
    mat = check_output(args.mat, args, "--mat") if args.mat else None
    report_target = check_report_target(args.report, args, args.path)
    options = IdentificationOptions(estimator=args.estimator, gammas=parse_range(args.gammas, "--gammas", True),
                                    orders=parse_range(args.orders, "--orders", False), refine=not args.no_refine,
                                    feedthrough=args.feedthrough, max_order=parse_max_order(args.max_order))
    # Read in blocks: a noise recording of any length is identified in bounded memory.
    noise = open_recording(args.noise, args.input_channel, args.output_channel)
    sweeps = load_sweeps(args)
    result = identify(noise, sweeps, args.path, options, progress=None if args.quiet else terminal_progress())
    result.model.save(output)
    atomic_write_text(table, result.grid.to_csv())
    if mat:
        result.model.save_mat(mat)
    if report_target:
        from report import write_report

        # The report diagnoses the whole noise recording, in memory.
        report = write_report(report_target, result.model, noise.load(), sweeps, identification=result)
        print(f"wrote {report}")
    print(identification_summary(result))
    print(f"wrote {output} and {table}" + (f" and {mat}" if mat else ""))
    return 0
