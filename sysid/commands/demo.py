"""``helmet-anc demo``: the whole job on built-in synthetic sessions of both paths."""

from __future__ import annotations

from pathlib import Path

from ..grid import terminal_progress
from ..identify import identify
from ..model import atomic_write_text
from ..simulate import SessionSpec, simulate_session, write_session
from .common import identification_summary

ORDER = 90


def register(commands) -> None:
    parser = commands.add_parser("demo", help="simulate a session per path, identify both and summarise")
    parser.add_argument("outdir", nargs="?", default="helmet-anc-demo")
    parser.add_argument("--seed", type=int, default=0)
    parser.set_defaults(handler=run)


def run(args) -> int:
    outdir = Path(args.outdir)
    print(f"helmet-anc demo: synthetic sessions of the seed's appendix-A plants in {outdir}/")
    for path in ("fb", "ff"):
        session = simulate_session(SessionSpec(path=path, seed=args.seed))
        write_session(session, outdir / path)
        result = identify(session.noise, session.sweeps, path, progress=terminal_progress())
        result.model.save(outdir / f"{path}_model.json")
        atomic_write_text(outdir / f"{path}_model.grid.csv", result.grid.to_csv())
        print(identification_summary(result))
    print(f"models written to {outdir}/fb_model.json and {outdir}/ff_model.json")
    return 0
