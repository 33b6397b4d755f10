"""A user's own effect modules, loaded from the command line: ``--effect-module path/to/notch_effect.py``.

An effect of one's own is one module that builds an ``Effect`` and calls ``sysid.effects.register``
(README, "Your own effect"). From Python it is registered by importing it; ``simulate``,
``diagnose``, ``refine`` and ``report`` load it with ``--effect-module FILE`` (repeatable) before
they run, so ``--effect notch:1200,4`` and ``--add notch:...`` find it. A module that is
missing, does not load, or registers no effect is refused with one line naming the file, the
error and its line.
"""

from __future__ import annotations

import importlib.util
import sys
from pathlib import Path

from sysid.core.errors import HelmetAncError
from sysid.effects import registry

__all__ = ["add_effect_module_option", "load_effect_modules"]


def add_effect_module_option(parser) -> None:
    parser.add_argument("--effect-module", action="append", default=[], metavar="FILE.py",
                        help="load an effect of your own (a module that calls sysid.effects.register) before running; "
                             "repeatable")


def load_effect_modules(paths) -> list[str]:
    """Load each module file of ``paths``; return the names of the effects they registered (or replaced)."""
    found = []
    for path in paths:
        found.extend(_load(Path(path)))
    return found


def _load(path: Path) -> list[str]:
    option = f"--effect-module {path}"
    if path.is_dir():
        raise HelmetAncError(f"{option}: is a folder; give the effect's Python file")
    if not path.is_file():
        raise HelmetAncError(f"{option}: no such file")
    name = path.stem
    if not name.isidentifier():
        raise HelmetAncError(f"{option}: {name!r} is not a Python module name; rename the file (e.g. my_effect.py)")
    before = {effect.name: effect for effect in registry.effects()}
    spec = importlib.util.spec_from_file_location(name, path)
    if spec is None or spec.loader is None:
        raise HelmetAncError(f"{option}: not a Python module")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except HelmetAncError as exc:
        sys.modules.pop(name, None)
        raise HelmetAncError(f"{option}: {exc}") from None
    except Exception as exc:  # the user's code: any error is theirs to fix, reported in one line
        sys.modules.pop(name, None)
        if isinstance(exc, SyntaxError):
            line, text = exc.lineno, exc.msg
        else:
            own = path.resolve()
            frames = [f for f in _frames(exc.__traceback__) if Path(f.tb_frame.f_code.co_filename).resolve() == own]
            line, text = (frames[-1].tb_lineno if frames else None), str(exc)
        where = f" at line {line}" if line else ""
        raise HelmetAncError(f"{option}: does not load ({type(exc).__name__}{where}: {text})") from None
    added = [e.name for e in registry.effects() if before.get(e.name) is not e]
    if not added:
        raise HelmetAncError(f"{option}: registers no effect; the module must call sysid.effects.register(Effect(...))")
    return added


def _frames(tb):
    while tb is not None:
        yield tb
        tb = tb.tb_next
