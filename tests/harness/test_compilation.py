"""Starting fast: where the persistent cache lives, and compiling ahead on a thread."""

from __future__ import annotations

import subprocess
import sys
import threading
import time
import types
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from jax import monitoring

from mjzoo import learning
from mjzoo.harness import compilation

_compiles: list[str] = []
_threads: list[str] = []  # the threads that compiled them


def _compiled(name: str, *_, **__) -> None:
    if name.endswith("backend_compile_duration"):
        _compiles.append(name)
        _threads.append(threading.current_thread().name)


monitoring.register_event_duration_secs_listener(_compiled)


@pytest.mark.parametrize(
    "environment, expected",
    [
        ({"MJZOO_COMPILE_CACHE": "/tmp/here"}, Path("/tmp/here")),
        ({"MJZOO_COMPILE_CACHE": "0"}, None),
        ({"MJZOO_COMPILE_CACHE": "off"}, None),
        ({"XDG_CACHE_HOME": "/xdg"}, Path("/xdg/mjzoo/jax")),
        ({"HOME": "/home/u"}, Path("/home/u/.cache/mjzoo/jax")),
    ],
)
def test_the_cache_directory_follows_the_environment(monkeypatch, environment, expected):
    for name in ("MJZOO_COMPILE_CACHE", "XDG_CACHE_HOME"):
        monkeypatch.delenv(name, raising=False)
    for name, value in environment.items():
        monkeypatch.setenv(name, value)
    assert compilation.cache_directory() == expected


@pytest.fixture
def cache_dir_option():
    """jax's cache directory option, restored afterwards (these tests compile nothing)."""
    before = jax.config.jax_compilation_cache_dir
    yield lambda value: jax.config.update("jax_compilation_cache_dir", value)
    jax.config.update("jax_compilation_cache_dir", before)


def test_a_cache_the_user_gave_jax_is_kept(cache_dir_option, tmp_path):
    cache_dir_option(str(tmp_path / "theirs"))
    assert compilation.enable_cache(tmp_path / "ours") == tmp_path / "theirs"
    assert not (tmp_path / "ours").exists()


def test_turned_off_it_enables_nothing(cache_dir_option, monkeypatch):
    cache_dir_option(None)
    monkeypatch.setenv("MJZOO_COMPILE_CACHE", "0")
    assert compilation.enable_cache() is None


def test_on_an_accelerator_it_is_on_only_when_asked(cache_dir_option, monkeypatch, tmp_path):
    cache_dir_option(None)
    monkeypatch.delenv("MJZOO_COMPILE_CACHE", raising=False)
    monkeypatch.setattr(jax, "default_backend", lambda: "gpu")
    assert compilation.enable_cache() is None
    monkeypatch.setenv("MJZOO_COMPILE_CACHE", str(tmp_path / "asked"))
    assert compilation.enable_cache() == tmp_path / "asked"
    assert jax.config.jax_persistent_cache_enable_xla_caches == "none"


def test_compiling_ahead_leaves_nothing_to_compile_for_the_call():
    function = jax.jit(lambda x, n: jnp.cumsum(jnp.sin(x)) * n, static_argnums=1)
    x = jnp.arange(5.0)
    compilation.compile_ahead(function, jax.ShapeDtypeStruct(x.shape, x.dtype), 3).join()
    _compiles.clear()
    result = function(x, 3)
    assert _compiles == []  # the thread's executable served the call
    function(x, 4)  # another static argument: a compile of its own
    assert len(_compiles) == 1
    assert jnp.allclose(result, jnp.cumsum(jnp.sin(x)) * 3)


def test_a_function_lowered_by_the_caller_compiles_ahead_for_the_call():
    """The training chunk is traced on the caller's thread (tracing holds the GIL) and only
    compiled on the thread."""
    function = jax.jit(lambda x: jnp.tanh(x) @ x.T)
    x = jnp.ones((3, 2))
    compilation.compile_ahead(function.lower(jax.ShapeDtypeStruct(x.shape, x.dtype))).join()
    _compiles.clear()
    result = function(x)
    assert _compiles == []
    assert jnp.allclose(result, jnp.full((3, 3), 2 * np.tanh(1.0)))


