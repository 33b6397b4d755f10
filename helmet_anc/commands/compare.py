"""``helmet-anc compare``: a model against the two repeated sweeps, band by band."""

from __future__ import annotations

import json

from sysid.compare import compare, format_comparison
from sysid.model import Model, atomic_write_text
from .common import add_recording_options, check_output, load_sweeps

ORDER = 30


def register(commands) -> None:
    parser = commands.add_parser("compare", help="compare a model with the measured sweeps (error vs noise floor)")
    parser.add_argument("model", metavar="MODEL.json")
    add_recording_options(parser, noise=False)
    parser.add_argument("--json", metavar="OUT.json", help="also write the comparison (no signals) as JSON")
    parser.set_defaults(handler=run)


def run(args) -> int:
    target = check_output(args.json) if args.json else None
    model = Model.load(args.model)
    comparison = compare(model, load_sweeps(args))
    if target:
        atomic_write_text(target, json.dumps(comparison.to_dict(), indent=2) + "\n")
    print(format_comparison(comparison, args.model))
    if target:
        print(f"wrote {target}")
    return 0
