"""`mjzoo.learning.losses` against hand-computed numbers, including which elements the clipping
cuts off from the gradient, the vanilla and KL-penalized policy gradients, and jit / vmap
agreement."""

from __future__ import annotations

import math

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mjzoo.learning.losses import clipped_surrogate_loss
from mjzoo.learning.losses import kl_penalty_loss
from mjzoo.learning.losses import normalize_advantages
from mjzoo.learning.losses import policy_gradient_loss
from mjzoo.learning.losses import value_loss

EPS = 0.2
# ratios r = [0.5, 0.9, 1.1, 1.5], advantages A = [1, -1, 2, -2], eps = 0.2:
#   clip(r)     = [0.8, 0.9, 1.1, 1.2]
#   r * A       = [0.5, -0.9, 2.2, -3.0]
#   clip(r) * A = [0.8, -0.9, 2.2, -2.4]
#   min         = [0.5, -0.9, 2.2, -3.0]  -> every element takes the unclipped term
#   loss = -(0.5 - 0.9 + 2.2 - 3.0) / 4 = 0.3
#   clip_fraction: |r - 1| = [0.5, 0.1, 0.1, 0.5] > 0.2 -> 2 of 4 = 0.5
#   approx_kl = mean((r - 1) - ln r)
#     = ((-0.5 - ln 0.5) + (-0.1 - ln 0.9) + (0.1 - ln 1.1) + (0.5 - ln 1.5)) / 4
#   d loss / d log_prob_i = -A_i r_i / 4 where the unclipped term is the min, else 0
#     = [-0.125, 0.225, -0.55, 0.75]
RATIOS = np.array([0.5, 0.9, 1.1, 1.5])
ADV = np.array([1.0, -1.0, 2.0, -2.0], np.float32)
OLD_LOG_PROB = np.array([-1.0, -0.3, -2.0, 0.4], np.float32)
LOG_PROB = (OLD_LOG_PROB + np.log(RATIOS)).astype(np.float32)


def test_surrogate_hand_computed():
    loss, aux = clipped_surrogate_loss(jnp.asarray(LOG_PROB), jnp.asarray(OLD_LOG_PROB), jnp.asarray(ADV), EPS)
    np.testing.assert_allclose(loss, 0.3, rtol=1e-5)
    np.testing.assert_allclose(aux["clip_fraction"], 0.5)
    kl = ((-0.5 - math.log(0.5)) + (-0.1 - math.log(0.9)) + (0.1 - math.log(1.1)) + (0.5 - math.log(1.5))) / 4
    np.testing.assert_allclose(aux["approx_kl"], kl, rtol=1e-4)
    assert loss.shape == () and set(aux) == {"clip_fraction", "approx_kl"}


def test_surrogate_gradient_follows_the_unclipped_term():
    grad_fn = jax.grad(lambda lp, olp, a: clipped_surrogate_loss(lp, olp, a, EPS)[0], argnums=(0, 1, 2))
    d_lp, d_olp, d_adv = grad_fn(jnp.asarray(LOG_PROB), jnp.asarray(OLD_LOG_PROB), jnp.asarray(ADV))
    np.testing.assert_allclose(d_lp, [-0.125, 0.225, -0.55, 0.75], rtol=1e-5)
    # Collection-time quantities are constants of the loss.
    np.testing.assert_array_equal(d_olp, 0.0)
    np.testing.assert_array_equal(d_adv, 0.0)


def test_surrogate_zero_gradient_when_clipped_on_the_advantage_side():
    # r = 1.5 with A = +1: min(1.5, 1.2) = 1.2, the clipped constant -> gradient 0.
    # r = 0.5 with A = -1: min(-0.5, -0.8) = -0.8, the clipped constant -> gradient 0.
    # loss = -(1.2 - 0.8) / 2 = -0.2; both ratios are outside [0.8, 1.2].
    old = jnp.zeros(2)
    log_prob = jnp.log(jnp.array([1.5, 0.5]))
    adv = jnp.array([1.0, -1.0])
    (loss, aux), grad = jax.value_and_grad(clipped_surrogate_loss, has_aux=True)(log_prob, old, adv, EPS)
    np.testing.assert_allclose(loss, -0.2, rtol=1e-5)
    np.testing.assert_array_equal(grad, 0.0)
    np.testing.assert_allclose(aux["clip_fraction"], 1.0)


