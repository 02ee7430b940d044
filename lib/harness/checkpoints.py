"""Atomic, exactly-resumable checkpoints of arbitrary pytrees.

    path = checkpoints.save("runs/a/ckpt", step, train_state)      # keeps the newest 3
    train_state = checkpoints.restore("runs/a/ckpt", like=fresh_train_state)
    train_state, step, skipped = checkpoints.restore_newest_intact("runs/a/ckpt", like=fresh_train_state)

Storage is orbax-checkpoint's `CheckpointManager`: it writes each step into a temporary
directory (``<step>.orbax-checkpoint-tmp-*``) and renames it when complete, so a crash
mid-write leaves nothing that `latest_step` or `restore` would pick up; it prunes old
steps and, unlike a hand-written ``np.savez``, saves and restores sharded arrays
across devices and hosts, which `jax.sharding`-parallel training needs.

The tree is saved flat: leaf ``i`` as array ``"i"`` (a typed PRNG key as its
`jax.random.key_data`, which every orbax version stores), next to a JSON list of every
leaf's path, shape and dtype. `restore` compares that list with the template first, so
a mismatch is reported by path (orbax alone reports a tensorstore shape error, or a
tree diff), then rebuilds the template's structure (custom pytree nodes included),
wraps keys with the template's key implementation, returns Python and NumPy scalars as
such, and places arrays with the template's shardings.

A checkpoint can still be damaged after it was committed (a disk filled up, a file was
truncated or deleted by hand): `restore_newest_intact` then falls back to the newest
one that reads, with a `DamagedCheckpointWarning`, so a long run loses one checkpoint
interval rather than everything.
"""

from __future__ import annotations

import logging
import sys
import warnings
from pathlib import Path
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

__all__ = [
    "save",
    "restore",
    "restore_newest_intact",
    "latest_step",
    "all_steps",
    "CheckpointError",
    "DamagedCheckpointWarning",
]

PyTree = Any
_ARRAYS, _TREE = "arrays", "tree"  # the two items of every checkpoint step
_MAX_NAMES = 8  # how many differing paths an error message lists
_MAX_REASON = 400  # characters of a read error kept in messages (tensorstore's run to kilobytes)
# What orbax and tensorstore raise on reading a damaged checkpoint: a missing file
# (FileNotFoundError), bad JSON or bytes (ValueError), a missing item (KeyError).
_READ_ERRORS = (OSError, ValueError, KeyError)


def _orbax():
    """orbax.checkpoint, imported when first needed: it costs a launch ~0.4 s, before
    its first checkpoint is due."""
    import orbax.checkpoint

    return orbax.checkpoint


class CheckpointError(ValueError):
    """A checkpoint that cannot be restored: it does not match the template, or every
    checkpoint in the directory is damaged. A ValueError, as it was before it had a name."""


class DamagedCheckpointWarning(UserWarning):
    """`restore_newest_intact` skipped damaged checkpoints and restored an older one."""


def save(directory: str | Path, step: int, tree: PyTree, *, keep: int = 3) -> Path:
    """Writes `tree` as checkpoint `step` under `directory`; returns its path.

    Blocks until the checkpoint is complete on disk (training may then donate or
    overwrite the buffers). Afterwards only the newest `keep` checkpoints remain.
    Leaves may be JAX arrays (typed PRNG keys included), NumPy arrays and scalars, and
    Python bools, ints and floats.

    Raises:
      FileExistsError: `directory` already holds a checkpoint for `step` or a later
        step (another run's, most likely).
    """
    if keep < 1:
        raise ValueError(f"keep must be >= 1, got {keep}")
    step = _as_step(step)
    arrays, leaves = {}, []
    for i, (path, leaf) in enumerate(_flatten(tree)):
        if _size(leaf):  # orbax refuses empty arrays; their shape in `leaves` is all they hold
            arrays[str(i)] = _storable(leaf)
        leaves.append(dict(path=path, **_describe(leaf)))
    ocp = _orbax()
    options = ocp.CheckpointManagerOptions(
        max_to_keep=keep,
        enable_async_checkpointing=False,  # callers reuse (donate) the buffers right after
        cleanup_tmp_directories=True,  # clears what an earlier crash left behind
    )
    with ocp.CheckpointManager(Path(directory).absolute(), options=options) as manager:
        steps = manager.all_steps()
        if step in steps:
            raise FileExistsError(f"{directory} already holds a checkpoint for step {step}")
        if steps and step < max(steps):  # pruning keeps the highest steps: this one would go at once
            raise FileExistsError(
                f"{directory} holds checkpoints up to step {max(steps)}, newer than step {step}: "
                "restore from it, or save this run in another directory"
            )
        manager.save(
            step,
            args=ocp.args.Composite(
                **{_ARRAYS: ocp.args.StandardSave(arrays), _TREE: ocp.args.JsonSave({"leaves": leaves})}
            ),
        )
        manager.wait_until_finished()
    return Path(directory) / str(step)


def all_steps(directory: str | Path) -> list[int]:
    """The steps of the complete checkpoints under `directory`, ascending ([] if none)."""
    if not Path(directory).is_dir():
        return []
    with _reader(directory) as manager:
        return sorted(manager.all_steps())