def test_compiling_now_instead_of_ahead_also_serves_the_call():
    """`background=False` (Warp's GPU physics, `overlaps_safely`) compiles on this thread
    before returning: nothing left to compile, and nothing running beside the call."""
    function = jax.jit(lambda x: jnp.cos(x) * 2)
    x = jnp.arange(3.0)
    assert compilation.compile_ahead(function, jax.ShapeDtypeStruct(x.shape, x.dtype), background=False) is None
    _compiles.clear()
    result = function(x)
    assert _compiles == []
    assert jnp.allclose(result, jnp.cos(x) * 2)


def test_only_warp_physics_on_a_gpu_must_not_overlap_a_compile(monkeypatch):
    warp, mjx_jax = (types.SimpleNamespace(impl=types.SimpleNamespace(value=v)) for v in ("warp", "jax"))
    assert compilation.overlaps_safely(warp) and compilation.overlaps_safely(mjx_jax)  # on this CPU
    monkeypatch.setattr(jax, "default_backend", lambda: "gpu")
    assert not compilation.overlaps_safely(warp)
    assert compilation.overlaps_safely(mjx_jax) and compilation.overlaps_safely(None)  # a task without a Model


def test_waiting_long_for_a_compile_says_what_for(capsys):
    slow, quick = threading.Thread(target=time.sleep, args=(0.3,)), threading.Thread(target=time.sleep, args=(0.0,))
    slow.start(), quick.start()
    compilation.wait(slow, "training: the evaluation", patience=0.05)
    assert not slow.is_alive()  # waited to the end, not only `patience`
    assert capsys.readouterr().err == "training: the evaluation: still compiling after 0 s; waiting for it\n"
    compilation.wait(quick, "training: the chunk", patience=5.0)
    compilation.wait(None, "nothing")
    assert capsys.readouterr().err == ""


def test_a_failure_ahead_is_left_to_the_call():
    function = jax.jit(lambda x: x @ x)
    compilation.compile_ahead(function, jax.ShapeDtypeStruct((2, 3), jnp.float32)).join()  # no exception here
    with pytest.raises(TypeError):
        function(jnp.ones((2, 3)))


def test_the_train_state_is_owned_by_one_program_whatever_its_shapes():
    """Training copies its initial state so that each leaf owns its buffer (the chunk donates
    them): one compile for the tree, not one per leaf shape, and aliased leaves part."""
    from mjzoo.harness import training

    zeros = jnp.zeros(7)
    tree = {"a": zeros, "b": zeros, "c": jnp.ones((3, 7)), "d": jnp.arange(11), "key": jax.random.key(0)}
    _compiles.clear()
    owned = training._owned(tree)
    assert len(_compiles) == 1
    pointers = [x.unsafe_buffer_pointer() for x in jax.tree.leaves(jax.random.key_data(owned.pop("key")))]
    pointers += [x.unsafe_buffer_pointer() for x in jax.tree.leaves(owned)]
    assert len(set(pointers)) == len(pointers) == 5
    assert pointers[1] != zeros.unsafe_buffer_pointer()
    jax.tree.map(
        lambda x, y: jnp.array_equal(x, y) or pytest.fail("a copy differs"), owned, {k: tree[k] for k in owned}
    )


def test_the_chunk_compiled_ahead_from_inits_shapes_serves_every_chunk(monkeypatch):
    """`training.run` compiles its chunk on a thread while init compiles, from the shapes
    init will return: the described state (PRNG keys, the device's sharding) must be the
    placed state exactly, or the first chunk compiles again. And init's weakly typed leaf
    (`scale`) is made strong, as the chunk returns it, or the second chunk compiles again
    (Playground's CheetahRun: 49 s of an H100 run)."""

    from mjzoo.harness import devices
    from mjzoo.harness import training
    from tests.harness.test_training import counter

    algorithm = counter(
        num_updates=4,
        init=lambda task, hyperparams, key: {
            "updates": jnp.zeros((), jnp.int32),
            "per_env": jnp.zeros(4),
            "scale": jnp.asarray(1.0),
            "key": key,
        },
        update=lambda task, s: (
            {
                **s,
                "updates": s["updates"] + 1,
                "per_env": s["per_env"] * s["scale"],
                "scale": s["scale"] * task["gain"][0],  # strong, as data.time steps
                "key": jax.random.fold_in(s["key"], 1),
            },
            {},
        ),
    )
    settings = training.Settings(updates_per_chunk=2, eval_count=0, video=False, progress=False)  # chunks of 2
    task, key = {"gain": jnp.ones(3)}, jax.random.key(0)
    monkeypatch.setattr(compilation, "overlaps_safely", lambda model: False)  # as on Warp's GPU physics
    assert training._compile_chunk_ahead(algorithm, task, None, settings, key) is None  # the chunk compiles first
    monkeypatch.undo()
    ahead = training._compile_chunk_ahead(algorithm, task, None, settings, key)
    assert ahead is not None  # one device
    ahead.join()
    state = devices.shard_envs(
        training._owned(training._init_fn(algorithm.init)(task, None, key)), algorithm.per_env_fields
    )
    _compiles.clear()
    state, _ = training._chunk_fn(algorithm.update, 2)(devices.replicate(task), state)
    state, _ = training._chunk_fn(algorithm.update, 2)(devices.replicate(task), state)
    assert _compiles == []
    assert int(state["updates"]) == 4