def test_surrogate_at_ratio_one_is_policy_gradient():
    # r = 1 everywhere: loss = -mean(A), gradient -A/N (the vanilla policy gradient),
    # nothing clipped, KL estimate exactly 0.
    adv = jnp.array([[0.3, -1.2], [2.0, 0.1]])
    lp = jnp.array([[-0.7, -1.1], [-0.2, -3.0]])
    (loss, aux), grad = jax.value_and_grad(clipped_surrogate_loss, has_aux=True)(lp, lp, adv, 0.1)
    np.testing.assert_allclose(loss, -jnp.mean(adv), rtol=1e-6)
    np.testing.assert_allclose(grad, -adv / 4, rtol=1e-6)
    assert aux["clip_fraction"] == 0.0 and aux["approx_kl"] == 0.0


def test_policy_gradient_hand_computed():
    # log pi = [-1, -0.5], A = [2, -4]: loss = -(-2 + 2) / 2 = 0; d/d log pi = -A / 2 = [-1, 2].
    log_prob, adv = jnp.array([-1.0, -0.5]), jnp.array([2.0, -4.0])
    loss, (d_lp, d_adv) = jax.value_and_grad(policy_gradient_loss, argnums=(0, 1))(log_prob, adv)
    np.testing.assert_allclose(loss, 0.0, atol=1e-7)
    np.testing.assert_allclose(d_lp, [-1.0, 2.0])
    np.testing.assert_array_equal(d_adv, 0.0)


# The KL-penalized surrogate on the ratios above, beta = 0.5:
#   -mean(r * A) = -(0.5 - 0.9 + 2.2 - 3.0) / 4 = 0.3
#   k3 = (r - 1) - ln r = [0.193147, 0.005361, 0.004690, 0.094535], mean 0.0744332
#   loss = 0.3 + 0.5 * 0.0744332 = 0.3372166
#   d loss / d log_prob_i = (-A_i r_i + beta (r_i - 1)) / 4
#     = [(-0.5 - 0.25), (0.9 - 0.05), (-2.2 + 0.05), (3.0 + 0.25)] / 4
#     = [-0.1875, 0.2125, -0.5375, 0.8125]
def test_kl_penalty_hand_computed():
    grad_fn = jax.value_and_grad(kl_penalty_loss, argnums=(0, 1, 2), has_aux=True)
    (loss, aux), (d_lp, d_olp, d_adv) = grad_fn(jnp.asarray(LOG_PROB), jnp.asarray(OLD_LOG_PROB), jnp.asarray(ADV), 0.5)
    kl = np.mean((RATIOS - 1) - np.log(RATIOS))
    np.testing.assert_allclose(kl, 0.0744332, rtol=1e-5)
    np.testing.assert_allclose(loss, 0.3 + 0.5 * kl, rtol=1e-5)
    np.testing.assert_allclose(aux["approx_kl"], kl, rtol=1e-4)
    np.testing.assert_allclose(d_lp, [-0.1875, 0.2125, -0.5375, 0.8125], rtol=1e-4)
    np.testing.assert_array_equal(d_olp, 0.0)
    np.testing.assert_array_equal(d_adv, 0.0)
    # beta = 0 is the unclipped surrogate; at ratio 1 the penalty and its gradient vanish.
    np.testing.assert_allclose(
        kl_penalty_loss(jnp.asarray(LOG_PROB), jnp.asarray(OLD_LOG_PROB), jnp.asarray(ADV), 0.0)[0], 0.3, rtol=1e-5
    )
    same = jnp.asarray(OLD_LOG_PROB)
    d_same = jax.grad(lambda lp: kl_penalty_loss(lp, same, jnp.asarray(ADV), 10.0)[0])(same)
    np.testing.assert_allclose(d_same, -ADV / 4, rtol=1e-6)


