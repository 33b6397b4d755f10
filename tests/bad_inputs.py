"""Bad inputs a user can give, each with the command line that must refuse it (exit 2, one line, nothing written).

Used by tests/test_bad_input.py (in-process) and benchmarks/bad_input_table.py (real runs, the
"Bad input" table of BENCHMARKS.md). ``prepare`` writes the derived input files into a folder
from a valid session and model; each case's argv names files by ``{key}``.
"""

from __future__ import annotations

import json
import shutil
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from sysid.io.recordings import write_wav16


@dataclass(frozen=True)
class BadInput:
    label: str          # what was tried, in the user's words
    argv: tuple         # helmet-anc arguments; {key} is replaced by a prepared file
    expect: str         # a phrase the one-line message must contain


def _model_variant(model: dict, folder: Path, name: str, **changes) -> Path:
    path = folder / name
    path.write_text(json.dumps({**model, **changes}))
    return path


def prepare(folder: Path, session: dict, model_file: Path) -> dict[str, str]:
    """Write the bad inputs into ``folder``; return {key: path} for the case templates."""
    folder.mkdir(parents=True, exist_ok=True)
    files = {key: folder / Path(session[key]).name for key in ("noise", "sweep1", "sweep2")}
    for key, target in files.items():
        shutil.copyfile(session[key], target)
    model = json.loads(Path(model_file).read_text())
    files["model"] = folder / "model.json"
    files["model"].write_text(json.dumps(model))
    n = len(model["A"])
    files["sweep_copy"] = folder / "sweep1_copy.wav"
    shutil.copyfile(session["sweep1"], files["sweep_copy"])
    files["unstable"] = _model_variant(model, folder, "unstable.json", A=(1.02 * np.asarray(model["A"])).tolist())
    files["text_matrix"] = _model_variant(model, folder, "text_matrix.json", A="[[0.5]]")
    files["ragged"] = _model_variant(model, folder, "ragged.json", A=[[0.5] * n] + [[0.1]] * (n - 1))
    (folder / "nan.json").write_text(json.dumps({**model, "A": [[float("nan")] * n] * n}))  # NaN literal
    files["nan"] = folder / "nan.json"
    files["huge"] = _model_variant(model, folder, "huge.json", C=[[1e300] * n])
    files["delay"] = _model_variant(model, folder, "delay.json", delay=1e9)
    files["order"] = _model_variant(model, folder, "order.json", A=np.eye(1500).tolist(), B=[[0.0]] * 1500,
                                    C=[[0.0] * 1500])
    files["folder"] = folder / "a_folder"
    files["folder"].mkdir(exist_ok=True)
    files["user_notes"] = folder / "notes.json"
    files["user_notes"].write_text('{"my": "notes"}\n')
    files["user_firmware"] = folder / "my_firmware"
    files["user_firmware"].mkdir(exist_ok=True)
    (files["user_firmware"] / "main.c").write_text("int main(void) { return 0; }\n")
    files["garbage_wav"] = folder / "garbage.wav"
    files["garbage_wav"].write_bytes(b"RIFF\x24\x00\x00\x00WAVEfmt \x10\x00\x00\x00" + bytes(range(64)))
    import scipy.io.wavfile

    fs, data = scipy.io.wavfile.read(session["sweep1"])
    u, y = data[:, 0] / 32768.0, data[:, 1] / 32768.0
    files["noise_ear"] = folder / "sweep1_noise_ear.wav"
    write_wav16(files["noise_ear"], u, 0.01 * np.random.default_rng(0).standard_normal(u.size), fs)
    files["silent_ear"] = folder / "sweep1_silent_ear.wav"
    write_wav16(files["silent_ear"], u, np.zeros_like(y), fs)
    files["swapped"] = folder / "sweep1_swapped.wav"
    write_wav16(files["swapped"], y, u, fs)
    _, second = scipy.io.wavfile.read(session["sweep2"])
    u2, y2 = second[:, 0] / 32768.0, second[:, 1] / 32768.0
    files["half_level"] = folder / "sweep2_half_level.wav"
    write_wav16(files["half_level"], 0.5 * u2, 0.5 * y2, fs)
    # The same sweep stretched to 1.25 times its length: another excitation, not a repeat.
    stretched = np.linspace(0.0, u2.size - 1.0, int(1.25 * u2.size))
    files["longer"] = folder / "sweep2_longer.wav"
    write_wav16(files["longer"], *(np.interp(stretched, np.arange(u2.size), x) for x in (u2, y2)), fs)
    noise_fs, noise = scipy.io.wavfile.read(session["noise"])
    for key, seconds in (("noise_half_s", 0.5), ("noise_2s", 2.0)):
        files[key] = folder / f"noise_{seconds:g}s.wav"
        scipy.io.wavfile.write(files[key], noise_fs, noise[:int(seconds * noise_fs)])
    files["noise_truncated"] = folder / "noise_truncated.wav"  # the header promises the whole recording
    files["noise_truncated"].write_bytes(Path(session["noise"]).read_bytes()[:44 + 4 * int(2.0 * noise_fs)])
    files["controller"] = folder / "controller.json"
    files["controller"].write_text(json.dumps({"format": "helmet-anc/controller@1", "fs": model["fs"],
                                               "internal_model": model, "ff": None, "fb": None, "latency_samples": 2}))
    files["broken_effect"] = folder / "broken_effect.py"
    files["broken_effect"].write_text("from sysid.effects import Effect, register\nregister(Effect(name=))\n")
    return {key: str(path) for key, path in files.items()}


