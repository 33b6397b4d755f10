"""``helmet-anc demo``: the whole job on built-in synthetic sessions of both paths.

Simulates a session of each appendix-A plant, identifies both paths, and generates
and verifies the board's C filters for both models (host build, every sweep sample).
"""

from __future__ import annotations

from pathlib import Path

from ..errors import HelmetAncError
from ..grid import terminal_progress
from ..identify import identify
from ..model import atomic_write_text
from ..simulate import SessionSpec, simulate_session, write_session
from .common import identification_summary

ORDER = 90


def register(commands) -> None:
    parser = commands.add_parser("demo", help="simulate a session per path, identify both, generate and verify firmware")
    parser.add_argument("outdir", nargs="?", default="helmet-anc-demo")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--no-firmware", action="store_true", help="skip the C generation and verification")
    parser.set_defaults(handler=run)


def _firmware(model, outdir: Path, sweep_files) -> str:
    # The front end is the one place that reaches both packages (design.md, "Layout").
    from codegen.api import format_verification_table, generate_firmware

    manifest = generate_firmware(model, outdir, variant="both", sweeps=[str(f) for f in sweep_files])
    return format_verification_table(manifest)


def run(args) -> int:
    outdir = Path(args.outdir)
    if outdir.exists() and not outdir.is_dir():
        raise HelmetAncError(f"{outdir}: exists and is not a folder")
    print(f"helmet-anc demo: synthetic sessions of the seed's appendix-A plants in {outdir}/")
    models = {}
    for path in ("fb", "ff"):
        session = simulate_session(SessionSpec(path=path, seed=args.seed))
        files = write_session(session, outdir / path)
        result = identify(session.noise, session.sweeps, path, progress=terminal_progress())
        result.model.save(outdir / f"{path}_model.json")
        atomic_write_text(outdir / f"{path}_model.grid.csv", result.grid.to_csv())
        print(identification_summary(result))
        models[path] = (result.model, files)
    print(f"models written to {outdir}/fb_model.json and {outdir}/ff_model.json")
    if not args.no_firmware:
        print("\nfirmware: C filters generated and verified sample by sample on both sweeps (host build)")
        (outdir / "firmware").mkdir(exist_ok=True)
        for path, (model, files) in models.items():
            print(_firmware(model, outdir / "firmware" / path, (files["sweep1"], files["sweep2"])))
        print(f"C sources and manifests in {outdir}/firmware/")
    return 0
