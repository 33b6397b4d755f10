"""The README's examples run as written, and print what the README shows (docs/readme_examples.py).

Every shell and Python block of README.md is an example: run here in one scratch folder in README
order, its printed output compared line by line with the text block after it. The worked example
runs in the default run; the long ones are marked slow in the README (``<!-- readme: slow -->``)
and run with ``python -m pytest -m slow``. When an output changes on purpose,
``python docs/readme_examples.py --update`` rewrites the README's output blocks from a run.
"""

import sys

import pytest
from repo import REPO

sys.path.insert(0, str(REPO / "docs"))

import readme_examples  # noqa: E402

BLOCKS = readme_examples.examples((REPO / "README.md").read_text())
RUN = [b for b in BLOCKS if b.runnable]


@pytest.fixture(scope="module")
def workspace(tmp_path_factory):
    return readme_examples.Workspace(tmp_path_factory.mktemp("readme"))


def _param(block):
    marks = [pytest.mark.slow] if "slow" in block.marks else []
    if "expected to fail" in block.marks:
        marks.append(pytest.mark.xfail(reason=block.marks["expected to fail"], strict=False))
    return pytest.param(block.line, marks=marks, id=block.name)


@pytest.mark.parametrize("line", [_param(b) for b in RUN])
def test_the_example_runs_and_prints_what_the_readme_shows(line, workspace):
    block = workspace.example(line)
    result = workspace.run(line)
    assert result.returncode == 0, f"{result.command}: {result.stderr[-2000:]}"
    if block.output is not None:
        found = readme_examples.differences(block.output.text, result.stdout)
        assert not found, "\n".join(found) + "\n(python docs/readme_examples.py --update rewrites the README's " \
                                             "output blocks from a run)"


def test_the_worked_example_is_in_the_default_run():
    worked = [b for b in RUN if "slow" not in b.marks and "identify" in b.text and b.output is not None]
    assert worked, "the worked example must stay in the default run"


def test_nothing_is_skipped_without_a_reason():
    """Every shell and Python block is run, written as a file, or says why it is not run; every command
    that is not run is named with its reason; every output block follows an example."""
    for block in BLOCKS:
        if block.kind in ("sh", "python"):
            assert block.runnable or "file" in block.marks or block.marks.get("not run"), block.name
            for command, reason in readme_examples.commands(block) if block.kind == "sh" else []:
                assert reason is None or reason in readme_examples.NOT_RUN.values()
        assert block.kind != "text" or any(b.output is block for b in BLOCKS), block.line
        assert set(block.marks) <= {"slow", "file", "not run", "expected to fail"}, block.marks
    assert {c for b in BLOCKS if b.kind == "sh" for c, why in readme_examples.commands(b) if why} == \
        {"pip install .", "pip install '.[test]'", "python -m pytest"}


def test_the_effect_module_the_readme_shows_is_the_one_the_tests_register():
    shown = next(b for b in BLOCKS if b.marks.get("file") == "notch_effect.py")
    assert shown.text == (REPO / "tests" / "notch_effect.py").read_text()


def test_update_rewrites_only_the_output_blocks():
    text = "intro\n\n```sh\necho hi\n```\n\n```text\nold\n```\n\n```\nnot an example\n```\n"
    blocks = readme_examples.examples(text)
    new = readme_examples.updated_readme(text, {blocks[0].line: "hi\nthere\n"})
    assert new == "intro\n\n```sh\necho hi\n```\n\n```text\nhi\nthere\n```\n\n```\nnot an example\n```\n"
    assert readme_examples.differences("took 3.2 s wall\n", "took 4.0 s wall\n") == []
    # Figures are measurements: within 5 % or a unit of the last printed digit they agree; integers and words
    # must agree exactly.
    assert readme_examples.differences("rms 1.0e-3\n", "rms 1.1e-3\n") == []
    assert readme_examples.differences("rms 1.00e-3\n", "rms 1.10e-3\n")
    assert readme_examples.differences("12.72x the floor\n", "12.90x the floor\n") == []
    assert readme_examples.differences("order 16\n", "order 17\n")
    assert readme_examples.differences("refined\n", "rejected\n")