CHUNK_AHEAD_ON_TWO_DEVICES = """
import dataclasses, types
import jax, jax.numpy as jnp
from jax import monitoring
from mjzoo.harness import devices, training
compiles = []
monitoring.register_event_duration_secs_listener(
    lambda name, *args, **kwargs: compiles.append(name) if name == "/jax/core/compile/backend_compile_duration" else None)
@jax.tree_util.register_dataclass
@dataclasses.dataclass
class State:
    updates: jax.Array
    per_env: jax.Array
    key: jax.Array
algorithm = types.SimpleNamespace(
    per_env_fields=("per_env",),
    num_updates=4,
    init=lambda task, hyperparams, key: State(jnp.zeros((), jnp.int32), jnp.zeros((4, 3)), key),
    update=lambda task, s: (State(s.updates + 1, s.per_env + task["gain"], jax.random.fold_in(s.key, 1)), {}),
)
settings = training.Settings(updates_per_chunk=2, eval_count=0, video=False, progress=False)  # chunks of 2
task, key = {"gain": jnp.ones(3)}, jax.random.key(0)
training._compile_chunk_ahead(algorithm, task, None, settings, key).join()
state = devices.shard_envs(training._owned(training._init_fn(algorithm.init)(task, None, key)), algorithm.per_env_fields)
assert len(state.per_env.addressable_shards) == 2 and state.per_env.addressable_shards[0].data.shape == (2, 3)
compiles.clear()
state, _ = training._chunk_fn(algorithm.update, 2)(devices.replicate(task), state)
assert compiles == [], compiles
print("chunks", int(state.updates))
"""


