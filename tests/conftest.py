"""Test-session settings. XLA's backend optimizations triple the compile time of MJX
graphs on the CPU and buy nothing for the few steps a test runs; XLA's newer (MLIR)
fusion emitters compile an MJX rollout in about 1.5x the time of its classic ones
(check_task's rollout of cartpole_balance under the combinator stack: 44 s of CPU
against 29 s), with the same run time."""

import collections
import os
import shutil
import subprocess
import sys
import tempfile

_CLASSIC_FUSION = "--xla_cpu_use_fusion_emitters=false"
_CLASSIC_FUSION_OK = "MJZOO_TEST_CLASSIC_FUSION"  # the probe's answer, inherited by xdist's workers


def _xla_accepts(flag: str) -> bool:
    """Whether this jaxlib's XLA knows `flag`: XLA aborts the process on a flag it does
    not know, and flags come and go between releases. Asked once per run, in a child."""
    if _CLASSIC_FUSION_OK not in os.environ:
        probe = subprocess.run(
            [sys.executable, "-c", "import jax; jax.numpy.zeros(1).block_until_ready()"],
            env={**os.environ, "XLA_FLAGS": flag, "JAX_PLATFORMS": "cpu"},
            capture_output=True,
            timeout=120,
            check=False,
        )
        os.environ[_CLASSIC_FUSION_OK] = "1" if probe.returncode == 0 else "0"
    return os.environ[_CLASSIC_FUSION_OK] == "1"


os.environ.setdefault("MJZOO_COMPILE_CACHE", "0")  # tests compile afresh: no cache shared between runs
os.environ["XLA_FLAGS"] = " ".join(  # the caller's own XLA_FLAGS last: they win
    filter(
        None,
        [
            "--xla_backend_optimization_level=0",
            _CLASSIC_FUSION if _xla_accepts(_CLASSIC_FUSION) else "",
            os.environ.get("XLA_FLAGS", ""),
        ],
    )
)


import jax  # noqa: E402
import pytest  # noqa: E402

_RUN_CACHE = "MJZOO_TEST_RUN_COMPILE_CACHE"

# The modules that keep a worker busiest, heaviest first: seconds of CPU, the module run
# alone (2026-11-29), or ~ an estimate (its slowest tests in an earlier full run, or its
# docstring's figures). A stale figure only reorders; nothing is skipped. xdist's `--dist loadfile` hands out
# whole modules, by default most tests first: these have 1-38 tests, so most of them
# came last, where one worker ran the tail of minutes-long modules while the other sat
# idle. Handed out first, they run while the short modules fill in behind them.
HEAVY_FIRST = (
    "tests/conformance/test_conformance.py",  # 419
    "tests/algorithms/test_planners.py",  # 319
    "tests/algorithms/test_ppo.py",  # ~289 (the resume test on the block since)
    "tests/test_docs.py",  # 279
    "tests/conformance/test_conformance_locomotion.py",  # ~250
    "tests/algorithms/test_ppo_learning.py",  # ~246 (the GRU's run shortened since)
    "tests/harness/test_distributed.py",  # ~180
    "tests/conformance/test_conformance_locomotion_stacked.py",  # ~165
    "tests/algorithms/test_amp.py",  # ~135 (the two-device check on the block since)
    "tests/learning/test_a2c_doc.py",  # ~120 (one evaluation since)
    "tests/envs/test_locomotion.py",  # ~120
    "tests/interop/test_joystick_export.py",  # 115
    "tests/envs/test_robot_joystick.py",  # ~105
    "tests/algorithms/test_amp_learning.py",  # ~96
    "tests/algorithms/test_sweeps.py",  # ~57 (on the block since)
)


def pytest_configure(config):
    """JAX's persistent compilation cache, for this run only: a temporary directory the
    run's first process makes (xdist's workers inherit its name) and removes at the end.
    `_free_compiled_code` drops every executable after each module, and later modules
    compile many of the same programs again (eager array ops, an env's reset, a task's
    rollout): pendulum's and cartpole's check_task again after `jax.clear_caches()` cost
    15 s of CPU from this cache, 29 s compiled afresh. Each process writes a directory of
    its own, as JAX writes an entry without a lock. Sharing one under JAX's lock (which a
    size limit turns on) cost more than it saved: every write then reads every entry's
    access time to decide on eviction, quadratic in a run's thousands of entries
    (tests/catalog alone writes 725; CI: 2507 s to 3861 s; an idle run 2165 s without).
    Small programs count too (no minimum)."""
    if _RUN_CACHE not in os.environ:  # the run's controller, or a run without xdist
        os.environ[_RUN_CACHE] = tempfile.mkdtemp(prefix="mjzoo-test-jax-cache-")
        config._mjzoo_run_cache = os.environ[_RUN_CACHE]
    if getattr(config.option, "loadscopereorder", False):  # HEAVY_FIRST's order, not xdist's count
        config.option.loadscopereorder = False
    worker = getattr(config, "workerinput", {}).get("workerid", "main")
    jax.config.update("jax_compilation_cache_dir", os.path.join(os.environ[_RUN_CACHE], worker))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)


def pytest_collection_modifyitems(config, items):
    """HEAVY_FIRST's modules first, then the rest most tests first (xdist's own order), each
    module's tests in their own order."""
    rank = {path: i for i, path in enumerate(HEAVY_FIRST)}
    module = {id(item): item.nodeid.split("::")[0] for item in items}
    count = collections.Counter(module.values())
    items.sort(key=lambda item: (rank.get(module[id(item)], len(rank)), -count[module[id(item)]]))


def pytest_unconfigure(config):
    run_cache = getattr(config, "_mjzoo_run_cache", None)
    if run_cache:
        shutil.rmtree(run_cache, ignore_errors=True)
        os.environ.pop(_RUN_CACHE, None)


@pytest.fixture(autouse=True, scope="module")
def _free_compiled_code():
    """Drops each test module's compiled executables when it ends: a whole-suite process
    otherwise keeps hundreds of MJX executables alive (one run aborted inside LLVM)."""
    yield
    jax.clear_caches()


@pytest.fixture
def cpu_devices_env():
    """``env(n) -> dict``: the environment of a child process with `n` host CPU devices,
    the suite's XLA flags kept (a child given the device count alone compiles at -O3 with
    the MLIR emitters: AMP's two-device test took 102 s so, 58 s with the flags)."""

    def env(n: int = 2) -> dict[str, str]:
        flags = f"{os.environ.get('XLA_FLAGS', '')} --xla_force_host_platform_device_count={n}"
        return {**os.environ, "XLA_FLAGS": flags, "JAX_PLATFORMS": "cpu"}

    return env
