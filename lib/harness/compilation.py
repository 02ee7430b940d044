"""Starting fast: JAX's persistent compilation cache, and compiling ahead in the background.

A run spends longer compiling than learning unless compiles are kept: `enable_cache`
points JAX's persistent cache at the user's cache directory (the CLI and `train` do so
by default on a CPU; on a GPU when asked, see `enable_cache`), so a second launch of
the same run loads its executables from disk.
`compile_ahead` compiles a jitted function for given arguments on a background thread
(XLA releases the GIL while it compiles), so the evaluation compiles while the first
training chunk runs, and the chunk while init compiles; the later call finds the
executable already built.

    compilation.enable_cache()                        # ~/.cache/mjzoo/jax (XDG_CACHE_HOME), on a CPU
    MJZOO_COMPILE_CACHE=0 mjzoo train ...             # off;  =/some/dir: there (a GPU too)
"""

from __future__ import annotations

import os
import sys
import threading
import warnings
from collections.abc import Callable
from pathlib import Path
from typing import Any

import jax
from jax.experimental.compilation_cache import compilation_cache

__all__ = ["cache_directory", "compile_ahead", "enable_cache"]

_OFF = ("0", "off", "false", "no", "")


def cache_directory() -> Path | None:
    """Where mjzoo keeps compiled executables: ``$MJZOO_COMPILE_CACHE`` if set (a path,
    or 0/off/false/no for none), else ``$XDG_CACHE_HOME/mjzoo/jax`` (``~/.cache/mjzoo/jax``)."""
    chosen = os.environ.get("MJZOO_COMPILE_CACHE")
    if chosen is not None:
        return None if chosen.strip().lower() in _OFF else Path(chosen).expanduser()
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "mjzoo" / "jax"


def enable_cache(directory: str | Path | None = None) -> Path | None:
    """Turns JAX's persistent compilation cache on in `directory` (default
    `cache_directory()`), for every compile that takes over a second; returns the
    directory in use, or None when it stays off.

    Off by default on an accelerator: there, with JAX 0.11, programs run from the cache
    crashed now and then (CUDA_ERROR_ILLEGAL_INSTRUCTION on an H100, in mjzoo's and in
    Brax's programs alike), so a GPU run uses it only when `directory` or
    ``$MJZOO_COMPILE_CACHE`` names one. A cache directory the user already gave JAX
    (``JAX_COMPILATION_CACHE_DIR`` or ``jax.config``) is kept as it is. Safe to call more
    than once; it initializes JAX's backends (call `jax.distributed.initialize` first)."""
    current = jax.config.jax_compilation_cache_dir
    if current:
        return Path(current)
    chosen = directory is not None or os.environ.get("MJZOO_COMPILE_CACHE") is not None
    if not chosen and jax.default_backend() != "cpu":
        return None
    directory = Path(directory).expanduser() if directory is not None else cache_directory()
    if directory is None:
        return None
    try:
        directory.mkdir(parents=True, exist_ok=True)
    except OSError as error:  # a read-only home: run uncached rather than not at all
        message = (
            f"compilation cache: cannot create {directory} ({error.strerror}); running without it "
            "(set MJZOO_COMPILE_CACHE to a writable directory, or 0 to silence this)"
        )
        warnings.warn(message, stacklevel=2)
        return None
    compilation_cache.set_cache_dir(str(directory))
    # Executables only, not XLA's own caches (autotuning results, kernels): with two
    # compiles at once (`compile_ahead`) sharing them, programs crashed on an H100.
    jax.config.update("jax_persistent_cache_enable_xla_caches", "none")
    return directory


def compile_ahead(function: Callable, *args: Any, background: bool = True, **kwargs: Any) -> threading.Thread | None:
    """Starts compiling the jitted `function` for `args` (arrays or `jax.ShapeDtypeStruct`s
    with the shardings of the later call; static arguments as in that call) on a daemon
    thread, and returns it. A later call of `function` with matching arguments reuses
    the executable (it still traces, which is quick). A failure here is ignored: the
    later call compiles for itself and reports any error where it belongs.
    `background=False` compiles on this thread now and returns None: for programs that
    must not overlap a compile (`overlaps_safely`).

    `function` may instead be a `jax.stages.Lowered` (no arguments), traced and lowered
    by the caller: tracing holds the GIL, so where the caller goes on to trace something
    else, tracing on two threads at once would only slow both."""

    def work() -> None:
        try:
            lowered = function if isinstance(function, jax.stages.Lowered) else function.lower(*args, **kwargs)
            lowered.compile()
        except Exception:  # noqa: BLE001 (the real call raises it with its own context)
            pass

    if not background:
        work()
        return None
    thread = threading.Thread(target=work, name=f"compile-ahead-{getattr(function, '__name__', 'fn')}", daemon=True)
    thread.start()
    return thread


def described(tree: Any) -> Any:
    """`tree` with its arrays replaced by `jax.ShapeDtypeStruct`s of their shapes,
    shardings and weak types: what `compile_ahead` compiles for, kept while the arrays
    themselves are donated."""

    def like(x: Any) -> Any:
        if not isinstance(x, jax.Array):
            return x
        return jax.ShapeDtypeStruct(x.shape, x.dtype, sharding=x.sharding, weak_type=x.aval.weak_type)

    return jax.tree.map(like, tree)


def overlaps_safely(model: Any) -> bool:
    """Whether programs on `model`'s physics may run while another thread traces or
    compiles. Not MuJoCo Warp's on a GPU: Warp's runtime is not thread-safe while it
    captures its CUDA graphs (a program's first run), and with the chunk compiling
    ahead a humanoid run on an H200 failed in its first steps ("Graph creation error",
    with XLA's autotuner finding its red zone overwritten)."""
    impl = getattr(getattr(model, "impl", None), "value", None)
    return impl != "warp" or jax.default_backend() == "cpu"


def still_compiling(thread: threading.Thread | None, grace: float) -> bool:
    """Whether a `compile_ahead` thread is still at work after waiting up to `grace`
    seconds for it (None: nothing compiles)."""
    if thread is None:
        return False
    thread.join(grace)
    return thread.is_alive()


def wait(thread: threading.Thread | None, what: str, patience: float = 30.0) -> None:
    """Joins a `compile_ahead` thread (None: nothing to wait for), saying on stderr what
    the run waits for once that takes over `patience` seconds: a paused progress bar
    would not show why (a cold compile takes minutes on a GPU)."""
    if thread is None:
        return
    thread.join(patience)
    if thread.is_alive():
        print(f"{what}: still compiling after {patience:.0f} s; waiting for it", file=sys.stderr, flush=True)
        thread.join()
