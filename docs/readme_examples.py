"""The README's examples, run: every shell and Python block in a scratch folder, its printed output compared.

    python docs/readme_examples.py [--only LINE ...] [--keep DIR]   run the examples, report every difference
    python docs/readme_examples.py --update                         ... and rewrite the README's output blocks

What is an example, and what its output is, is read from the README itself:

* a ```sh block is run line by line with bash (backslash continuations joined; ``a && b`` is
  two commands), each command in the same scratch folder, in README order; its output is what
  its *last* command prints on standard output (the earlier ones must succeed);
* a ```python block is run as a script in that folder (so ``import notch_effect`` finds a
  module an earlier block wrote there); its output is all it prints;
* a ```text block is the output of the nearest runnable block before it, compared line by
  line after ``normalise`` (only wall times vary from run to run; every other figure must
  agree to the last digit printed);
* other fences (```, a usage synopsis or a layout) are no examples.

An HTML comment on the lines right above a block's fence marks it (invisible on the rendered
page): ``<!-- readme: file NAME -->`` writes the block to NAME instead of running it;
``<!-- readme: slow -->`` leaves it out of the default test run (``tests/test_readme.py``;
``python -m pytest -m slow`` runs it); ``<!-- readme: not run: REASON -->`` and
``<!-- readme: expected to fail: REASON -->`` say why a block is not run, or fails today.
Commands of a block that are never run are named, with the reason, in ``NOT_RUN``. Nothing is
skipped without a reason: ``plan`` lists every block and command and what happens to it.

Every example runs after every earlier one in one folder (later ones read the files earlier
ones wrote: the worked example's ``ff_model.json``), except those that read nothing of the
others (``INDEPENDENT``: the demo), which run in a folder of their own. The command line is
this tree's (``PYTHONPATH`` set to it, as the tests run).
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
README = ROOT / "README.md"

__all__ = ["Example", "Result", "NOT_RUN", "INDEPENDENT", "examples", "commands", "Workspace", "normalise",
           "differences", "updated_readme", "plan", "main"]

# Commands the README shows that no run of its examples executes, and why.
NOT_RUN = {
    "pip install": "installing is what the environment under test did; the examples run from this tree",
    "python -m pytest": "the test suite itself (tests/test_readme.py runs these examples)",
}
# Commands whose examples read no file an earlier example wrote: run in a folder of their own.
INDEPENDENT = ("helmet-anc demo",)
# What genuinely varies from run to run: wall and CPU times.
VARIABLE = (re.compile(r"\b\d+(\.\d+)? ?(s|ms|min)\b(?= (wall|CPU|of CPU|elapsed))"),
            re.compile(r"(?<=in )\d+(\.\d+)? ?s\b"))
_FENCE = re.compile(r"^```(\w*)\s*$")
_MARK = re.compile(r"^<!--\s*readme:\s*(.*?)\s*-->\s*$")


@dataclass
class Example:
    """One fenced block of the README: ``kind`` sh, python or text; ``line`` its opening fence (1-based);
    ``marks`` from the comments above it; ``output`` the text block holding its output, if any."""

    kind: str
    line: int
    end: int
    text: str
    marks: dict = field(default_factory=dict)
    output: "Example | None" = None

    @property
    def name(self) -> str:
        """``line N: <first words>``, the example's name in test ids and reports."""
        first = next((line.strip() for line in self.text.splitlines() if line.strip() and not line.startswith("#")),
                     "")
        return f"line {self.line}: {first[:60]}"

    @property
    def runnable(self) -> bool:
        return self.kind in ("sh", "python") and "file" not in self.marks and "not run" not in self.marks

    @property
    def independent(self) -> bool:
        return self.kind == "sh" and all(c.startswith(INDEPENDENT) for c, why in commands(self) if why is None)


def _marks(lines: list[str], fence: int) -> dict:
    marks = {}
    k = fence - 1
    while k >= 0 and _MARK.match(lines[k]):
        text = _MARK.match(lines[k]).group(1)
        key, _, value = text.partition(":") if ":" in text else text.partition(" ")
        marks[key.strip()] = value.strip()
        k -= 1
    return marks