def test_the_chunk_compiles_ahead_for_the_env_batch_split_over_two_devices(cpu_devices_env):
    """With several devices the chunk is compiled ahead for the shardings `shard_envs`
    gives (`devices.env_shardings`): the call compiles nothing. (It used to compile only
    after init there: on two H200s the first chunk ended 43 s later than on one.)"""
    done = subprocess.run(
        [sys.executable, "-c", CHUNK_AHEAD_ON_TWO_DEVICES],
        env=cpu_devices_env(2),
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr[-3000:]
    assert "chunks 2" in done.stdout


def test_the_evaluation_compiled_ahead_serves_the_first_evaluation():
    """`training.run` traces and compiles the evaluation on a thread while the first chunk
    runs: the first evaluation's call compiles nothing more on the main thread."""
    from mjzoo.harness import training
    from tests.harness.test_training import TASK
    from tests.harness.test_training import counter

    algorithm = counter(
        evaluate=lambda task, s, key, n, steps: learning.Evaluation(
            jnp.full(n, s.per_env.sum() * steps), jnp.zeros(n), None
        )
    )
    during, hooks = _main_thread_compiles_per_evaluation()
    settings = training.Settings(updates_per_chunk=1, eval_every=1, eval_steps=3, video=False, progress=False)
    _, last = training.run(algorithm, TASK, settings, hooks=hooks)
    assert last["eval/return"] == 4 * 2.0 * 3  # four envs at 2.0, times 3 steps
    assert during == [0, 0]


def _main_thread_compiles_per_evaluation(**hooks) -> tuple[list[int], Any]:
    """A list that `training.run`'s evaluations fill with the compiles each made on the
    main thread (from the end of its chunk to its result), and the `training.Hooks`
    (with `hooks`) that fill it."""
    from mjzoo.harness import training

    during, before = [], []
    hooks = training.Hooks(
        on_chunk=lambda updates, metrics: before.append(_threads.count("MainThread")),
        on_evaluation=lambda step, value: during.append(_threads.count("MainThread") - before[-1]),
        **hooks,
    )
    return during, hooks


def test_beside_warp_on_a_gpu_the_evaluation_compiles_alone_before_the_first_chunk(monkeypatch):
    """Warp is not thread-safe while it captures its CUDA graphs (`overlaps_safely`): the
    evaluation then compiles on the main thread, after init has run and before the chunk
    runs, and the chunk is not compiled ahead; the first evaluation still finds it."""
    from mjzoo.harness import training
    from tests.harness.test_training import TASK
    from tests.harness.test_training import counter

    algorithm = counter(
        evaluate=lambda task, s, key, n, steps: learning.Evaluation(
            jnp.full(n, s.per_env.sum() * steps), jnp.zeros(n), None
        )
    )
    monkeypatch.setattr(compilation, "overlaps_safely", lambda model: False)
    events = []

    def compile_evaluation(*args, **kwargs):
        ahead = compilation.compile_ahead(*args, **kwargs)
        events.append(("evaluation compiled", threading.current_thread().name, ahead))
        return ahead

    during, hooks = _main_thread_compiles_per_evaluation(compile_evaluation=compile_evaluation)
    chunk_ran = hooks.on_chunk
    hooks = hooks._replace(on_chunk=lambda *args: events.append(("chunk", None, None)) or chunk_ran(*args))
    settings = training.Settings(updates_per_chunk=1, eval_every=1, eval_steps=3, video=False, progress=False)
    _, last = training.run(algorithm, TASK, settings, hooks=hooks)
    assert events[:2] == [("evaluation compiled", "MainThread", None), ("chunk", None, None)]
    assert last["eval/return"] == 4 * 2.0 * 3 and during == [0, 0]


@pytest.mark.parametrize("cold", [True, False])
def test_the_evaluation_compiles_beside_a_cold_chunk_and_after_a_cached_one(cold):
    """A chunk still compiling `COLD_GRACE_S` after init is a cold compile: the
    evaluation's compile starts then, beside it, not once the chunk runs. A chunk done
    by then (loaded from the cache) runs first, and the evaluation compiles while it does.
    Driven by `Hooks` alone: a chunk compile that says it is still at work at the grace
    check (cold) or that it is done (cached)."""
    from mjzoo.harness import training
    from tests.harness.test_training import TASK
    from tests.harness.test_training import counter

    algorithm = counter(
        evaluate=lambda task, s, key, n, steps: learning.Evaluation(
            jnp.full(n, s.per_env.sum() * steps), jnp.zeros(n), None
        )
    )
    events, handles = [], []

    class ChunkCompile:  # the real compile; when cold, alive still at the first join (the grace check)
        def __init__(self, lowered):
            self.real, self.joins = compilation.compile_ahead(lowered), 0

        def join(self, timeout=None):
            self.joins += 1
            if self.real is not None:
                self.real.join(timeout)

        def is_alive(self):
            return (cold and self.joins < 2) or (self.real is not None and self.real.is_alive())

    def compile_chunk(lowered):
        handles.append(ChunkCompile(lowered))
        return handles[-1]

    def compile_evaluation(*args, **kwargs):
        events.append(("evaluation", handles[0].is_alive()))
        return compilation.compile_ahead(*args, **kwargs)

    hooks = training.Hooks(
        compile_chunk=compile_chunk,
        compile_evaluation=compile_evaluation,
        on_chunk=lambda updates, metrics: events.append(("chunk", updates)),
    )
    settings = training.Settings(updates_per_chunk=1, eval_every=1, eval_steps=3, video=False, progress=False)
    _, last = training.run(algorithm, TASK, settings, hooks=hooks)
    assert len(handles) == 1 and handles[0].joins >= 2  # the grace check, then the wait for it
    assert events == [("evaluation", cold), ("chunk", 1), ("chunk", 2)]  # one evaluation compile, beside if cold
    assert last["eval/return"] == 4 * 2.0 * 3
