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

from . import commands as command_package
from sysid.errors import HelmetAncError
from sysid.recordings import RecordingWarning

__all__ = ["main", "build_parser"]

EXIT_USAGE = 2


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
    parser = _Parser(prog="helmet-anc", description="Identify, diagnose and ship helmet ANC sound-path models.")
    commands = parser.add_subparsers(dest="command", required=True, parser_class=_Parser)
    for module in _command_modules():
        module.register(commands)
    return parser


def _one_line_warning(message, category, filename, lineno, file=None, line=None):
    (file or sys.stderr).write(f"helmet-anc: warning: {message}\n")


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    previous = warnings.showwarning
    warnings.showwarning = _one_line_warning
    try:
        with warnings.catch_warnings():
            warnings.simplefilter("always", RecordingWarning)
            return args.handler(args)
    except HelmetAncError as exc:
        sys.stderr.write(f"helmet-anc {args.command}: error: {exc}\n")
        return EXIT_USAGE
    except KeyboardInterrupt:
        sys.stderr.write("helmet-anc: interrupted\n")
        return 130
    finally:
        warnings.showwarning = previous


if __name__ == "__main__":
    sys.exit(main())
