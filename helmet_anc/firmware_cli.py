"""Command line ``generate-firmware MODEL -o DIR``: model JSON -> verified C filter code.

Exit status 0 on success, 2 on bad input or a refusal (one-line message on
stderr, no traceback). ``build_parser``/``main`` are also what ``helmet-anc
generate-firmware`` runs.
"""

from __future__ import annotations

import argparse
import sys

from codegen import __version__
from codegen.api import format_verification_table, generate_firmware
from codegen.errors import CodegenError
from codegen.plan import TARGETS, VARIANTS
from sysid.estimation.grid import terminal_progress

from .pipes import quiet_on_closed_stdout

__all__ = ["build_parser", "main"]


class _Parser(argparse.ArgumentParser):
    """argparse whose usage errors are one line and exit status 2."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message}\n")


EXAMPLE = "example: generate-firmware fb_model.json -o fb_firmware --verify --sweep sweep1.wav --sweep sweep2.wav"


def build_parser(prog: str = "generate-firmware") -> argparse.ArgumentParser:
    parser = _Parser(prog=prog, description="Generate C filter code (float32 and Q15) for the ANC board from a "
                                            "helmet-anc model, and verify it against the Python references.",
                     epilog=EXAMPLE.replace("generate-firmware", prog, 1))
    parser.add_argument("model", nargs="?", help="model JSON file (format helmet-anc/model@1)")
    parser.add_argument("--controller", metavar="JSON",
                        help="instead of a model: a controller JSON (helmet-anc design) -> C of its internal model, "
                             "Q and W for the board's control path (firmware/anc_control.h)")
    parser.add_argument("-o", "--output", required=True, metavar="DIR",
                        help="output folder: a new one, or one holding only a previous generate-firmware output")
    parser.add_argument("--force", action="store_true",
                        help="write into a folder holding other files (only files a previous manifest lists are removed)")
    parser.add_argument("--name", help="C prefix of the generated symbols (default: the model's path, fb or ff)")
    parser.add_argument("--variant", choices=VARIANTS, default="both", help="float32, Q15 or both (default both)")
    parser.add_argument("--fs", type=float, help="board sample rate in Hz (default: the model's, 44.1 kHz)")
    parser.add_argument("--target", choices=TARGETS, default="generic",
                        help="generic C, or coefficient tables for CMSIS-DSP's biquad functions")
    parser.add_argument("--min-snr", type=float, default=80.0, metavar="DB",
                        help="refuse a variant whose predicted SNR (full-scale output sine) is below this "
                             "(default 80; 30 with --controller, whose filters are judged in the closed loop)")
    parser.add_argument("--allow-unstable", action="store_true", help="generate code even for an unstable model")
    parser.add_argument("--order", type=int, help="balanced truncation to this many states")
    parser.add_argument("--scaling", choices=("linf", "l1"), default="linf", help="section scaling norm (default linf)")
    parser.add_argument("--headroom", type=float, default=6.0, metavar="DB", help="scaling headroom in dB (default 6)")
    parser.add_argument("--quantiser", choices=("efb", "round"), default="efb",
                        help="Q31 quantiser: first-order error feedback (default) or rounding")
    parser.add_argument("--verify", action="store_true", help="build on the host and run the sweeps through the C code")
    parser.add_argument("--sweep", action="append", default=[], metavar="WAV",
                        help="sweep recording for --verify (give it twice for the two sweeps)")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress display on stderr")
    parser.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    return parser


def main(argv=None, prog: str = "generate-firmware") -> int:
    """Run the command with ``argv`` (default: the process's arguments); return the exit status."""
    return quiet_on_closed_stdout(lambda: _main(argv, prog))


def _main(argv, prog: str) -> int:
    parser = build_parser(prog)
    args = parser.parse_args(argv)
    if args.verify and not args.sweep:
        print(f"{parser.prog}: error: --verify needs at least one --sweep WAV", file=sys.stderr)
        return 2
    if args.sweep and not args.verify:
        print(f"{parser.prog}: error: --sweep is only used with --verify", file=sys.stderr)
        return 2
    if (args.model is None) == (args.controller is None):
        print(f"{parser.prog}: error: give a model JSON or --controller JSON (exactly one)", file=sys.stderr)
        return 2
    if args.controller is not None:
        return _controller(parser, args, argv)
    manifest = _generate(parser, lambda: generate_firmware(
        args.model, args.output, name=args.name, variant=args.variant, fs=args.fs, target=args.target,
        min_snr=args.min_snr, allow_unstable=args.allow_unstable, sweeps=args.sweep if args.verify else None,
        order=args.order, scaling=args.scaling, headroom_db=args.headroom, quantiser=args.quantiser,
        force=args.force, progress=None if args.quiet else terminal_progress()))
    if isinstance(manifest, int):
        return manifest
    print(format_verification_table(manifest))
    return 0


def _generate(parser, run):
    """``run()``'s manifest, after saying what it wrote; or the exit status of its one-line error."""
    try:
        manifest = run()
    except KeyboardInterrupt:
        # Every file is written by rename (sysid.core.files): an interrupt leaves no partial output.
        print(f"{parser.prog}: interrupted; no partial output left", file=sys.stderr)
        return 130
    except (CodegenError, ValueError) as exc:
        message = str(exc).strip().splitlines()[0] if str(exc).strip() else type(exc).__name__
        print(f"{parser.prog}: error: {message}", file=sys.stderr)
        return 2
    print(f"wrote {', '.join(str(p) for p in manifest.files)} and {manifest.outdir / 'manifest.json'}")
    return manifest


def _controller(parser, args, argv) -> int:
    """``--controller``: the control path's filters and their worst-case headroom table."""
    from codegen.api import generate_controller_firmware
    from codegen.controller import CONTROLLER_MIN_SNR_DB, format_headroom_table

    # --min-snr given on the command line applies; its model default (80) does not.
    given = argparse.ArgumentParser(add_help=False)
    given.add_argument("--min-snr", type=float)
    min_snr = given.parse_known_args(argv)[0].min_snr

    unused = [flag for flag, value in (("--name", args.name), ("--fs", args.fs), ("--order", args.order),
                                       ("--verify", args.verify), ("--allow-unstable", args.allow_unstable))
              if value] + (["--target"] if args.target != "generic" else [])
    if unused:
        print(f"{parser.prog}: error: {', '.join(unused)} not used with --controller (the filters run at the "
              "controller's rate under fixed names)", file=sys.stderr)
        return 2
    manifest = _generate(parser, lambda: generate_controller_firmware(
        args.controller, args.output, variant=args.variant,
        min_snr=CONTROLLER_MIN_SNR_DB if min_snr is None else min_snr,
        quantiser=args.quantiser, force=args.force, progress=None if args.quiet else terminal_progress()))
    if isinstance(manifest, int):
        return manifest
    for key, reason in manifest.data["refused"].items():
        # One line per variant left out; the variants that meet --min-snr were written.
        print(f"{parser.prog}: note: {key} variant not generated ({', '.join(manifest.data['variants'])} written): "
              f"{reason}", file=sys.stderr)
    print(f"worst-case headroom (latency {manifest.data['controller']['latency_samples']} samples):")
    print(format_headroom_table(manifest.data["headroom"]))
    return 0


if __name__ == "__main__":
    sys.exit(main())