def examples(text: str) -> list[Example]:
    """Every fenced block of ``text`` (a README) with its marks; text blocks attached to the runnable block
    before them."""
    lines = text.splitlines()
    blocks, k = [], 0
    while k < len(lines):
        opened = _FENCE.match(lines[k])
        if not opened:
            k += 1
            continue
        end = next(j for j in range(k + 1, len(lines)) if lines[j].startswith("```"))
        blocks.append(Example(opened.group(1) or "", k + 1, end + 1, "\n".join(lines[k + 1:end]) + "\n",
                              _marks(lines, k)))
        k = end + 1
    last = None
    for block in blocks:
        if block.runnable or "expected to fail" in block.marks:
            last = block
        elif block.kind == "text":
            if last is None or last.output is not None:
                raise ValueError(f"README line {block.line}: an output block with no example before it")
            last.output = block
    return blocks


def commands(example: Example) -> list[tuple[str, str | None]]:
    """The commands of a shell block, continuations joined and ``&&`` split: (command, None) when it is
    run, (command, reason) when it is not (``NOT_RUN``)."""
    joined = re.sub(r"\\\n\s*", " ", example.text)
    found = []
    for line in joined.splitlines():
        line = line.split("  #")[0].strip()
        if not line or line.startswith("#"):
            continue
        for command in (part.strip() for part in line.split("&&")):
            reason = next((why for prefix, why in NOT_RUN.items() if command.startswith(prefix)), None)
            found.append((command, reason))
    return found


@dataclass
class Result:
    """What running an example gave: the output compared (stdout), stderr, exit status and wall time."""

    stdout: str
    stderr: str
    returncode: int
    seconds: float
    command: str = ""


class Workspace:
    """A scratch folder the examples run in, in README order; each example runs once."""

    def __init__(self, folder: Path, readme: Path = README):
        self.folder = Path(folder)
        self.folder.mkdir(parents=True, exist_ok=True)
        self.blocks = examples(Path(readme).read_text())
        self.results: dict[int, Result] = {}
        self.environment = {**os.environ, "PYTHONPATH": os.pathsep.join(
            [str(ROOT)] + [p for p in os.environ.get("PYTHONPATH", "").split(os.pathsep) if p]),
            "COLUMNS": "200"}

    def example(self, line: int) -> Example:
        return next(b for b in self.blocks if b.line == line)

    def run(self, line: int) -> Result:
        """The result of the example at ``line``, after every earlier one it may need (run once each)."""
        target = self.example(line)
        for block in self.blocks:
            if block.line > line:
                break
            if block.line in self.results:
                continue
            if block.line != line and (block.independent or not (block.runnable or "file" in block.marks)):
                continue
            self.results[block.line] = self._run(block)
        return self.results[target.line]

    def _run(self, block: Example) -> Result:
        if "file" in block.marks:
            (self.folder / block.marks["file"]).write_text(block.text)
            return Result("", "", 0, 0.0, f"wrote {block.marks['file']}")
        if block.kind == "python":
            script = self.folder / f"readme_line_{block.line}.py"
            script.write_text(block.text)
            return self._execute([sys.executable, script.name], self.folder, script.name)
        folder = self.folder / f"line_{block.line}" if block.independent else self.folder
        folder.mkdir(exist_ok=True)
        result = Result("", "", 0, 0.0)
        for command, reason in commands(block):
            if reason is not None:
                continue
            result = self._execute(["bash", "-c", command], folder, command)
            if result.returncode != 0:
                break
        return result

    def _execute(self, argv, folder: Path, label: str) -> Result:
        started = time.perf_counter()
        done = subprocess.run(argv, cwd=folder, env=self.environment, capture_output=True, text=True)
        return Result(done.stdout, done.stderr, done.returncode, time.perf_counter() - started, label)


def normalise(text: str) -> list[str]:
    """Lines without trailing blanks, wall times replaced by ``<time>``; no trailing empty lines."""
    lines = []
    for line in text.rstrip("\n").splitlines():
        for pattern in VARIABLE:
            line = pattern.sub("<time>", line)
        lines.append(line.rstrip())
    return lines


# A printed figure is a measurement: a fit's last digits move with the machine's round-off (BLAS, the order of
# a sum), so decimal figures agree within FIGURE_TOLERANCE of each other (relative) or one unit of their last
# printed digit, whichever is larger; integers (orders, delays, counts) and every word must agree exactly.
FIGURE_TOLERANCE = 0.05
_FIGURE = re.compile(r"[-+]?\d+\.\d+(?:[eE][-+]?\d+)?")


