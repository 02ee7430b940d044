"""Checkpoints: exact round trips of mixed pytrees, pruning, crash safety, clear errors."""

from __future__ import annotations

import dataclasses
import subprocess
import sys

import jax
import jax.numpy as jnp
import numpy as np
import orbax.checkpoint as ocp
import pytest

from mjzoo.harness import checkpoints


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class Inner:
    key: jax.Array
    count: jax.Array


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True)
class TrainState:
    params: dict
    inner: Inner
    done: jax.Array
    host: np.ndarray
    update: int
    lr: float


def make_state(seed: int) -> TrainState:
    key = jax.random.key(seed)
    k1, k2 = jax.random.split(key)
    return TrainState(
        params={
            "w": jax.random.normal(k1, (3, 4)),
            "layers": [jnp.arange(seed, seed + 2, dtype=jnp.int32)],
            "scale": np.float32(seed) / 2,
            "flag": seed % 2 == 1,
        },
        inner=Inner(key=jax.random.split(k2, 5), count=jnp.asarray(seed, jnp.uint8)),
        done=jnp.asarray([True, False, seed % 2 == 0]),
        host=np.full((2,), seed, np.int64),
        update=seed * 10,
        lr=0.5 + seed,
    )


def assert_identical(a, b) -> None:
    """Same structure, leaf types, dtypes, key implementations and bit-exact values."""
    assert jax.tree_util.tree_structure(a) == jax.tree_util.tree_structure(b)
    for x, y in zip(jax.tree_util.tree_leaves(a), jax.tree_util.tree_leaves(b), strict=True):
        assert type(x) is type(y)
        if isinstance(x, jax.Array) and jnp.issubdtype(x.dtype, jax.dtypes.prng_key):
            assert x.dtype == y.dtype
            x, y = jax.random.key_data(x), jax.random.key_data(y)
        np.testing.assert_array_equal(np.asarray(x), np.asarray(y), strict=True)


def test_round_trip_is_exact_and_keys_stay_usable(tmp_path):
    state = make_state(3)
    path = checkpoints.save(tmp_path, 7, state)
    assert path == tmp_path / "7" and path.is_dir()

    restored = checkpoints.restore(tmp_path, like=make_state(0))

    assert_identical(restored, state)
    assert isinstance(restored, TrainState) and isinstance(restored.inner, Inner)
    # A restored key continues the random stream exactly where the saved one would.
    np.testing.assert_array_equal(
        jax.random.uniform(restored.inner.key[2], (4,)), jax.random.uniform(state.inner.key[2], (4,))
    )


def test_non_default_key_implementation_round_trips(tmp_path):
    state = {"key": jax.random.key(5, impl="rbg")}
    checkpoints.save(tmp_path, 0, state)
    restored = checkpoints.restore(tmp_path, like={"key": jax.random.key(0, impl="rbg")})
    assert_identical(restored, state)


def test_keeps_newest_three_and_restores_any_kept_step(tmp_path):
    for step in [10, 20, 30, 40, 50]:
        checkpoints.save(tmp_path, step, make_state(step))
    assert checkpoints.all_steps(tmp_path) == [30, 40, 50]
    assert checkpoints.latest_step(tmp_path) == 50
    assert_identical(checkpoints.restore(tmp_path, make_state(0)), make_state(50))
    assert_identical(checkpoints.restore(tmp_path, make_state(0), step=30), make_state(30))
    with pytest.raises(FileNotFoundError, match=r"step 10 .*\[30, 40, 50\]"):
        checkpoints.restore(tmp_path, make_state(0), step=10)


def test_keep_parameter(tmp_path):
    for step in range(4):
        checkpoints.save(tmp_path, step, {"x": jnp.ones(2) * step}, keep=1)
    assert checkpoints.all_steps(tmp_path) == [3]


def test_leftover_temporary_directory_is_ignored(tmp_path):
    checkpoints.save(tmp_path, 1, make_state(1))
    # What a crash mid-write of step 2 leaves: a temporary directory with partial data.
    partial = tmp_path / "2.orbax-checkpoint-tmp-1234567" / "arrays"
    partial.mkdir(parents=True)
    (partial / "garbage").write_bytes(b"\x00" * 10)

    assert checkpoints.latest_step(tmp_path) == 1
    assert_identical(checkpoints.restore(tmp_path, make_state(0)), make_state(1))
    checkpoints.save(tmp_path, 3, make_state(3))  # and a later save clears it away
    assert sorted(p.name for p in tmp_path.iterdir()) == ["1", "3"]