# values v = [1, 2, 3], returns R = [2, 2, 0]:
#   (v - R)^2 = [1, 0, 9], loss = 0.5 * 10 / 3 = 5/3
# clipped with old values [0.5, 2.5, 1.0], eps = 0.2:
#   v - v_old = [0.5, -0.5, 2.0] -> clip -> [0.2, -0.2, 0.2] -> v_clip = [0.7, 2.3, 1.2]
#   (v_clip - R)^2 = [1.69, 0.09, 1.44]
#   max            = [1.69, 0.09, 9.0]  -> loss = 0.5 * 10.78 / 3
#   gradient wrt v: elements 0 and 1 take the clipped (constant) branch -> 0;
#     element 2 takes the unclipped branch -> 0.5 * 2 * (3 - 0) / 3 = 1
VALUES = jnp.array([1.0, 2.0, 3.0])
RETURNS = jnp.array([2.0, 2.0, 0.0])
OLD_VALUES = jnp.array([0.5, 2.5, 1.0])


def test_value_loss_hand_computed():
    np.testing.assert_allclose(value_loss(VALUES, RETURNS), 5.0 / 3.0, rtol=1e-6)
    # Unclipped gradient: (v - R) / N = [-1, 0, 3] / 3; returns are constants.
    d_v, d_r = jax.grad(value_loss, argnums=(0, 1))(VALUES, RETURNS)
    np.testing.assert_allclose(d_v, [-1.0 / 3.0, 0.0, 1.0], rtol=1e-6)
    np.testing.assert_array_equal(d_r, 0.0)


def test_clipped_value_loss_hand_computed():
    loss, grad = jax.value_and_grad(value_loss)(VALUES, RETURNS, OLD_VALUES, 0.2)
    np.testing.assert_allclose(loss, 0.5 * 10.78 / 3.0, rtol=1e-5)
    np.testing.assert_allclose(grad, [0.0, 0.0, 1.0], rtol=1e-6, atol=1e-7)
    # The clipped loss is never below the unclipped one.
    assert loss >= value_loss(VALUES, RETURNS)


def test_value_loss_needs_both_clip_arguments():
    with pytest.raises(ValueError, match="both old_values and clip_epsilon"):
        value_loss(VALUES, RETURNS, OLD_VALUES)
    with pytest.raises(ValueError, match="both old_values and clip_epsilon"):
        value_loss(VALUES, RETURNS, clip_epsilon=0.2)


def test_normalize_advantages():
    # mean 2.5, population std sqrt(1.25): (x - 2.5) / 1.1180340
    out = normalize_advantages(jnp.array([1.0, 2.0, 3.0, 4.0]))
    np.testing.assert_allclose(out, [-1.3416408, -0.4472136, 0.4472136, 1.3416408], rtol=1e-5)
    # Over ALL elements, not per column: a [2, 2] reshape gives the same numbers.
    np.testing.assert_allclose(normalize_advantages(jnp.array([[1.0, 2.0], [3.0, 4.0]])).ravel(), out, rtol=1e-6)
    # A constant batch has std 0: eps keeps it finite, mapping to zeros.
    np.testing.assert_array_equal(normalize_advantages(jnp.full((5,), 3.0)), 0.0)


def test_jit_and_vmap():
    rng = np.random.default_rng(0)
    lp, olp, adv, v, ret, ov = (jnp.asarray(rng.normal(size=(3, 16)), jnp.float32) for _ in range(6))

    def all_losses(lp, olp, adv, v, ret, ov):
        surrogate, aux = clipped_surrogate_loss(lp, olp, normalize_advantages(adv), 0.2)
        penalized = kl_penalty_loss(lp, olp, adv, 0.5)
        return surrogate, aux, penalized, policy_gradient_loss(lp, adv), value_loss(v, ret), value_loss(v, ret, ov, 0.5)

    # vmap over the leading axis: each row is its own minibatch.
    batched = jax.jit(jax.vmap(all_losses))(lp, olp, adv, v, ret, ov)
    chex.assert_tree_shape_prefix(batched, (3,))
    for i in range(3):
        row = all_losses(lp[i], olp[i], adv[i], v[i], ret[i], ov[i])
        chex.assert_trees_all_close(jax.tree.map(lambda x, i=i: x[i], batched), row, rtol=1e-5, atol=1e-6)
    # Traced clip epsilon.
    loss_fn = jax.jit(lambda e: clipped_surrogate_loss(lp, olp, adv, e)[0])
    np.testing.assert_allclose(loss_fn(jnp.float32(0.2)), clipped_surrogate_loss(lp, olp, adv, 0.2)[0], rtol=1e-6)
