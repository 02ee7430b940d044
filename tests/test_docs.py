"""The documentation runs and holds together: every ```python block of README.md and the
docs pages in DOCS runs as written; the README stays short; every link points at a file
that exists in the repository; and the generated pages (docs/benchmarks.md, docs/cli.md,
docs/api.md) are their scripts' output.

Each ```python block is one test. A document's blocks share one namespace and run in
the order the document reads (the README's PPO block trains the task its first block
composed), so a test first runs any earlier block of its document that has not run yet:
`-k` may pick any one of them. They run in a temporary working directory, so nothing
they write lands in the repository. Tracebacks point at the document's own lines.

A few lines are not run, for time alone: see NOT_RUN. Each shows as a skipped test with
its reason (pytest -ra), and the test fails if its document no longer has that line. A
few run smaller than printed (SHRUNK: the same code on fewer steps), checked alike.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
DOCS = (
    "README.md",
    "docs/concepts.md",
    "docs/training.md",
    "docs/planning.md",
    "docs/interop.md",
    "docs/own-task.md",
    "docs/sweeps.md",
    "docs/robots.md",
    "docs/motion.md",
    "docs/catalog.md",
)
README_MAX_LINES = 200
_FENCE = re.compile(r"^```python\n(.*?)^```", re.S | re.M)


def _blocks(doc: str) -> list[tuple[int, str]]:
    """(first line number in `doc`, source) of each ```python block."""
    text = (ROOT / doc).read_text()
    return [(text.count("\n", 0, m.start(1)) + 1, m.group(1)) for m in _FENCE.finditer(text)]


BLOCKS = {doc: _blocks(doc) for doc in DOCS}

_PPO_TRAIN = (
    "training.run compiles two more programs (a chunk of updates and the evaluation) and runs them: "
    "minutes on a 2-core CPU. It is tested in tests/algorithms/test_ppo.py."
)
_WHOLE_RUN = (
    "ppo.train's whole run compiles its own program (init and a scan of updates): minutes on a "
    "2-core CPU. tests/algorithms/test_sweeps.py runs it, vmapped and alone."
)
_EXPORTED = (
    "needs a trained run's exported policy (runs/cb): tests/interop/test_export.py exports one and "
    "runs export.load, sim2sim.run_in_mujoco and sim2sim.replay on it."
)
# Lines the block tests leave out, by document (matched by what the line contains), and why.
NOT_RUN = {
    "README.md": {},
    "docs/concepts.md": {},
    "docs/planning.md": {},
    "docs/catalog.md": {},
    "docs/training.md": {
        "training.run(ppo.make": _PPO_TRAIN,
        "whole_run(config, task, hyperparams, jax.random.key(0))": _WHOLE_RUN,
        "training.run(algorithm, pole": _PPO_TRAIN.replace(
            "tests/algorithms/test_ppo.py", "tests/algorithms/test_amp.py"
        ),
    },
    "docs/interop.md": {
        **dict.fromkeys(
            ('export.load("runs/cb', "act(obs)", 'run_in_mujoco("runs/cb', "sim2sim.replay(task, start"), _EXPORTED
        ),
    },
    "docs/own-task.md": {"training.run(ppo.make": _PPO_TRAIN},
    "docs/sweeps.md": {},
    "docs/robots.md": {},
    "docs/motion.md": {},
}
# Lines run smaller than printed, by document: {what the line contains: (its replacement there, why)}.
SHRUNK = {
    **{doc: {} for doc in DOCS},
    "docs/concepts.md": {
        "state, key, 100)[1]": (
            "state, key, 20)[1]",
            "20 steps, not 100: the rollout compiles the same, and the page's 64 x 100 steps, run for two "
            "masses, cost ~9 s more of -O0 CPU on a 2-core CPU",
        ),
    },
    "docs/sweeps.md": {
        "total_steps=327_680": (
            "total_steps=2 * 64 * 32",
            "two updates, not 160: the 12 whole runs of 327k steps take too long for the suite on a 2-core CPU",
        ),
        "num_replans=50": (
            "num_replans=4",
            "4 replans, not 50: the six vmapped closed loops compile the same and run 12x shorter on a 2-core CPU",
        ),
    },
}
MIN_BLOCKS = {doc: 1 for doc in DOCS} | {"docs/training.md": 3, "docs/own-task.md": 3, "docs/sweeps.md": 2}


def _source(doc: str, line: int, source: str) -> str:
    """`source` with each NOT_RUN line replaced by `pass` and each SHRUNK marker by its
    replacement (same indentation, same line count)."""
    lines = source.splitlines()
    for i, text in enumerate(lines):
        if any(marker in text for marker in NOT_RUN[doc]):
            lines[i] = text[: len(text) - len(text.lstrip())] + "pass  # not run here: see NOT_RUN"
        for marker, (replacement, _) in SHRUNK[doc].items():
            lines[i] = lines[i].replace(marker, replacement)
    return "\n" * (line - 1) + "\n".join(lines) + "\n"  # line numbers as in the document


@pytest.fixture(scope="module")
def docs(tmp_path_factory):
    """Per document: the shared namespace and the indices of the blocks already run, in a temp cwd."""
    cwd = os.getcwd()
    os.chdir(tmp_path_factory.mktemp("docs"))
    try:
        yield {
            doc: {"namespace": {"__name__": Path(doc).stem.replace("-", "_")}, "done": set(), "failed": set()}
            for doc in DOCS
        }
    finally:
        os.chdir(cwd)


def _run(docs: dict, doc: str, index: int) -> dict:
    """Runs block `index` of `doc` (and the earlier ones first); returns the document's namespace."""
    state = docs[doc]
    for earlier in range(index):
        if earlier in state["failed"]:
            line = BLOCKS[doc][earlier][0]
            pytest.fail(f"{doc} block {earlier + 1} (line {line}) failed; block {index + 1} needs it")
        if earlier not in state["done"]:
            _run(docs, doc, earlier)
    if index not in state["done"]:
        line, source = BLOCKS[doc][index]
        code = compile(_source(doc, line, source), str(ROOT / doc), "exec")
        try:
            exec(code, state["namespace"])
        except BaseException:
            state["failed"].add(index)
            raise
        state["done"].add(index)
    return state["namespace"]


@pytest.mark.parametrize("doc", DOCS)
def test_docs_have_python_examples(doc):
    assert len(BLOCKS[doc]) >= MIN_BLOCKS[doc], f"expected {doc}'s Python examples, found {len(BLOCKS[doc])} blocks"


@pytest.mark.parametrize(
    "doc, index",
    [(doc, i) for doc in DOCS for i in range(len(BLOCKS[doc]))],
    ids=[f"{doc}:line{line}" for doc in DOCS for line, _ in BLOCKS[doc]],
)
def test_doc_block(docs, doc, index):
    _run(docs, doc, index)


def test_concepts_example_changes_a_mass_without_recompiling(docs):
    run = _run(docs, "docs/concepts.md", 0)["run"]  # the page's jitted rollout, called with two tasks
    assert run._cache_size() == 1, "the heavier task recompiled docs/concepts.md's example"


def test_readme_example_plans_the_heavier_pendulum_without_recompiling(docs):
    """The README's closed loop swings the pendulum up, and its heavier task reuses the
    compiled program: one more mass compiles nothing either."""
    namespace = _run(docs, "README.md", 0)
    angle = namespace["mjzoo"].catalog.wrap_angle(namespace["result"].states.data.qpos[-1, 0])
    assert abs(float(angle)) < 0.3, f"the README's MPPI left the heavier pendulum {float(angle):.2f} rad from upright"
    run, task = namespace["closed_loop"].run, namespace["task"]
    compiled = run._cache_size()
    lighter = task.replace(model=task.model.replace(body_mass=task.model.body_mass * 0.9))
    args = namespace["mppi"], namespace["config"], lighter, lighter, namespace["start"], namespace["key"], 150
    run(*args, replan_every=2, hyperparams=namespace["hyperparams"])
    assert run._cache_size() == compiled, "a task with another mass compiled the README's closed loop again"


def test_readme_is_short():
    lines = (ROOT / "README.md").read_text().count("\n")
    assert lines <= README_MAX_LINES, (
        f"README.md has {lines} lines; keep it to {README_MAX_LINES} and move the rest to docs/"
    )


_LINK = re.compile(r"!?\[[^\]]*\]\(([^)\s]+)(?:\s+\"[^\"]*\")?\)")


def _pages() -> list[Path]:
    return [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


@pytest.mark.parametrize("page", _pages(), ids=lambda p: p.relative_to(ROOT).as_posix())
def test_links_point_at_files_in_the_repository(page):
    """Every relative link and image of README.md and docs/*.md names a file or folder
    that exists inside the repository (anchors and web addresses are not checked)."""
    broken = []
    for target in _LINK.findall(page.read_text()):
        if re.match(r"[a-z]+:", target) or target.startswith("#"):
            continue
        path = (page.parent / target.split("#")[0]).resolve()
        if not path.is_relative_to(ROOT) or not path.exists():
            broken.append(target)
    assert not broken, f"{page.relative_to(ROOT)} links to files not in the repository: {broken}"


def test_own_task_reacher_is_reached_by_mppi(docs):
    """The MPPI loop of docs/own-task.md brings the fingertip to the goal it drew."""
    index = next(i for i, (_, source) in enumerate(BLOCKS["docs/own-task.md"]) if "mppi.plan" in source)
    namespace = _run(docs, "docs/own-task.md", index)
    start, final = namespace["start_distance"], namespace["final_distance"]
    assert final < 0.03 and final < start / 3, f"MPPI left the fingertip {final:.3f} m from the goal ({start:.3f} m)"


@pytest.mark.parametrize("doc, marker", [(doc, marker) for doc in DOCS for marker in sorted(NOT_RUN[doc])])
def test_doc_line_not_run(doc, marker):
    found = [line for _, source in BLOCKS[doc] for line in source.splitlines() if marker in line]
    assert len(found) == 1, f"NOT_RUN names {marker!r}, which {doc}'s Python blocks have {len(found)} times"
    pytest.skip(f"{doc} line {found[0].strip()!r} not run: {NOT_RUN[doc][marker]}")


@pytest.mark.parametrize("doc, marker", [(doc, marker) for doc in DOCS for marker in sorted(SHRUNK[doc])])
def test_doc_line_shrunk(doc, marker):
    found = [line for _, source in BLOCKS[doc] for line in source.splitlines() if marker in line]
    assert len(found) == 1, f"SHRUNK names {marker!r}, which {doc}'s Python blocks have {len(found)} times"
    pytest.skip(f"{doc} runs {marker!r} as {SHRUNK[doc][marker][0]!r}: {SHRUNK[doc][marker][1]}")


def test_sweeps_page_draws_every_rate_and_seed(docs):
    """docs/sweeps.md's vmapped sweep gives [rate, seed, update] curves and a PNG of them."""
    namespace = _run(docs, "docs/sweeps.md", len(BLOCKS["docs/sweeps.md"]) - 1)
    assert namespace["returns"].shape == (4, 3, namespace["config"].num_updates)
    assert namespace["states"].hyperparams.learning_rate.shape == (4, 3)
    assert Path("sweep.png").stat().st_size > 10_000  # in the test's temporary working directory


@pytest.mark.parametrize(
    "script",
    [
        "benchmarks/report.py",  # docs/benchmarks.md, from benchmarks/results/
        "scripts/cli_reference.py",  # docs/cli.md, from the parsers of `mjzoo`'s commands
        "scripts/api_reference.py",  # docs/api.md, from the modules' __all__ and docstrings
    ],
)
def test_generated_page_is_its_scripts_output(script):
    """Each generated page is its script's output: a measurement, flag or public name
    committed without regenerating the page, or a hand edit, fails here."""
    out = subprocess.run([sys.executable, str(ROOT / script), "--check"], capture_output=True, text=True)
    assert out.returncode == 0, out.stderr
