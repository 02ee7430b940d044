"""The README's Python examples run as written.

Each ```python block of README.md is one test. The blocks share one namespace and run in
the order the README reads (the PPO block trains the task the first block composed), so
a test first runs any earlier block that has not run yet: `-k` may pick any one of them.
They run in a temporary working directory, so nothing they write lands in the
repository. Tracebacks point at README.md's own lines.

One line is not run, for time alone: see NOT_RUN. It shows as a skipped test with its
reason (pytest -ra), and the test fails if the README no longer has that line.
"""

from __future__ import annotations

import os
import re
from pathlib import Path

import pytest

README = Path(__file__).resolve().parents[1] / "README.md"
_FENCE = re.compile(r"^```python\n(.*?)^```", re.S | re.M)


def _blocks() -> list[tuple[int, str]]:
    """(first line number in README.md, source) of each ```python block."""
    text = README.read_text()
    return [(text.count("\n", 0, m.start(1)) + 1, m.group(1)) for m in _FENCE.finditer(text)]


BLOCKS = _blocks()

# README lines the block tests leave out (matched by what the line contains), and why.
NOT_RUN = {
    "ppo.train(": "ppo.train compiles two more programs (a chunk of updates and the evaluation) and runs "
    "them: about 2.5 minutes on a 2-core CPU, as long as all the other README examples together. The harness "
    "it calls is tested in tests/algorithms/test_ppo.py.",
}


def _source(line: int, source: str) -> str:
    """`source` with each NOT_RUN line replaced by `pass` (same indentation, same line count)."""
    lines = source.splitlines()
    for i, text in enumerate(lines):
        if any(marker in text for marker in NOT_RUN):
            lines[i] = text[: len(text) - len(text.lstrip())] + "pass  # not run here: see NOT_RUN"
    return "\n" * (line - 1) + "\n".join(lines) + "\n"  # line numbers as in README.md


@pytest.fixture(scope="module")
def readme(tmp_path_factory):
    """The shared namespace and the indices of the blocks already run, in a temp cwd."""
    cwd = os.getcwd()
    os.chdir(tmp_path_factory.mktemp("readme"))
    try:
        yield {"namespace": {"__name__": "readme"}, "done": set(), "failed": set()}
    finally:
        os.chdir(cwd)


def _run(readme: dict, index: int) -> None:
    for earlier in range(index):
        if earlier in readme["failed"]:
            pytest.fail(f"README block {earlier + 1} (line {BLOCKS[earlier][0]}) failed; block {index + 1} needs it")
        if earlier not in readme["done"]:
            _run(readme, earlier)
    line, source = BLOCKS[index]
    code = compile(_source(line, source), str(README), "exec")
    try:
        exec(code, readme["namespace"])
    except BaseException:
        readme["failed"].add(index)
        raise
    readme["done"].add(index)


def test_readme_has_python_examples():
    assert len(BLOCKS) >= 3, f"expected the README's Python examples, found {len(BLOCKS)} blocks"


@pytest.mark.parametrize("index", range(len(BLOCKS)), ids=[f"line{line}" for line, _ in BLOCKS])
def test_readme_block(readme, index):
    _run(readme, index)


def test_readme_example_changes_a_mass_without_recompiling(readme):
    if 0 not in readme["done"]:
        _run(readme, 0)
    run = readme["namespace"]["run"]  # the first block's jitted rollout, called with two tasks
    assert run._cache_size() == 1, "the heavier task recompiled the README's first example"


@pytest.mark.parametrize("marker", sorted(NOT_RUN))
def test_readme_line_not_run(marker):
    found = [line for _, source in BLOCKS for line in source.splitlines() if marker in line]
    assert len(found) == 1, f"NOT_RUN names {marker!r}, which README.md's Python blocks have {len(found)} times"
    pytest.skip(f"README line {found[0].strip()!r} not run: {NOT_RUN[marker]}")
