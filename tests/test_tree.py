"""`mjzoo.tree`: `Packing` (a pytree as one flat array per dtype, and back) and `strongly_typed`."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mjzoo.tree import Packing
from mjzoo.tree import strongly_typed


def _tree():
    return {
        "pose": jnp.arange(6.0).reshape(2, 3),
        "count": jnp.int32(7),
        "key": jax.random.key(3),
        "flags": [jnp.zeros((0,)), jnp.array([True, False])],
        "scale": jnp.float32(2.5),
    }


def _same(a, b) -> bool:
    if jnp.issubdtype(a.dtype, jax.dtypes.prng_key):
        a, b = jax.random.key_data(a), jax.random.key_data(b)
    return a.dtype == b.dtype and a.shape == b.shape and bool(jnp.all(a == b))


def test_a_tree_packs_into_one_array_per_dtype_and_back_exactly():
    tree = _tree()
    packing = Packing.of(tree)
    packed = jax.jit(packing.pack)(tree)
    # float32: 6 + 1 + 0, int32: 1, uint32: the key's 2 words, bool: 2.
    assert {str(p.dtype): p.shape for p in packed} == {"float32": (7,), "int32": (1,), "uint32": (2,), "bool": (2,)}
    back = jax.jit(packing.unpack)(packed)
    assert jax.tree.all(jax.tree.map(_same, tree, back))
    # The key still draws what the original draws.
    assert float(jax.random.uniform(back["key"])) == float(jax.random.uniform(tree["key"]))


def test_stacked_packs_unpack_with_their_batch_axis():
    trees = [jax.tree.map(lambda x, i=i: x + i if x.dtype == jnp.float32 else x, _tree()) for i in range(3)]
    packing = Packing.of(trees[0])
    stacked = jax.tree.map(lambda *xs: jnp.stack(xs), *[packing.pack(t) for t in trees])
    batch = packing.unpack(stacked)
    assert batch["pose"].shape == (3, 2, 3) and batch["key"].shape == (3,)
    np.testing.assert_array_equal(batch["scale"], [2.5, 3.5, 4.5])


def test_a_changed_structure_or_shape_is_named():
    packing = Packing.of(_tree())
    with pytest.raises(ValueError, match="structure changed"):
        packing.pack({**_tree(), "extra": jnp.zeros(())})
    with pytest.raises(ValueError, match=r"shape changed: \(3,\) \(was \(2,\)\)"):
        packing.pack({**_tree(), "flags": [jnp.zeros((0,)), jnp.zeros((3,), bool)]})


def test_strongly_typed_makes_python_numbers_and_weak_arrays_strong_and_keeps_the_rest():
    tree = {
        "time": 0.0,
        "count": 3,
        "weak": jnp.asarray(2.0),
        "strong": jnp.float32(1.5),
        "key": jax.random.key(1),
        "half": jnp.ones(2, jnp.bfloat16),
    }
    for strong in (strongly_typed(tree), jax.jit(strongly_typed)(tree)):  # eagerly, and as a jit traces it
        assert {k: (x.dtype, jax.typeof(x).weak_type) for k, x in strong.items()} == {
            "time": (jnp.float32, False),
            "count": (jnp.int32, False),
            "weak": (jnp.float32, False),
            "strong": (jnp.float32, False),
            "key": (tree["key"].dtype, False),
            "half": (jnp.bfloat16, False),
        }
        assert float(strong["time"]) == 0.0 and int(strong["count"]) == 3 and float(strong["weak"]) == 2.0
    assert strongly_typed(tree)["strong"] is tree["strong"]  # nothing to do: the same array