def test_write_that_fails_midway_leaves_no_checkpoint(tmp_path, monkeypatch):
    checkpoints.save(tmp_path, 1, make_state(1))

    async def crash(self, x, directory):
        raise OSError("disk full")

    # Orbax writes the arrays, then the tree description: fail at the latter, so the
    # arrays of step 2 are left half-written on disk.
    monkeypatch.setattr(ocp.handlers.JsonCheckpointHandler, "_save_fn", crash)
    with pytest.raises(OSError, match="disk full"):
        checkpoints.save(tmp_path, 2, make_state(2))
    monkeypatch.undo()
    assert any(p.name.startswith("2.") for p in tmp_path.iterdir()), "expected a partial write on disk"

    assert checkpoints.all_steps(tmp_path) == [1]
    assert_identical(checkpoints.restore(tmp_path, make_state(0)), make_state(1))


def test_no_checkpoint_is_a_clear_error(tmp_path):
    assert checkpoints.latest_step(tmp_path / "absent") is None
    assert not (tmp_path / "absent").exists()  # looking must not create it
    with pytest.raises(FileNotFoundError, match="no complete checkpoint"):
        checkpoints.restore(tmp_path / "absent", make_state(0))
    with pytest.raises(FileNotFoundError, match="no complete checkpoint"):
        checkpoints.restore(tmp_path, make_state(0))


def test_mismatched_template_names_what_differs(tmp_path):
    checkpoints.save(tmp_path, 4, {"a": jnp.zeros(3), "b": {"c": jnp.zeros(2, jnp.int32)}, "k": jax.random.key(0)})

    with pytest.raises(ValueError, match=r"not the checkpoint: \['new'\].*not the template: \['b'\]\['c'\]"):
        checkpoints.restore(tmp_path, {"a": jnp.zeros(3), "new": jnp.zeros(2, jnp.int32), "k": jax.random.key(0)})
    with pytest.raises(ValueError, match=r"\['a'\]: checkpoint float32\[3\], template float32\[4\]"):
        checkpoints.restore(tmp_path, {"a": jnp.zeros(4), "b": {"c": jnp.zeros(2, jnp.int32)}, "k": jax.random.key(0)})
    with pytest.raises(ValueError, match=r"\['k'\]: checkpoint key<fry>\[\], template uint32\[2\]"):
        checkpoints.restore(
            tmp_path, {"a": jnp.zeros(3), "b": {"c": jnp.zeros(2, jnp.int32)}, "k": jnp.zeros(2, jnp.uint32)}
        )


def test_bad_arguments(tmp_path):
    checkpoints.save(tmp_path, 1, {"x": jnp.zeros(1)})
    with pytest.raises(FileExistsError, match="step 1"):
        checkpoints.save(tmp_path, 1, {"x": jnp.ones(1)})
    assert_identical(checkpoints.restore(tmp_path, {"x": jnp.ones(1)}), {"x": jnp.zeros(1)})
    checkpoints.save(tmp_path, 5, {"x": jnp.ones(1)})
    with pytest.raises(FileExistsError, match="up to step 5, newer than step 3"):  # would be pruned at once
        checkpoints.save(tmp_path, 3, {"x": jnp.ones(1)})
    assert checkpoints.all_steps(tmp_path) == [1, 5]
    with pytest.raises(ValueError, match="keep"):
        checkpoints.save(tmp_path, 2, {"x": jnp.zeros(1)}, keep=0)
    with pytest.raises(ValueError, match="step"):
        checkpoints.save(tmp_path, -1, {"x": jnp.zeros(1)})
    with pytest.raises(TypeError, match="str"):
        checkpoints.save(tmp_path, 3, {"x": "text"})


SHARDED_SCRIPT = """
import sys
import jax, jax.numpy as jnp, numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec as P
from mjzoo.harness import checkpoints

mesh = Mesh(np.array(jax.devices()), ("envs",))
shard = NamedSharding(mesh, P("envs"))
def state(seed):
    return {"obs": jax.device_put(jnp.arange(8.0) + seed, shard),
            "keys": jax.device_put(jax.random.split(jax.random.key(seed), 4), shard)}
saved = state(1)
checkpoints.save(sys.argv[1], 0, saved)
restored = checkpoints.restore(sys.argv[1], like=state(0))
assert len(jax.devices()) == 2
for name in saved:
    assert restored[name].sharding == shard, (name, restored[name].sharding)
np.testing.assert_array_equal(restored["obs"], saved["obs"])
np.testing.assert_array_equal(jax.random.key_data(restored["keys"]), jax.random.key_data(saved["keys"]))
print("ok")
"""


