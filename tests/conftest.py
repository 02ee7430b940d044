"""Test-session settings. XLA's backend optimizations triple the compile time of MJX
graphs on the CPU and buy nothing for the few steps a test runs."""

import os

os.environ["XLA_FLAGS"] = " ".join(
    filter(None, [os.environ.get("XLA_FLAGS", ""), "--xla_backend_optimization_level=0"])
)