def latest_step(directory: str | Path) -> int | None:
    """The step of the newest complete checkpoint under `directory`, or None."""
    steps = all_steps(directory)
    return steps[-1] if steps else None


def restore(directory: str | Path, like: PyTree, step: int | None = None) -> PyTree:
    """Reads checkpoint `step` (default: the newest) as a pytree shaped like `like`.

    Args:
      directory: where `save` wrote.
      like: a template with the saved tree's structure, e.g. the freshly initialised
        state. The result has its structure, leaf types, dtypes, PRNG key
        implementations and shardings; its values are not used.
      step: which checkpoint; None for the newest.

    Raises:
      FileNotFoundError: no (such) complete checkpoint under `directory`.
      CheckpointError: the checkpoint's leaves differ from the template's (named by path).
      OSError, ValueError, KeyError: the checkpoint is damaged (see `restore_newest_intact`).
    """
    steps = all_steps(directory)
    if not steps:
        raise FileNotFoundError(f"no complete checkpoint in {directory}")
    step = steps[-1] if step is None else _as_step(step)
    if step not in steps:
        raise FileNotFoundError(f"no checkpoint for step {step} in {directory}; it has steps {steps}")

    template, treedef = jax.tree_util.tree_flatten_with_path(like)
    template = [(jax.tree_util.keystr(path), leaf) for path, leaf in template]
    ocp = _orbax()
    with _reader(directory) as manager:
        saved = manager.restore(step, args=ocp.args.Composite(**{_TREE: ocp.args.JsonRestore()}))[_TREE]
        index = _match(saved["leaves"], template, f"checkpoint {step} in {directory}")
        target = {index[path]: _target(leaf) for path, leaf in template if _size(leaf)}
        arrays = manager.restore(step, args=ocp.args.Composite(**{_ARRAYS: ocp.args.StandardRestore(target)}))[_ARRAYS]
    restored = [_like(arrays[index[path]], leaf) if _size(leaf) else leaf for path, leaf in template]
    return jax.tree_util.tree_unflatten(treedef, restored)


def restore_newest_intact(directory: str | Path, like: PyTree) -> tuple[PyTree, int, list[tuple[int, str]]]:
    """Restores the newest checkpoint that reads, skipping damaged newer ones.

    Returns (tree, its step, [(skipped step, why), ...] newest first), and warns with a
    `DamagedCheckpointWarning` (one line) when it skipped any. A template mismatch is not
    damage: every checkpoint of the run would mismatch alike, so it raises at once.

    Raises:
      FileNotFoundError: no complete checkpoint under `directory`.
      CheckpointError: the newest checkpoint does not match `like`, or none is intact
        (each one named with what failed).
    """
    _quiet_abandoned_reads()
    skipped: list[tuple[int, str]] = []
    for step in reversed(all_steps(directory)):
        try:
            tree = restore(directory, like, step)
        except CheckpointError:
            raise
        except _READ_ERRORS as e:
            skipped.append((step, _reason(e)))
            continue
        if skipped:
            warnings.warn(
                f"{directory}: {_damaged(skipped)}; restored checkpoint {step}, the newest intact one",
                DamagedCheckpointWarning,
                stacklevel=2,
            )
        return tree, step, skipped
    if not skipped:
        raise FileNotFoundError(f"no complete checkpoint in {directory}")
    raise CheckpointError(f"no intact checkpoint in {directory}: {_damaged(skipped)}")


def set_aside(directory: str | Path, step: int) -> Path:
    """Renames checkpoint `step` to ``<step>.damaged`` (or ``.damaged-2``, ...), where
    nothing lists or prunes it: a run that resumed from an older step can save `step`
    again, and the damaged files stay for inspection."""
    source = Path(directory) / str(_as_step(step))
    target, n = source.with_name(f"{step}.damaged"), 1
    while target.exists():
        n += 1
        target = source.with_name(f"{step}.damaged-{n}")
    return source.rename(target)


def _damaged(skipped: list[tuple[int, str]]) -> str:
    return "; ".join(f"checkpoint {step} is damaged ({why})" for step, why in skipped)


def _reason(error: BaseException) -> str:
    """A read error in one short line. Tensorstore's are "CODE: context: ...: cause [its
    JSON spec]": the code and the innermost two parts (which file, what is wrong) say it."""
    text = " ".join(str(error.args[0] if isinstance(error, KeyError) and error.args else error).split())
    parts = text.split(" [tensorstore_spec")[0].split(": ")
    if len(parts) > 3:
        parts = [parts[0], "...", *parts[-2:]]
    text = f"{type(error).__name__}: " + ": ".join(parts)
    return text if len(text) <= _MAX_REASON else text[:60] + "..." + text[63 - _MAX_REASON :]


_QUIET = False


