"""``helmet-anc diagnose``: ranked findings naming the physical effects a model misses."""

from __future__ import annotations

import json

from sysid.core.files import atomic_write_text
from sysid.diagnose import diagnose, format_findings
from sysid.io.recordings import load_recording

from .common import add_force_option, add_recording_options, check_output, load_model, load_sweeps

ORDER = 31
DIAGNOSIS_FORMAT = "helmet-anc/diagnosis@1"


def register(commands) -> None:
    parser = commands.add_parser("diagnose", help="name the physical effects a model misses, with remedies")
    parser.add_argument("model", metavar="MODEL.json")
    add_recording_options(parser)
    parser.add_argument("--json", metavar="OUT.json", help="also write the findings as JSON")
    add_force_option(parser)
    parser.set_defaults(handler=run)


def run(args) -> int:
    target = check_output(args.json, args, "--json") if args.json else None
    model = load_model(args.model)
    noise = load_recording(args.noise, args.input_channel, args.output_channel)
    findings = diagnose(model, noise, load_sweeps(args))
    if target:
        atomic_write_text(target, json.dumps({"format": DIAGNOSIS_FORMAT, "model": args.model, "rms": findings.comparison.rms,
                                              "noise_floor": findings.comparison.noise_floor,
                                              "findings": findings.to_dicts()}, indent=2) + "\n")
    print(f"{args.model}: rms {findings.comparison.rms:.3e} FS, {findings.comparison.ratio:.2f}x the noise floor")
    print(format_findings(findings))
    if target:
        print(f"wrote {target}")
    return 0
