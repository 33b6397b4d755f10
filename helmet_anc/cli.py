"""The ``helmet-anc`` command line.

Subcommands live in ``helmet_anc.commands`` (one module each, found at start-up). Every
user error ends in one line on stderr, ``helmet-anc <command>: error: ...``, and
exit status 2; nothing is written unless the command succeeds.
"""

from __future__ import annotations

import argparse
import importlib
import pkgutil
import sys
import warnings

from sysid.core.errors import HelmetAncError
from sysid.io.recordings import RecordingWarning

from . import commands as command_package
from .effect_modules import add_effect_module_option, load_effect_modules
from .pipes import quiet_on_closed_stdout

__all__ = ["main", "build_parser"]

EXIT_USAGE = 2
# The subcommands that read effects by name (--effect, --add, the detectors): they take --effect-module.
EFFECT_COMMANDS = ("simulate", "diagnose", "refine", "report")
EXIT_INTERRUPTED = 130  # 128 + SIGINT, what a shell reports for Ctrl-C

# One example per subcommand, shown at the end of its --help.
EXAMPLES = {
    "simulate": "helmet-anc simulate session --path fb --seed 1",
    "identify": "helmet-anc identify --noise session/noise.wav --sweep session/sweep1.wav "
                "--sweep session/sweep2.wav -o fb_model.json",
    "compare": "helmet-anc compare fb_model.json --sweep session/sweep1.wav --sweep session/sweep2.wav",
    "diagnose": "helmet-anc diagnose fb_model.json --noise session/noise.wav --sweep session/sweep1.wav "
                "--sweep session/sweep2.wav",
    "refine": "helmet-anc refine fb_model.json --auto --noise session/noise.wav --sweep session/sweep1.wav "
              "--sweep session/sweep2.wav -o fb_refined.json",
    "report": "helmet-anc report fb_model.json --noise session/noise.wav --sweep session/sweep1.wav "
              "--sweep session/sweep2.wav -o fb_report.html",
    "demo": "helmet-anc demo demo_output",
    "batch": "helmet-anc batch sessions.csv -o batch_output",
    "design": "helmet-anc design --fb fb_model.json --ff ff_model.json --disturbance ride.wav -o controller.json",
    "generate-firmware": "helmet-anc generate-firmware fb_model.json -o fb_firmware",
}


def _version() -> str:
    try:
        from importlib.metadata import version

        return version("helmet-anc")
    except Exception:  # not installed (run from a source tree): the packages' own version
        from codegen import __version__

        return __version__


class _Parser(argparse.ArgumentParser):
    """An ArgumentParser whose errors are one line (no usage dump) with exit status 2."""

    def error(self, message):
        sys.stderr.write(f"{self.prog}: error: {message}\n")
        raise SystemExit(EXIT_USAGE)


def _command_modules():
    modules = []
    for info in pkgutil.iter_modules(command_package.__path__):
        module = importlib.import_module(f"{command_package.__name__}.{info.name}")
        if hasattr(module, "register"):
            modules.append(module)
    return sorted(modules, key=lambda m: (getattr(m, "ORDER", 50), m.__name__))


def build_parser() -> argparse.ArgumentParser:
    parser = _Parser(prog="helmet-anc", description="Identify, diagnose and ship helmet ANC sound-path models.",
                     epilog="example: " + EXAMPLES["identify"])
    parser.add_argument("--version", action="version", version=f"%(prog)s {_version()}")
    parser.add_argument("-q", "--quiet", action="store_true", help="no progress display on stderr")
    commands = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    for module in _command_modules():
        module.register(commands)
    for name, sub in commands.choices.items():
        if name in EXAMPLES and not sub.epilog:
            sub.epilog = "example: " + EXAMPLES[name]
        if name in EFFECT_COMMANDS:
            add_effect_module_option(sub)
    return parser


def _one_line(message) -> str:
    return f"helmet-anc: warning: {message}\n"


def main(argv=None) -> int:
    """Run ``helmet-anc`` with ``argv`` (default: the process's arguments); return the exit status."""
    return quiet_on_closed_stdout(lambda: _main(argv))


def _main(argv) -> int:
    argv = sys.argv[1:] if argv is None else list(argv)
    leading = 0
    while leading < len(argv) and argv[leading] in ("-q", "--quiet"):
        leading += 1
    global_options, rest = argv[:leading][:1], argv[leading:]
    if rest[:1] == ["generate-firmware"]:
        # Its options belong to the generate-firmware parser, --help included (design.md, "Layout").
        from .firmware_cli import main as firmware_main

        return _run_interruptible(lambda: firmware_main(rest[1:] + global_options, prog="helmet-anc generate-firmware"))
    args = build_parser().parse_args(argv)
    # Warnings about the inputs (clipping, a DC offset) come before the results they qualify: held
    # until the command first writes to stdout, then shown, then shown as they come. A bad input
    # still reads as its one error line, not as warnings about the same file followed by the error.
    held = _HeldWarnings()
    previous, stdout = warnings.showwarning, sys.stdout
    warnings.showwarning = lambda message, *rest, **named: held.add(_one_line(message))
    sys.stdout = _ReleasingStream(stdout, held.release)
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("always", RecordingWarning)
            load_effect_modules(getattr(args, "effect_module", None) or [])
            status = args.handler(args)
    except HelmetAncError as exc:
        sys.stderr.write(f"helmet-anc {args.command}: error: {exc}\n")
        return EXIT_USAGE
    except KeyboardInterrupt:
        sys.stderr.write(f"helmet-anc {args.command}: interrupted; no partial output left\n")
        return EXIT_INTERRUPTED
    finally:
        warnings.showwarning = previous
        sys.stdout = stdout
    held.release()
    return status


class _HeldWarnings:
    """Warning lines held until ``release`` (the command's first output), then written as they come."""

    def __init__(self):
        self.lines: list[str] = []
        self.released = False

    def add(self, line: str) -> None:
        if self.released:
            sys.stderr.write(line)
        else:
            self.lines.append(line)

    def release(self) -> None:
        if not self.released:
            self.released = True
            sys.stderr.write("".join(self.lines))
            sys.stderr.flush()


class _ReleasingStream:
    """A text stream that calls ``before_first_write`` once, before its first write, then writes through."""

    def __init__(self, stream, before_first_write):
        self._stream = stream
        self._before = before_first_write

    def write(self, text):
        if text:
            self._before()
        return self._stream.write(text)

    def __getattr__(self, name):
        return getattr(self._stream, name)


def _run_interruptible(run) -> int:
    try:
        return run()
    except KeyboardInterrupt:
        sys.stderr.write("helmet-anc: interrupted; no partial output left\n")
        return EXIT_INTERRUPTED


if __name__ == "__main__":
    sys.exit(main())
