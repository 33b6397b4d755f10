"""``helmet-anc compare``: a model against the two repeated sweeps, band by band."""

from __future__ import annotations

import json

from sysid.core.files import atomic_write_text
from sysid.validation.compare import compare, format_comparison

from .common import add_force_option, add_recording_options, check_output, load_model, load_sweeps

ORDER = 30
COMPARISON_FORMAT = "helmet-anc/comparison@1"


def register(commands) -> None:
    parser = commands.add_parser("compare", help="compare a model with the measured sweeps (error vs noise floor)")
    parser.add_argument("model", metavar="MODEL.json")
    add_recording_options(parser, noise=False)
    parser.add_argument("--json", metavar="OUT.json", help="also write the comparison (no signals) as JSON")
    add_force_option(parser)
    parser.set_defaults(handler=run)


def run(args) -> int:
    target = check_output(args.json, args, "--json") if args.json else None
    model = load_model(args.model)
    comparison = compare(model, load_sweeps(args))
    if target:
        atomic_write_text(target, json.dumps({"format": COMPARISON_FORMAT, **comparison.to_dict()}, indent=2) + "\n")
    print(format_comparison(comparison, args.model))
    if target:
        print(f"wrote {target}")
    return 0