def _same_line(shown: str, printed: str) -> bool:
    """The lines agree: the same text with every decimal figure replaced, and each pair of figures within
    FIGURE_TOLERANCE (relative) or one unit of the README's last printed digit."""
    if _FIGURE.sub("#", shown) != _FIGURE.sub("#", printed):
        return False
    for a, b in zip(_FIGURE.findall(shown), _FIGURE.findall(printed)):
        mantissa = a.lower().split("e")[0]
        unit = 10.0 ** -len(mantissa.split(".")[1]) * (10.0 ** int(a.lower().split("e")[1]) if "e" in a.lower()
                                                       else 1.0)
        x, y = float(a), float(b)
        if abs(x - y) > max(FIGURE_TOLERANCE * max(abs(x), abs(y)), unit * (1 + 1e-9)):
            return False
    return True


def differences(expected: str, printed: str) -> list[str]:
    """Line-by-line differences (README line vs printed line), empty when they agree (``_same_line``)."""
    shown, got = normalise(expected), normalise(printed)
    found = [f"line {k + 1}:\n  README : {a}\n  printed: {b}" for k, (a, b) in enumerate(zip(shown, got))
             if not _same_line(a, b)]
    if len(shown) != len(got):
        found.append(f"the README shows {len(shown)} lines, the example printed {len(got)}")
    return found


def updated_readme(text: str, outputs: dict[int, str]) -> str:
    """``text`` with the output block of each example in ``outputs`` (its line -> printed text) replaced."""
    lines = text.splitlines(keepends=True)
    for block in sorted((b for b in examples(text) if b.line in outputs and b.output is not None),
                        key=lambda b: -b.line):
        body = outputs[block.line].rstrip("\n")
        lines[block.output.line:block.output.end - 1] = [line + "\n" for line in body.splitlines()]
    return "".join(lines)


def plan(blocks: list[Example]) -> list[str]:
    """One line per block and command: run, written as a file, or not run and why."""
    out = []
    for block in blocks:
        if block.kind not in ("sh", "python"):
            continue
        if "file" in block.marks:
            out.append(f"{block.name}: written as {block.marks['file']}")
        elif "not run" in block.marks:
            out.append(f"{block.name}: not run: {block.marks['not run']}")
        elif block.kind == "sh" and all(why for _, why in commands(block)):
            out.append(f"{block.name}: no command run")
        else:
            state = "expected to fail: " + block.marks["expected to fail"] if "expected to fail" in block.marks else (
                "run (slow)" if "slow" in block.marks else "run")
            out.append(f"{block.name}: {state}" + ("" if block.output else ", no output shown"))
        if block.kind == "sh":
            out.extend(f"    not run: {command}: {why}" for command, why in commands(block) if why)
    return out


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--update", action="store_true", help="rewrite the README's output blocks from this run")
    parser.add_argument("--only", type=int, action="append", default=[], metavar="LINE",
                        help="run only up to these examples (the line of their opening fence)")
    parser.add_argument("--keep", metavar="DIR", help="run in DIR and keep it (default: a temporary folder)")
    args = parser.parse_args(argv)
    text = README.read_text()
    blocks = examples(text)
    print("\n".join(plan(blocks)))
    with tempfile.TemporaryDirectory(prefix="readme-") as scratch:
        workspace = Workspace(Path(args.keep or scratch))
        targets = [b for b in blocks if (b.runnable or "expected to fail" in b.marks)
                   and (not args.only or b.line in args.only)]
        outputs, failed = {}, 0
        for block in targets:
            result = workspace.run(block.line)
            status = "ok" if result.returncode == 0 else f"exit {result.returncode}"
            found = differences(block.output.text, result.stdout) if block.output and result.returncode == 0 else []
            print(f"\n{block.name}: {status}, {result.seconds:.1f} s" + (f", {len(found)} difference(s)" if found
                                                                         else ""))
            if result.returncode != 0:
                print("  " + (result.stderr.strip().splitlines() or ["(no message)"])[-1])
                failed += "expected to fail" not in block.marks
            for line in found:
                print("  " + line.replace("\n", "\n  "))
            if block.output and result.returncode == 0:
                outputs[block.line] = result.stdout
    if args.update:
        new = updated_readme(text, outputs)
        if new != text:
            README.write_text(new)
            print(f"\nrewrote {sum(1 for b in blocks if b.line in outputs)} output block(s) of {README}")
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
