"""`mjzoo.learning.targets` and `losses.temperature_loss` against hand-computed numbers,
under jit and vmap; the layer-normed mlp's scale invariance."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mjzoo import learning
from mjzoo.learning import losses
from mjzoo.learning import networks
from mjzoo.learning import targets

SUPPORT = jnp.array([-1.0, 0.0, 1.0])


def test_twin_td_target_takes_the_smaller_critic_and_the_entropy_bonus():
    r, d = jnp.array([1.0, 2.0]), jnp.array([0.5, 0.0])
    q1, q2 = jnp.array([4.0, 1.0]), jnp.array([3.0, 5.0])
    np.testing.assert_allclose(jax.jit(targets.twin_td_target)(r, d, q1, q2), [2.5, 2.0])
    soft = jax.jit(targets.twin_td_target)(r, d, q1, q2, jnp.array([1.0, -1.0]), 0.5)
    np.testing.assert_allclose(soft, [1.0 + 0.5 * (3.0 - 0.5), 2.0])
    grad = jax.grad(lambda q: targets.twin_td_target(r, d, q, q2).sum())(q1)
    np.testing.assert_array_equal(grad, 0.0)  # a fixed target


def test_twin_td_target_under_vmap():
    r, d, q1, q2 = (jnp.arange(6.0).reshape(2, 3) + i for i in range(4))
    batched = jax.vmap(targets.twin_td_target)(r, d, q1, q2)
    np.testing.assert_allclose(batched, r + d * jnp.minimum(q1, q2))


def test_smoothed_action_clips_the_noise_and_the_action():
    action, key = jnp.array([0.0, 0.9, -0.95]), jax.random.key(3)
    noise = 10.0 * jax.random.normal(key, (3,))
    expected = np.clip(np.asarray(action) + np.clip(np.asarray(noise), -0.5, 0.5), -1, 1)
    np.testing.assert_allclose(jax.jit(targets.smoothed_action)(action, key, 10.0, 0.5), expected, rtol=1e-6)
    np.testing.assert_array_equal(targets.smoothed_action(action, key, 0.0, 0.5), action)


@pytest.mark.parametrize(
    "probs, reward, discount, expected",
    [
        ([0.0, 1.0, 0.0], 0.5, 1.0, [0.0, 0.5, 0.5]),  # 0 -> 0.5: split between atoms 0 and 1
        ([0.2, 0.3, 0.5], 1.0, 0.0, [0.0, 0.0, 1.0]),  # a terminal step: all on r
        ([0.2, 0.3, 0.5], 0.0, 0.5, [0.1, 0.65, 0.25]),  # -0.5, 0, 0.5
        ([0.2, 0.3, 0.5], 5.0, 1.0, [0.0, 0.0, 1.0]),  # clipped at v_max
        ([0.2, 0.3, 0.5], -9.0, 1.0, [1.0, 0.0, 0.0]),  # clipped at v_min
    ],
)
def test_categorical_projection_by_hand(probs, reward, discount, expected):
    out = jax.jit(targets.categorical_projection)(
        SUPPORT, jnp.array([probs]), jnp.array([reward]), jnp.array([discount])
    )
    np.testing.assert_allclose(out, [expected], atol=1e-6)


def test_categorical_projection_under_vmap_keeps_mass_and_the_mean():
    support = targets.categorical_support(-10.0, 10.0, 51)
    probs = jax.nn.softmax(jax.random.normal(jax.random.key(0), (4, 8, 51)))
    reward, discount = jnp.full((4, 8), 0.3), jnp.full((4, 8), 0.9)
    out = jax.vmap(targets.categorical_projection, in_axes=(None, 0, 0, 0))(support, probs, reward, discount)
    np.testing.assert_allclose(out.sum(-1), 1.0, rtol=1e-5)
    # No atom reaches past the support, so the projection keeps the mean: r + d E[z].
    mean = targets.categorical_value(support, out)
    np.testing.assert_allclose(mean, 0.3 + 0.9 * targets.categorical_value(support, probs), atol=1e-4)


def test_categorical_support_and_value():
    np.testing.assert_allclose(targets.categorical_support(-1.0, 1.0, 3), SUPPORT)
    assert float(targets.categorical_value(SUPPORT, jnp.array([0.1, 0.65, 0.25]))) == pytest.approx(0.15)
    with pytest.raises(ValueError, match="num_atoms=1"):
        targets.categorical_support(-1.0, 1.0, 1)


def test_polyak_under_jit_and_vmap():
    target, online = {"a": jnp.zeros(()), "b": jnp.array([2.0])}, {"a": jnp.ones(()), "b": jnp.array([4.0])}
    out = jax.jit(targets.polyak)(target, online, 0.25)
    np.testing.assert_allclose(out["a"], 0.25)
    np.testing.assert_allclose(out["b"], [2.5])
    taus = jnp.array([0.0, 1.0])
    both = jax.vmap(targets.polyak, in_axes=(None, None, 0))(target, online, taus)
    np.testing.assert_allclose(both["b"], [[2.0], [4.0]])


def test_temperature_loss_and_its_gradient():
    log_prob = jnp.array([1.0, 3.0])  # entropy estimate -2, below the target -1: alpha must grow
    loss, grad = jax.jit(jax.value_and_grad(losses.temperature_loss))(jnp.float32(0.5), log_prob, -1.0)
    assert float(loss) == pytest.approx(-0.5)
    assert float(grad) == pytest.approx(-1.0)  # descent raises log alpha
    batched = jax.vmap(losses.temperature_loss, in_axes=(0, None, None))(jnp.array([0.0, 1.0]), log_prob, -1.0)
    np.testing.assert_allclose(batched, [0.0, -1.0])
    assert learning.temperature_loss is losses.temperature_loss


def test_layer_norm_mlp_is_scale_invariant_in_its_hidden_layer():
    x = jnp.array([[0.3, -1.2, 0.7]])
    for normed in (True, False):
        net = networks.mlp(2, (8,), activation=lambda v: v, layer_norm=normed)
        params = net.init(jax.random.key(0), x[0])
        same = np.allclose(net.apply(params, 10.0 * x), net.apply(params, x), atol=1e-4)
        assert same == normed