def test_arrays_sharded_over_devices_restore_onto_the_template_sharding(tmp_path, cpu_devices_env):
    env = cpu_devices_env(2)
    result = subprocess.run(
        [sys.executable, "-c", SHARDED_SCRIPT, str(tmp_path)],
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
        close_fds=False,  # lets Python use posix_spawn: no fork of this multithreaded (JAX) process
    )
    assert result.returncode == 0 and result.stdout.strip() == "ok", result.stderr


def test_empty_arrays_round_trip(tmp_path):
    """mjx.Data holds zero-size arrays (no contacts in a model): they must not stop a save."""
    tree = {"contacts": jnp.zeros((0, 3)), "qpos": jnp.arange(3.0), "none": np.zeros((4, 0), np.int32)}
    checkpoints.save(tmp_path, 1, tree)
    restored = checkpoints.restore(tmp_path, like=jax.tree.map(jnp.zeros_like, tree))
    assert restored["contacts"].shape == (0, 3) and restored["none"].shape == (4, 0)
    assert restored["none"].dtype == np.int32
    np.testing.assert_array_equal(restored["qpos"], tree["qpos"])


def _damage(directory, step: int) -> None:
    """Truncates every array data file of checkpoint `step` (a full disk, a bad copy)."""
    files = list((directory / str(step) / "arrays" / "d").iterdir())
    assert files
    for path in files:
        path.write_bytes(b"")


def test_restore_newest_intact_skips_damaged_checkpoints_with_one_warning(tmp_path):
    for step in (1, 2, 3):
        checkpoints.save(tmp_path, step, make_state(step))
    _damage(tmp_path, 3)
    (tmp_path / "2" / "tree" / "metadata").unlink()
    with pytest.warns(checkpoints.DamagedCheckpointWarning) as caught:
        tree, step, skipped = checkpoints.restore_newest_intact(tmp_path, make_state(0))
    assert step == 1 and [s for s, _ in skipped] == [3, 2]
    assert_identical(tree, make_state(1))
    assert "OUT_OF_RANGE" in skipped[0][1] and "tensorstore_spec" not in skipped[0][1]
    assert skipped[1][1].startswith("FileNotFoundError") and "metadata" in skipped[1][1]
    (message,) = [str(w.message) for w in caught]
    assert "\n" not in message and message.startswith(f"{tmp_path}: checkpoint 3 is damaged (ValueError: ")
    assert message.endswith("restored checkpoint 1, the newest intact one")
    with pytest.raises(checkpoints.CheckpointError, match="does not match"):  # it reads, but it is not restored
        checkpoints.restore(tmp_path, {"x": jnp.zeros(1)}, step=1)


def test_restore_newest_intact_when_none_is_intact_or_none_exists(tmp_path):
    for step in (1, 2):
        checkpoints.save(tmp_path, step, make_state(step))
        _damage(tmp_path, step)
    with pytest.raises(
        checkpoints.CheckpointError,
        match=r"no intact checkpoint in .*: checkpoint 2 is damaged \(.*\); checkpoint 1 is damaged",
    ):
        checkpoints.restore_newest_intact(tmp_path, make_state(0))
    with pytest.raises(FileNotFoundError, match="no complete checkpoint"):
        checkpoints.restore_newest_intact(tmp_path / "absent", make_state(0))


def test_a_mismatch_is_not_skipped_as_damage(tmp_path):
    """Every checkpoint of a run mismatches a wrong template alike: falling back would
    only hide that, so the newest one's mismatch is raised (a CheckpointError, a ValueError)."""
    checkpoints.save(tmp_path, 1, {"x": jnp.zeros(2)})
    checkpoints.save(tmp_path, 2, {"x": jnp.zeros(2)})
    with pytest.raises(ValueError, match=r"checkpoint 2 in .* does not match the template"):
        checkpoints.restore_newest_intact(tmp_path, {"x": jnp.zeros(3)})


def test_a_damaged_checkpoint_set_aside_can_be_saved_again(tmp_path):
    for step in (1, 2):
        checkpoints.save(tmp_path, step, {"x": jnp.ones(1) * step})
    _damage(tmp_path, 2)
    assert checkpoints.set_aside(tmp_path, 2) == tmp_path / "2.damaged"
    assert checkpoints.all_steps(tmp_path) == [1]
    checkpoints.save(tmp_path, 2, {"x": jnp.ones(1) * 5})
    assert checkpoints.set_aside(tmp_path, 2) == tmp_path / "2.damaged-2"  # the first stays
    checkpoints.save(tmp_path, 2, {"x": jnp.ones(1) * 7})
    assert_identical(checkpoints.restore(tmp_path, {"x": jnp.zeros(1)}), {"x": jnp.ones(1) * 7})
    assert sorted(p.name for p in tmp_path.iterdir()) == ["1", "2", "2.damaged", "2.damaged-2"]
