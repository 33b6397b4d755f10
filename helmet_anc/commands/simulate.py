"""``helmet-anc simulate``: write a synthetic session like the seed's experiment."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

from sysid.core.effect_spec import parse_effect
from sysid.core.errors import HelmetAncError
from sysid.core.files import OutputRefused, check_output_file, is_ours
from sysid.core.model import Model
from sysid.core.plants import appendix_a_model
from sysid.core.thresholds import NOISE_AFTER_TRANSIENT_S
from sysid.io.recordings import noise_length_rule
from sysid.io.wav import SAMPLE_FORMATS
from sysid.random_plant import random_plant
from sysid.simulate import SIMULATED_EFFECTS, SessionSpec, simulate_session, write_session

ORDER = 10


def register(commands) -> None:
    parser = commands.add_parser("simulate", help="write a synthetic session (noise.wav, sweep1/2.wav, truth.json)")
    parser.add_argument("outdir", help="folder for noise.wav, sweep1.wav, sweep2.wav and truth.json (created if needed)")
    parser.add_argument("--path", choices=("fb", "ff"), default="fb",
                        help="fb: headphone drive -> ear microphone; ff: chin microphone -> ear microphone (default fb)")
    parser.add_argument("--plant", choices=("appendix-a", "random"), default="appendix-a",
                        help="true plant: the seed's appendix-A model of --path, or a random plausible helmet path "
                             "drawn from --seed (its own sample rate, latency and sensor noise)")
    parser.add_argument("--seed", type=int, default=0,
                        help="seed of the excitations and sensor noise, and of the random plant (whole number, default 0)")
    parser.add_argument("--noise-seconds", type=float, default=20.0, metavar="S",
                        help=f"length of the noise recording in s (default 20); it needs {noise_length_rule()}")
    parser.add_argument("--sweep-seconds", type=float, default=5.0, metavar="S",
                        help="length of each 20 Hz-4 kHz log sweep in s, without the 0.5 s of silence on either "
                             "side (default 5)")
    parser.add_argument("--output-noise", type=float, default=None, metavar="FS",
                        help="ear-microphone noise RMS in full-scale units (FS); default 2e-4, or the random plant's own")
    parser.add_argument("--input-noise", type=float, default=2e-5, metavar="FS",
                        help="input-channel noise RMS in full-scale units (FS; default 2e-5)")
    parser.add_argument("--fs", type=float, default=None, metavar="HZ",
                        help=f"sample rate in Hz, {MIN_FS:g}-{MAX_FS:g} (default 44100, or the random plant's own); "
                             "the plant is resampled exactly (zero-order hold, delay rounded to whole samples)")
    parser.add_argument("--bits", choices=SAMPLE_FORMATS, default="16",
                        help="sample format of the WAV files: 16, 24 or 32-bit PCM, or float (32-bit IEEE; default 16)")
    parser.add_argument("--effect", action="append", default=[], metavar="KIND[:PARAMS]",
                        help="hidden effect, repeatable; each with its parameters in order (units in their names; "
                             "FS: full-scale units), all optional: " + "; ".join(
                                 f"{name}:{','.join(p.name for p in params)}" for name, params in SIMULATED_EFFECTS.items())
                             + " (e.g. delay:23, resonance:3400,8,10)")
    parser.add_argument("--force", action="store_true",
                        help="replace session files in OUTDIR that helmet-anc did not write")
    parser.set_defaults(handler=run)


# Sample rates simulate writes (Hz): the noise excitation reaches 5 kHz.
MIN_FS, MAX_FS = 16000.0, 192000.0


def at_rate(model: Model, fs: float) -> Model:
    """``model`` at the sample rate ``fs`` (Hz): its LTI core resampled by zero-order hold (exact for a plant
    sampled that way, as the appendix-A and random plants are; ``codegen.realise.rediscretise``), its delay
    rounded to whole samples of the new rate."""
    if fs == model.fs:
        return model
    from codegen.errors import CodegenError
    from codegen.realise import rediscretise

    try:
        A, B = rediscretise(model.A, model.B, model.fs, fs)
    except CodegenError as exc:
        raise HelmetAncError(f"--fs {fs:g}: the plant cannot be resampled ({exc})") from None
    return Model(path=model.path, fs=fs, A=A, B=B, C=model.C, D=model.D, delay=int(round(model.delay * fs / model.fs)),
                 identification=dict(model.identification or {}, resampled_from_hz=model.fs))


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
    if args.fs is not None and not MIN_FS <= args.fs <= MAX_FS:
        raise HelmetAncError(f"--fs must be between {MIN_FS:g} and {MAX_FS:g} Hz (the noise excitation reaches 5 kHz); "
                             f"found {args.fs:g}")
    output_noise = {} if args.output_noise is None else {"output_noise": args.output_noise}
    settings = dict(noise_duration=args.noise_seconds, sweep_duration=args.sweep_seconds,
                    input_noise=args.input_noise, bits=args.bits, **output_noise)
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
        drawn = random_plant(args.seed, args.path)
        fs = args.fs or drawn.fs
        fields = {"output_noise": drawn.sensor_noise, **settings, "fs": fs}
        session = simulate_session(SessionSpec(path=args.path, seed=args.seed, **fields), plant=at_rate(drawn.model, fs),
                                   effects=effects)
        session.truth["generator"] = drawn.to_dict()
    else:
        fs = args.fs or spec.fs
        session = simulate_session(replace(spec, fs=fs), plant=at_rate(appendix_a_model(args.path), fs), effects=effects)
    files = write_session(session, args.outdir)
    print(f"wrote {', '.join(str(p) for p in files.values())}")
    return 0
