"""``helmet-anc simulate``: write a synthetic session like the seed's experiment."""

from __future__ import annotations

from pathlib import Path

from sysid.core.effect_spec import parse_effect
from sysid.core.errors import HelmetAncError
from sysid.core.files import OutputRefused, check_output_file, is_ours
from sysid.core.thresholds import NOISE_AFTER_TRANSIENT_S
from sysid.io.recordings import noise_length_rule
from sysid.random_plant import random_session
from sysid.simulate import SIMULATED_EFFECTS, SessionSpec, simulate_session, write_session

ORDER = 10


def register(commands) -> None:
    parser = commands.add_parser("simulate", help="write a synthetic session (noise.wav, sweep1/2.wav, truth.json)")
    parser.add_argument("outdir")
    parser.add_argument("--path", choices=("fb", "ff"), default="fb")
    parser.add_argument("--plant", choices=("appendix-a", "random"), default="appendix-a",
                        help="true plant: the seed's appendix-A model of --path, or a random plausible helmet path "
                             "drawn from --seed (its own sample rate, latency and sensor noise)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--noise-seconds", type=float, default=20.0)
    parser.add_argument("--sweep-seconds", type=float, default=5.0)
    parser.add_argument("--output-noise", type=float, default=None,
                        help="ear-microphone noise RMS (FS); default 2e-4, or the random plant's own")
    parser.add_argument("--input-noise", type=float, default=2e-5, help="input-channel noise RMS (FS)")
    parser.add_argument("--effect", action="append", default=[], metavar="KIND[:PARAMS]",
                        help="hidden effect, repeatable: " + ", ".join(SIMULATED_EFFECTS) + " (e.g. delay:23, resonance:3400,8,10)")
    parser.add_argument("--force", action="store_true",
                        help="replace session files in OUTDIR that helmet-anc did not write")
    parser.set_defaults(handler=run)


SESSION_FILES = ("noise.wav", "sweep1.wav", "sweep2.wav", "truth.json")


def check_session_folder(outdir: str, force: bool) -> None:
    """Before any work: OUTDIR is a folder (or can be made), and its session files are ours or --force.

    A session's recordings are ours when its truth.json is (the WAV files carry no tag).
    """
    folder = Path(outdir)
    if folder.exists() and not folder.is_dir():
        raise OutputRefused(f"{folder}: exists and is not a folder; give a folder for the session")
    if not folder.exists():
        existing = next((p for p in folder.parents if p.exists()), Path("."))
        if not existing.is_dir():
            raise OutputRefused(f"{folder}: cannot create a folder under {existing}, which is a file")
        return
    ours = is_ours(folder / "truth.json")
    for name in SESSION_FILES:
        check_output_file(folder / name, force=force, option="outdir", ours=lambda _: ours)


def run(args) -> int:
    check_session_folder(args.outdir, args.force)
    output_noise = {} if args.output_noise is None else {"output_noise": args.output_noise}
    settings = dict(noise_duration=args.noise_seconds, sweep_duration=args.sweep_seconds,
                    input_noise=args.input_noise, **output_noise)
    spec = SessionSpec(path=args.path, seed=args.seed, **settings)
    if not args.noise_seconds > spec.transient_s + NOISE_AFTER_TRANSIENT_S:
        raise HelmetAncError(f"--noise-seconds {args.noise_seconds:g}: a noise recording needs "
                             f"{noise_length_rule(spec.transient_s)}")
    if args.sweep_seconds <= 0.1:
        raise HelmetAncError(f"--sweep-seconds must be above 0.1; found {args.sweep_seconds:g}")
    if args.seed < 0:
        raise HelmetAncError(f"--seed must be a non-negative whole number; found {args.seed}")
    if (args.output_noise is not None and args.output_noise < 0) or args.input_noise < 0:
        raise HelmetAncError("noise levels must be non-negative")
    effects = [parse_effect(text, SIMULATED_EFFECTS) for text in args.effect]
    if args.plant == "random":
        session = random_session(args.seed, args.path, effects=effects, **settings)
    else:
        session = simulate_session(spec, effects=effects)
    files = write_session(session, args.outdir)
    print(f"wrote {', '.join(str(p) for p in files.values())}")
    return 0
