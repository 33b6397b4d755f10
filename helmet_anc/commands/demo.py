"""``helmet-anc demo``: the whole job on built-in synthetic sessions of both paths.

Simulates a session of each appendix-A plant and identifies both paths; then shows
the diagnose -> refine loop on a re-measured FF session that hides a converter delay
and mains hum the model does not know; writes an HTML report per model; and generates
and verifies the board's C filters for both models (host build, every sweep sample).
"""

from __future__ import annotations

from pathlib import Path

from sysid.core.files import atomic_write_text, staged_output_tree
from sysid.estimation.grid import terminal_progress
from sysid.identify import identify
from sysid.simulate import SessionSpec, simulate_session, write_session

from ..progress import busy
from .common import identification_summary

# The hidden effects of the demo's second FF session: 23 samples of extra converter
# latency (about 18 cm of sound path) and 50 Hz mains hum with its harmonics.
DEMO_EFFECTS = ("delay:23", "periodic-disturbance")

ORDER = 90
# The demo's own manifest: every file of OUTDIR it wrote (relative path -> SHA-256). A rerun
# writes into OUTDIR only when everything there is listed in it (or with --force), and
# replaces or removes only files it lists (sysid.core.files, "output trees").
MANIFEST = "demo-manifest.json"
MANIFEST_FORMAT = "helmet-anc/demo-manifest@1"


def register(commands) -> None:
    parser = commands.add_parser("demo", help="simulate a session per path, identify both, generate and verify firmware")
    parser.add_argument("outdir", nargs="?", default="helmet-anc-demo")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--no-firmware", action="store_true", help="skip the C generation and verification")
    parser.add_argument("--no-report", action="store_true", help="skip the HTML reports")
    parser.add_argument("--force", action="store_true",
                        help="write into an OUTDIR holding files the demo did not write (they are never replaced)")
    parser.set_defaults(handler=run)


def _firmware(model, outdir: Path, sweep_files) -> str:
    # The front end is the one place that reaches both packages (design.md, "Layout").
    from codegen.api import format_verification_table, generate_firmware

    manifest = generate_firmware(model, outdir, variant="both", sweeps=[str(f) for f in sweep_files])
    return format_verification_table(manifest)


def _refinement_loop(model, work: Path, outdir: Path, seed: int):
    """Diagnose the FF model on a session with hidden effects, refine until done, print each step."""
    from sysid.diagnose import diagnose, format_findings
    from sysid.refine import format_refinement, refine_auto
    from sysid.validation.compare import compare

    session = simulate_session(SessionSpec(path="ff", seed=seed + 1), effects=DEMO_EFFECTS)
    write_session(session, work / "ff-remeasured")
    before = compare(model, session.sweeps)
    print(f"\ndiagnose: the FF model on a re-measured session ({outdir}/ff-remeasured/, hidden effects kept "
          f"in truth.json): rms {before.rms:.3e} FS = {before.rms / before.noise_floor:.1f}x the noise floor")
    print(format_findings(diagnose(model, session.noise, session.sweeps, comparison=before)))
    auto = refine_auto(model, session.noise, session.sweeps)
    refined = auto.model
    print("refine --auto:")
    print(format_refinement(auto.steps, auto.stop_reason))
    refined.save(work / "ff_refined_model.json")
    print(f"refined model written to {outdir}/ff_refined_model.json")
    return refined, session


def run(args) -> int:
    outdir = Path(args.outdir)
    # Built in a staging folder beside OUTDIR and moved there at the end: an interrupted
    # demo leaves OUTDIR as it was.
    with staged_output_tree(outdir, MANIFEST, MANIFEST_FORMAT, args.force, option="OUTDIR") as work:
        _demo(args, work, outdir)
    print(f"everything above is in {outdir}/ ({MANIFEST} lists it)")
    return 0


def _demo(args, work: Path, outdir: Path) -> None:
    """The demo's job, writing into ``work``; messages name the files by their final place in ``outdir``."""
    print(f"helmet-anc demo: synthetic sessions of the seed's appendix-A plants in {outdir}/")
    models = {}
    for path in ("fb", "ff"):
        session = simulate_session(SessionSpec(path=path, seed=args.seed))
        files = write_session(session, work / path)
        result = identify(session.noise, session.sweeps, path, progress=None if args.quiet else terminal_progress())
        result.model.save(work / f"{path}_model.json")
        atomic_write_text(work / f"{path}_model.grid.csv", result.grid.to_csv())
        print(identification_summary(result))
        models[path] = (result.model, files, result, session)
    print(f"models written to {outdir}/fb_model.json and {outdir}/ff_model.json")
    with busy("demo: diagnose and refine --auto", args.quiet):
        refined = _refinement_loop(models["ff"][0], work, outdir, args.seed)
    if not args.no_report:
        from report import write_report

        (work / "reports").mkdir(exist_ok=True)
        with busy("demo: HTML reports", args.quiet):
            for path, (model, files, result, session) in models.items():
                write_report(work / "reports" / f"{path}-report.html", model, session.noise, session.sweeps,
                             identification=result)
            model, session = refined
            write_report(work / "reports" / "ff-refined-report.html", model, session.noise, session.sweeps)
        print(f"\nHTML reports in {outdir}/reports/ (fb-report.html, ff-report.html, ff-refined-report.html)")
    if not args.no_firmware:
        print("\nfirmware: C filters generated and verified sample by sample on both sweeps (host build)")
        (work / "firmware").mkdir(exist_ok=True)
        for path, (model, files, _, _) in models.items():
            with busy(f"demo: {path} firmware, generated and verified", args.quiet):
                text = _firmware(model, work / "firmware" / path, (files["sweep1"], files["sweep2"]))
            print(text)
        print(f"C sources and manifests in {outdir}/firmware/")
