"""``helmet-anc demo``: the whole job on built-in synthetic sessions of both paths, in seconds.

Simulates a short session of each appendix-A plant and identifies both paths; then shows
the diagnose -> refine loop on a re-measured FF session that hides a converter delay
and mains hum the model does not know; writes the HTML report of the refined model; and
generates and verifies the board's C filters for both models (host build, every sweep
sample). One line per step on stderr says where it is.

Short sessions (8 s of noise, two 2 s sweeps) and the seed's gamma grid at step 30, as the
tests use, keep it to about 20 s on two cores (BENCHMARKS.md, "The first minutes"): the
thesis-length sessions (20 s, 5 s) and the step-10 grid of ``helmet-anc identify`` took 104 s
with three reports. Every step is the one a user runs on their own sessions.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

from threadpoolctl import threadpool_limits

from sysid.core.files import atomic_write_text, staged_output_tree
from sysid.identify import IdentificationOptions, identify
from sysid.simulate import SessionSpec, simulate_session, write_session

from .common import identification_summary

# The hidden effects of the demo's second FF session: 23 samples of extra converter
# latency (about 18 cm of sound path) and 50 Hz mains hum with its harmonics.
DEMO_EFFECTS = ("delay:23", "periodic-disturbance")
# The demo's sessions and grid: short sessions and the seed's gamma grid at step 30 (tests/conftest.py).
DEMO_SESSION = dict(noise_duration=8.0, sweep_duration=2.0, sweep_silence=0.2)
DEMO_OPTIONS = IdentificationOptions(gammas=tuple(range(10, 1001, 30)))

ORDER = 90
# The demo's own manifest: every file of OUTDIR it wrote (relative path -> SHA-256). A rerun
# writes into OUTDIR only when everything there is listed in it (or with --force), and
# replaces or removes only files it lists (sysid.core.files, "output trees").
MANIFEST = "demo-manifest.json"
MANIFEST_FORMAT = "helmet-anc/demo-manifest@1"


def register(commands) -> None:
    parser = commands.add_parser("demo", help="simulate a session per path, identify both, diagnose and refine, "
                                              "report, generate and verify firmware (about 20 s)")
    parser.add_argument("outdir", nargs="?", default="helmet-anc-demo",
                        help="folder for everything the demo writes (default helmet-anc-demo)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the simulated sessions (whole number, default 0)")
    parser.add_argument("--no-firmware", action="store_true", help="skip the C generation and verification")
    parser.add_argument("--no-report", action="store_true", help="skip the HTML report")
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

    session = simulate_session(SessionSpec(path="ff", seed=seed + 1, **DEMO_SESSION), effects=DEMO_EFFECTS)
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
    # One BLAS thread, as identify and diagnose run: the products here are small, and the refinement's
    # comparisons (150 dot products over a sweep each) waited on a second thread for 8 of the demo's seconds.
    with staged_output_tree(outdir, MANIFEST, MANIFEST_FORMAT, args.force, option="OUTDIR") as work, \
            threadpool_limits(limits=1, user_api="blas"):
        _demo(args, work, outdir)
    print(f"everything above is in {outdir}/ ({MANIFEST} lists it)")
    return 0


def step_count(report: bool, firmware: bool) -> int:
    """The demo's steps: identify each path, the refinement loop, the report, the firmware of each path."""
    return 3 + int(report) + 2 * int(firmware)


class _Steps:
    """One line per step on stderr, ``demo [2/6] simulate and identify the FF path ... (at 2 s)`` (none with
    --quiet), with the seconds since the demo started."""

    def __init__(self, quiet: bool, total: int):
        self.quiet = quiet
        self.total = total
        self.count = 0
        self.started = time.perf_counter()

    def __call__(self, text: str) -> None:
        self.count += 1
        if not self.quiet:
            elapsed = time.perf_counter() - self.started
            sys.stderr.write(f"demo [{self.count}/{self.total}] {text} (at {elapsed:.0f} s)\n")
            sys.stderr.flush()


def _demo(args, work: Path, outdir: Path) -> None:
    """The demo's job, writing into ``work``; messages name the files by their final place in ``outdir``."""
    step = _Steps(args.quiet, step_count(not args.no_report, not args.no_firmware))
    print(f"helmet-anc demo: short synthetic sessions of the seed's appendix-A plants in {outdir}/")
    models = {}
    for k, path in enumerate(("fb", "ff")):
        step(f"simulate and identify the {path.upper()} path (8 s of noise, two 2 s sweeps)")
        session = simulate_session(SessionSpec(path=path, seed=args.seed, **DEMO_SESSION))
        files = write_session(session, work / path)
        result = identify(session.noise, session.sweeps, path, DEMO_OPTIONS)
        result.model.save(work / f"{path}_model.json")
        atomic_write_text(work / f"{path}_model.grid.csv", result.grid.to_csv())
        print(identification_summary(result))
        models[path] = (result.model, files, result, session)
    print(f"models written to {outdir}/fb_model.json and {outdir}/ff_model.json")
    step("diagnose the FF model on a re-measured session, refine --auto")
    refined = _refinement_loop(models["ff"][0], work, outdir, args.seed)
    if not args.no_report:
        from report import write_report

        step("HTML report of the refined FF model")
        (work / "reports").mkdir(exist_ok=True)
        model, session = refined
        write_report(work / "reports" / "ff-refined-report.html", model, session.noise, session.sweeps, grid="skip")
        print(f"\nHTML report in {outdir}/reports/ff-refined-report.html (identification, validation per band, "
              "diagnosis, the refinement's steps)")
    if not args.no_firmware:
        print("\nfirmware: C filters generated and verified sample by sample on both sweeps (host build)")
        (work / "firmware").mkdir(exist_ok=True)
        for path, (model, files, _, _) in models.items():
            step(f"generate and verify the {path.upper()} firmware")
            print(_firmware(model, work / "firmware" / path, (files["sweep1"], files["sweep2"])))
        print(f"C sources and manifests in {outdir}/firmware/")
