"""``helmet-anc generate-firmware``: the same as the ``generate-firmware`` console script."""

from __future__ import annotations

import argparse

ORDER = 80


def register(commands) -> None:
    parser = commands.add_parser("generate-firmware", help="generate C filters for a model (see generate-firmware -h)",
                                 add_help=False)
    parser.add_argument("args", nargs=argparse.REMAINDER)
    parser.set_defaults(handler=run)


def run(args) -> int:
    # The front end is the one place that reaches both packages (design.md, "Layout").
    from ..firmware_cli import main as firmware_main

    return firmware_main(args.args)
