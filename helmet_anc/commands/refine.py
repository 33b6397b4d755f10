"""``helmet-anc refine``: add a named effect's structure (or let ``--auto`` choose) and re-identify."""

from __future__ import annotations

import sys

from sysid.core.errors import HelmetAncError
from sysid.core.model import Model
from sysid.io.recordings import load_recording
from sysid.refine import REFINE_EFFECTS, format_refinement, parse_refinement, refine, refine_auto

from ..progress import busy
from .common import add_force_option, add_recording_options, check_output, check_report_target, load_sweeps, parse_max_order

ORDER = 32


def register(commands) -> None:
    parser = commands.add_parser("refine", help="add an effect to a model and re-identify; --auto follows diagnose")
    parser.add_argument("model", metavar="MODEL.json")
    add_recording_options(parser)
    parser.add_argument("--add", action="append", default=[], metavar="EFFECT[:PARAMS]",
                        help="structure to add, repeatable: " + ", ".join(REFINE_EFFECTS) + " (e.g. delay:23)")
    parser.add_argument("--auto", action="store_true", help="diagnose, add the top finding, refit, until done")
    parser.add_argument("--max-order", metavar="N",
                        help="state cap: the refined model holds at most N states (default: the model's own cap)")
    parser.add_argument("--report", metavar="PATH", help="also write the HTML report of the refined model (file or folder)")
    parser.add_argument("-o", "--output", required=True, metavar="NEW.json")
    add_force_option(parser)
    parser.set_defaults(handler=run)


def run(args) -> int:
    if bool(args.add) == bool(args.auto):
        raise HelmetAncError("give --add EFFECT[:PARAMS] (repeatable) or --auto, not both")
    max_order = parse_max_order(args.max_order)
    specs = [parse_refinement(text) for text in args.add]
    output = check_output(args.output, args)
    model = Model.load(args.model)
    report_target = check_report_target(args.report, args, model.path)
    noise = load_recording(args.noise, args.input_channel, args.output_channel)
    sweeps = load_sweeps(args)
    stop_reason = None
    if args.auto:
        # One line per step when stderr is a pipe; the spinner names the step on a terminal.
        with busy("refine --auto", args.quiet) as step:
            auto = refine_auto(model, noise, sweeps, progress=step, max_order=max_order)
        model, steps, stop_reason = auto.model, auto.steps, auto.stop_reason
    else:
        steps = []
        for spec in specs:
            with busy("refine", args.quiet) as step:
                result = refine(model, noise, sweeps, spec, max_order=max_order, progress=step)
            steps.append(result.step)
            model = result.model
            if result.step.worse:
                sys.stderr.write(f"helmet-anc refine: warning: adding {spec.kind} raised the validation rms from "
                                 f"{result.step.rms_before:.3e} to {result.step.rms_after:.3e} FS\n")
    model.save(output)
    print(format_refinement(steps, stop_reason))
    print(f"wrote {output}")
    if report_target:
        from report import write_report

        print(f"wrote {write_report(report_target, model, noise, sweeps)}")
    return 0