_SWEEPS = ("--sweep", "{sweep1}", "--sweep", "{sweep2}")
_RECORDINGS = ("--noise", "{noise}", *_SWEEPS)

CASES = (
    BadInput("the same sweep file twice", ("compare", "{model}", "--sweep", "{sweep1}", "--sweep", "{sweep1}"),
             "sample-identical"),
    BadInput("a sample-identical copy of a sweep", ("compare", "{model}", "--sweep", "{sweep1}", "--sweep",
                                                    "{sweep_copy}"), "sample-identical"),
    BadInput("an unstable model to compare", ("compare", "{unstable}", *_SWEEPS), "unstable"),
    BadInput("an unstable model to diagnose", ("diagnose", "{unstable}", *_RECORDINGS), "unstable"),
    BadInput("an unstable model to generate-firmware", ("generate-firmware", "{unstable}", "-o", "{folder}/fw"),
             "unstable"),
    BadInput("a WAV file where the model JSON goes", ("compare", "{sweep1}", *_SWEEPS), "is a WAV recording"),
    BadInput("model matrix given as text", ("compare", "{text_matrix}", *_SWEEPS), "not numeric"),
    BadInput("model matrix with rows of different lengths", ("compare", "{ragged}", *_SWEEPS), "different lengths"),
    BadInput("model matrix with NaN", ("compare", "{nan}", *_SWEEPS), "non-finite"),
    BadInput("model coefficient 1e300", ("compare", "{huge}", *_SWEEPS), "above the limit"),
    BadInput("model delay of 1e9 samples", ("diagnose", "{delay}", *_RECORDINGS), "above the limit"),
    BadInput("model of order 1500", ("compare", "{order}", *_SWEEPS), "above the limit"),
    BadInput("a folder given as a sweep", ("compare", "{model}", "--sweep", "{folder}", "--sweep", "{sweep2}"),
             "is a folder"),
    BadInput("a folder given as the model", ("compare", "{folder}", *_SWEEPS), "is a folder"),
    BadInput("a corrupt WAV file", ("compare", "{model}", "--sweep", "{garbage_wav}", "--sweep", "{sweep2}"),
             "not a readable WAV"),
    BadInput("an ear channel hearing only noise (disconnected, or the wrong channel)",
             ("identify", "--noise", "{noise}", "--sweep", "{noise_ear}", "--sweep", "{sweep2}",
              "-o", "{folder}/m.json"), "--input-channel/--output-channel"),
    BadInput("a silent (disconnected) ear channel", ("identify", "--noise", "{noise}", "--sweep", "{silent_ear}",
                                                     "--sweep", "{sweep2}", "-o", "{folder}/m.json"), "silent"),
    BadInput("the ear on channel 0 and the input on channel 1 (swapped)",
             ("identify", "--noise", "{noise}", "--sweep", "{swapped}", "--sweep", "{sweep2}", "-o", "{folder}/m.json"),
             "--input-channel 1 --output-channel 0"),
    BadInput("-o naming an input recording", ("identify", *_RECORDINGS, "-o", "{sweep2}", "--force"), "is an input"),
    BadInput("-o naming the model read", ("refine", "{model}", *_RECORDINGS, "--add", "delay:2", "-o", "{model}"),
             "is an input"),
    BadInput("--max-order of no states", ("refine", "{model}", *_RECORDINGS, "--auto", "--max-order", "0",
                                          "-o", "{folder}/r.json"), "--max-order"),
    BadInput("--max-order that is not a number", ("refine", "{model}", *_RECORDINGS, "--auto", "--max-order", "many",
                                                  "-o", "{folder}/r.json"), "--max-order"),
    BadInput("--add more states to a model at the state cap",
             ("refine", "{model}", *_RECORDINGS, "--add", "under-modelled", "--max-order", "5", "-o", "{folder}/r.json"),
             "state cap"),
    BadInput("-o naming a file helmet-anc did not write", ("compare", "{model}", *_SWEEPS, "--json", "{user_notes}"),
             "--force"),
    BadInput("-o in a folder that does not exist", ("identify", *_RECORDINGS, "-o", "{folder}/missing/m.json"),
             "does not exist"),
    BadInput("generate-firmware into a folder of the user's sources",
             ("generate-firmware", "{model}", "-o", "{user_firmware}"), "did not write"),
    BadInput("demo into a folder of the user's files", ("demo", "{user_firmware}"), "did not write"),
    BadInput("an unknown effect", ("simulate", "{folder}/s", "--effect", "reverb:3"), "effect"),
    BadInput("an effect parameter that is not a number", ("simulate", "{folder}/s", "--effect", "delay:abc"),
             "delay"),
    BadInput("the second sweep at half the level of the first", ("compare", "{model}", "--sweep", "{sweep1}",
                                                                  "--sweep", "{half_level}"), "-6.0 dB"),
    BadInput("a second sweep of another length (not a repeat)",
             ("identify", "--noise", "{noise}", "--sweep", "{sweep1}", "--sweep", "{longer}", "-o", "{folder}/m.json"),
             "do not repeat each other"),
    BadInput("a noise recording of 0.5 s", ("identify", "--noise", "{noise_half_s}", *_SWEEPS, "-o", "{folder}/m.json"),
             "is too short; it needs more than 3.8 s"),
    BadInput("a noise recording of 2 s", ("diagnose", "{model}", "--noise", "{noise_2s}", *_SWEEPS),
             "is too short; it needs more than 3.8 s"),
    BadInput("a noise WAV cut short (header promises more)", ("report", "{model}", "--noise", "{noise_truncated}",
                                                              *_SWEEPS, "-o", "{folder}/r.html"), "is too short"),
    BadInput("simulate --noise-seconds 3.04", ("simulate", "{folder}/s", "--noise-seconds", "3.04"),
             "needs more than 3.8 s"),
    BadInput("simulate --fs 8000", ("simulate", "{folder}/s", "--fs", "8000"), "--fs must be between"),
    BadInput("a controller given as the model to compare", ("compare", "{controller}", *_SWEEPS),
             "this is a controller (helmet-anc/controller@1), not a model"),
    BadInput("a controller given as the model to refine", ("refine", "{controller}", *_RECORDINGS, "--auto",
                                                           "-o", "{folder}/r.json"), "this is a controller"),
    BadInput("--report into a folder that does not exist", ("identify", *_RECORDINGS, "-o", "{folder}/m.json",
                                                             "--report", "{folder}/reps/"), "does not exist"),
    BadInput("--effect-module that does not exist", ("simulate", "{folder}/s", "--effect-module", "{folder}/none.py",
                                                     "--effect", "notch:1200"), "no such file"),
    BadInput("--effect-module that does not load", ("simulate", "{folder}/s", "--effect-module", "{broken_effect}",
                                                    "--effect", "notch:1200"), "does not load (SyntaxError"),
)


def argv_of(case: BadInput, files: dict[str, str]) -> list[str]:
    return [part.format(**files) for part in case.argv]


def snapshot(folder: Path) -> dict[str, bytes]:
    """Every file under ``folder`` with its content (to prove nothing was touched)."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(Path(folder).rglob("*")) if p.is_file()}