def _quiet_abandoned_reads() -> None:
    """Silences the aftermath of a failed read (once per process, before the first read
    that may fail: it starts before the error reaches us): orbax gives up on the first
    bad array and closes its event loop while tensorstore still reads the others; they
    then report "Event loop is closed" (as unraisable exceptions), "exception was never
    retrieved" (to the asyncio logger) and "coroutine ... was never awaited", with
    tracebacks, after the error itself was handled. Only those reports are dropped."""
    global _QUIET
    if _QUIET:
        return
    _QUIET = True
    previous = sys.unraisablehook

    def hook(unraisable) -> None:
        if not (isinstance(unraisable.exc_value, RuntimeError) and "Event loop is closed" in str(unraisable.exc_value)):
            previous(unraisable)

    sys.unraisablehook = hook
    logging.getLogger("asyncio").addFilter(lambda record: "exception was never retrieved" not in record.getMessage())
    warnings.filterwarnings("ignore", r"coroutine '[\w.<>]+' was never awaited", RuntimeWarning)


def _reader(directory: str | Path) -> Any:  # orbax.checkpoint.CheckpointManager
    # create=False: looking for checkpoints must not make directories.
    ocp = _orbax()
    return ocp.CheckpointManager(Path(directory).absolute(), options=ocp.CheckpointManagerOptions(create=False))


def _as_step(step: int) -> int:
    if isinstance(step, bool) or int(step) != step or step < 0:
        raise ValueError(f"step must be a non-negative integer, got {step!r}")
    return int(step)


def _flatten(tree: PyTree) -> list[tuple[str, Any]]:
    return [(jax.tree_util.keystr(p), leaf) for p, leaf in jax.tree_util.tree_flatten_with_path(tree)[0]]


def _size(leaf: Any) -> int:
    return int(np.size(leaf)) if isinstance(leaf, (jax.Array, np.ndarray)) else 1


def _is_key(leaf: Any) -> bool:
    return isinstance(leaf, jax.Array) and jnp.issubdtype(leaf.dtype, jax.dtypes.prng_key)


def _storable(leaf: Any) -> jax.Array | np.ndarray:
    if _is_key(leaf):
        return jax.random.key_data(leaf)
    return leaf if isinstance(leaf, (jax.Array, np.ndarray)) else _scalar(leaf)


def _scalar(leaf: Any) -> np.ndarray:
    if isinstance(leaf, (bool, int, float, np.generic)):
        return np.asarray(leaf)
    raise TypeError(f"cannot checkpoint a leaf of type {type(leaf).__name__}: use arrays or Python scalars")


def _describe(leaf: Any) -> dict[str, Any]:
    """Shape and dtype as compared between checkpoint and template; a key's dtype names
    its implementation (``key<fry>``), so threefry and rbg keys never mix."""
    array = leaf if isinstance(leaf, (jax.Array, np.ndarray)) else _scalar(leaf)
    return dict(shape=list(array.shape), dtype=str(array.dtype))


def _match(saved: list[dict], template: list[tuple[str, Any]], what: str) -> dict[str, str]:
    """Maps each template path to its array name in the checkpoint, or raises naming
    every path that is missing, unexpected or of another shape or dtype."""
    by_path = {leaf["path"]: (str(i), leaf) for i, leaf in enumerate(saved)}
    wanted = {path: _describe(leaf) for path, leaf in template}
    missing = [p for p in wanted if p not in by_path]
    extra = [p for p in by_path if p not in wanted]
    differ = [
        f"{p}: checkpoint {_fmt(by_path[p][1])}, template {_fmt(d)}"
        for p, d in wanted.items()
        if p in by_path and (by_path[p][1]["shape"], by_path[p][1]["dtype"]) != (d["shape"], d["dtype"])
    ]
    problems = []
    if missing:
        problems.append(f"in the template but not the checkpoint: {_names(missing)}")
    if extra:
        problems.append(f"in the checkpoint but not the template: {_names(extra)}")
    if differ:
        problems.append(f"different shape or dtype: {_names(differ)}")
    if problems:
        raise CheckpointError(f"{what} does not match the template; " + "; ".join(problems))
    return {p: by_path[p][0] for p in wanted}


def _fmt(leaf: dict) -> str:
    return f"{leaf['dtype']}{leaf['shape']}"


def _names(items: list[str]) -> str:
    more = f" and {len(items) - _MAX_NAMES} more" if len(items) > _MAX_NAMES else ""
    return ", ".join(items[:_MAX_NAMES]) + more


def _target(leaf: Any) -> jax.ShapeDtypeStruct | np.ndarray:
    """What orbax restores a leaf into: device arrays onto the template's sharding,
    host values as NumPy."""
    if isinstance(leaf, jax.Array):
        data = jax.random.key_data(leaf) if _is_key(leaf) else leaf
        return jax.ShapeDtypeStruct(data.shape, data.dtype, sharding=data.sharding)
    return np.asarray(leaf)


def _like(value: Any, leaf: Any) -> Any:
    """`value` as the same kind of leaf as the template's `leaf`."""
    if _is_key(leaf):
        return jax.random.wrap_key_data(value, impl=jax.random.key_impl(leaf))
    if isinstance(leaf, (jax.Array, np.ndarray)):
        return value
    if isinstance(leaf, np.generic):
        return np.asarray(value, leaf.dtype)[()]
    return type(leaf)(np.asarray(value).item())  # Python bool, int or float
