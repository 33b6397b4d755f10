"""``helmet-anc diagnose``: ranked findings naming the physical effects a model misses."""

from __future__ import annotations

import json

from sysid.diagnose import diagnose, format_findings
from sysid.model import Model, atomic_write_text
from sysid.recordings import load_recording
from .common import add_recording_options, check_output, load_sweeps

ORDER = 31


def register(commands) -> None:
    parser = commands.add_parser("diagnose", help="name the physical effects a model misses, with remedies")
    parser.add_argument("model", metavar="MODEL.json")
    add_recording_options(parser)
    parser.add_argument("--json", metavar="OUT.json", help="also write the findings as JSON")
    parser.set_defaults(handler=run)


def run(args) -> int:
    target = check_output(args.json) if args.json else None
    model = Model.load(args.model)
    noise = load_recording(args.noise, args.input_channel, args.output_channel)
    findings = diagnose(model, noise, load_sweeps(args))
    if target:
        atomic_write_text(target, json.dumps({"model": args.model, "rms": findings.comparison.rms,
                                              "noise_floor": findings.comparison.noise_floor,
                                              "findings": list(findings)}, indent=2) + "\n")
    print(f"{args.model}: rms {findings.comparison.rms:.3e} FS, {findings.comparison.ratio:.2f}x the noise floor")
    print(format_findings(findings))
    if target:
        print(f"wrote {target}")
    return 0
