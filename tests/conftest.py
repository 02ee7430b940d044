"""Test-session settings. XLA's backend optimizations triple the compile time of MJX
graphs on the CPU and buy nothing for the few steps a test runs."""

import os

os.environ.setdefault("MJZOO_COMPILE_CACHE", "0")  # tests compile afresh: no cache shared between runs
os.environ["XLA_FLAGS"] = " ".join(
    filter(None, [os.environ.get("XLA_FLAGS", ""), "--xla_backend_optimization_level=0"])
)


import jax  # noqa: E402
import pytest  # noqa: E402


@pytest.fixture(autouse=True, scope="module")
def _free_compiled_code():
    """Drops each test module's compiled executables when it ends: a whole-suite process
    otherwise keeps hundreds of MJX executables alive (one run aborted inside LLVM)."""
    yield
    jax.clear_caches()
