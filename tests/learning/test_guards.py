"""`mjzoo.learning.guards`: a non-finite loss, gradient or result keeps the old params and
optimizer state and reports skipped=1; a finite step is kept; inside a scan of optax
steps and under jit and vmap."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

from mjzoo.learning.guards import skip_non_finite_update

OLD_PARAMS = {"w": jnp.array([1.0, 2.0]), "b": jnp.array(0.5)}
NEW_PARAMS = {"w": jnp.array([0.9, 2.1]), "b": jnp.array(0.4)}
# An optimizer-like state with an integer step count (counts as finite).
OLD_OPT = {"count": jnp.int32(3), "mu": jnp.array([0.1, 0.1])}
NEW_OPT = {"count": jnp.int32(4), "mu": jnp.array([0.2, 0.0])}
GRADS = {"w": jnp.array([1.0, -1.0]), "b": jnp.array(1.0)}


def _guard(grads=GRADS, loss=1.5, new_params=NEW_PARAMS, new_opt=NEW_OPT):
    return skip_non_finite_update(new_params, new_opt, OLD_PARAMS, OLD_OPT, grads, jnp.float32(loss))


def _assert_trees_equal(a, b):
    assert jax.tree.structure(a) == jax.tree.structure(b)
    for x, y in zip(jax.tree.leaves(a), jax.tree.leaves(b)):
        np.testing.assert_array_equal(x, y)


def test_a_finite_step_is_kept():
    params, opt_state, skipped = _guard()
    _assert_trees_equal(params, NEW_PARAMS)
    _assert_trees_equal(opt_state, NEW_OPT)
    assert skipped == 0 and skipped.dtype == jnp.int32 and skipped.shape == ()


@pytest.mark.parametrize(
    "bad",
    [
        {"grads": {"w": jnp.array([1.0, jnp.nan]), "b": jnp.array(1.0)}},
        {"grads": {"w": jnp.array([1.0, 1.0]), "b": jnp.array(-jnp.inf)}},
        {"loss": jnp.nan},
        {"new_params": {"w": jnp.array([0.9, jnp.inf]), "b": jnp.array(0.4)}},
        {"new_opt": {"count": jnp.int32(4), "mu": jnp.array([jnp.nan, 0.0])}},
    ],
    ids=["nan_grad", "inf_grad", "nan_loss", "inf_param", "nan_moment"],
)
def test_a_non_finite_step_keeps_the_old_state(bad):
    params, opt_state, skipped = jax.jit(_guard)(**bad)
    _assert_trees_equal(params, OLD_PARAMS)
    _assert_trees_equal(opt_state, OLD_OPT)  # the count does not advance either
    assert skipped == 1


def test_under_vmap_each_member_skips_its_own_step():
    """Three runs stacked; only the middle one's gradient has a NaN."""
    stack = lambda t: jax.tree.map(lambda x: jnp.stack([x] * 3), t)
    grads = stack(GRADS)
    grads = {**grads, "w": grads["w"].at[1, 0].set(jnp.nan)}
    losses = jnp.array([1.0, 2.0, 3.0])
    params, opt_state, skipped = jax.jit(jax.vmap(skip_non_finite_update))(
        stack(NEW_PARAMS), stack(NEW_OPT), stack(OLD_PARAMS), stack(OLD_OPT), grads, losses
    )
    np.testing.assert_array_equal(skipped, [0, 1, 0])
    np.testing.assert_array_equal(params["w"], np.float32([[0.9, 2.1], [1.0, 2.0], [0.9, 2.1]]))
    np.testing.assert_array_equal(opt_state["count"], [4, 3, 4])


def test_in_a_scan_of_adam_steps_a_nan_minibatch_is_skipped():
    """Loss 0.5 * (w - x)^2 over 4 minibatches x; the third is NaN. The guarded run
    equals the run over the three finite minibatches alone, and counts one skip."""
    optimizer = optax.adam(0.1)
    loss_fn = lambda w, x: 0.5 * jnp.sum(jnp.square(w - x))

    def step(carry, x):
        w, opt_state = carry
        loss, grads = jax.value_and_grad(loss_fn)(w, x)
        updates, new_opt_state = optimizer.update(grads, opt_state, w)
        w, opt_state, skipped = skip_non_finite_update(
            optax.apply_updates(w, updates), new_opt_state, w, opt_state, grads, loss
        )
        return (w, opt_state), skipped

    def run(xs):
        w = jnp.zeros(2)
        return jax.lax.scan(step, (w, optimizer.init(w)), xs)

    xs = jnp.array([[1.0, 2.0], [1.5, 2.5], [jnp.nan, 0.0], [2.0, 3.0]])
    (w, opt_state), skipped = jax.jit(run)(xs)
    (w_ref, opt_ref), _ = jax.jit(run)(xs[jnp.array([0, 1, 3])])
    np.testing.assert_array_equal(skipped, [0, 0, 1, 0])
    assert np.all(np.isfinite(w))
    np.testing.assert_allclose(w, w_ref, rtol=1e-6)
    _assert_trees_equal(jax.tree.leaves(opt_state), jax.tree.leaves(opt_ref))


def test_mismatched_structures_raise():
    with pytest.raises(ValueError, match="skip_non_finite_update: old and new params differ in structure"):
        skip_non_finite_update({"w": 1.0}, NEW_OPT, OLD_PARAMS, OLD_OPT, GRADS, 1.0)
