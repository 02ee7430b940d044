"""`mjzoo.learning.discriminators` against hand-computed numbers: losses, rewards, the
per-sample gradient penalty (exact for linear and quadratic discriminators), that every
term is a mean over its samples, the composed loss, the optimizer's decay mask, errors,
and jit / vmap agreement."""

from __future__ import annotations

import math

import chex
import jax
import jax.numpy as jnp
import numpy as np
import optax
import pytest

from mjzoo.learning import discriminators as disc
from mjzoo.learning.networks import mlp

METRIC_NAMES = {
    "disc/loss_reference",
    "disc/loss_policy",
    "disc/accuracy_reference",
    "disc/accuracy_policy",
    "disc/logit_reference",
    "disc/logit_policy",
}


def test_least_squares_at_the_targets():
    # d_ref = 1, d_pol = -1: both terms 0; rewards 1 (reference target) and 0 (policy target).
    loss, metrics = disc.least_squares_loss(jnp.array([1.0]), jnp.array([-1.0]))
    assert loss == 0.0 and set(metrics) == METRIC_NAMES
    np.testing.assert_array_equal(disc.least_squares_reward(jnp.array([1.0, -1.0])), [1.0, 0.0])


def test_least_squares_hand_computed():
    # ref [0, 2]: (d - 1)^2 = [1, 1], mean 1.   pol [0.5]: (d + 1)^2 = 2.25.   loss 3.25.
    # accuracy: ref > 0 for 1 of 2; pol < 0 for 0 of 1; mean logits 1 and 0.5.
    loss, m = disc.least_squares_loss(jnp.array([0.0, 2.0]), jnp.array([0.5]))
    np.testing.assert_allclose(loss, 3.25)
    np.testing.assert_allclose([m["disc/loss_reference"], m["disc/loss_policy"]], [1.0, 2.25])
    np.testing.assert_allclose([m["disc/accuracy_reference"], m["disc/accuracy_policy"]], [0.5, 0.0])
    np.testing.assert_allclose([m["disc/logit_reference"], m["disc/logit_policy"]], [1.0, 0.5])
    # d/d d_ref = 2 (d - 1) / 2 = [-1, 1];  d/d d_pol = 2 (d + 1) = 3.
    g_ref, g_pol = jax.grad(lambda r, p: disc.least_squares_loss(r, p)[0], argnums=(0, 1))(
        jnp.array([0.0, 2.0]), jnp.array([0.5])
    )
    np.testing.assert_allclose(g_ref, [-1.0, 1.0])
    np.testing.assert_allclose(g_pol, [3.0])


def test_least_squares_reward_hand_computed():
    # 1 - (d - 1)^2 / 4 at d = 0, 2, 3, -3, 0.5: 0.75, 0.75, 0, max(0, -3) = 0, 1 - 0.0625.
    logits = jnp.array([[0.0, 2.0, 3.0], [-3.0, 0.5, 1.0]])
    np.testing.assert_allclose(disc.least_squares_reward(logits), [[0.75, 0.75, 0.0], [0.0, 0.9375, 1.0]])


def test_logistic_loss_hand_computed():
    # d = 0 for both: D = 1/2, loss = -log 1/2 - log 1/2 = 2 log 2.
    loss, m = disc.logistic_loss(jnp.zeros(3), jnp.zeros(2))
    np.testing.assert_allclose(loss, 2 * math.log(2), rtol=1e-6)
    # d = ln 3 -> D = 3/4: reference term -log 3/4, policy term -log(1 - 3/4) = log 4.
    d = jnp.array([math.log(3.0)])
    loss, m = disc.logistic_loss(d, d)
    np.testing.assert_allclose(m["disc/loss_reference"], -math.log(0.75), rtol=1e-6)
    np.testing.assert_allclose(m["disc/loss_policy"], math.log(4.0), rtol=1e-6)
    np.testing.assert_allclose(loss, math.log(4.0) - math.log(0.75), rtol=1e-6)


def test_logistic_loss_is_stable_for_large_logits():
    # Confident and right: ~0. Confident and wrong: ~|d| (a naive log(sigmoid) gives inf).
    right, _ = disc.logistic_loss(jnp.array([100.0]), jnp.array([-100.0]))
    wrong, _ = disc.logistic_loss(jnp.array([-100.0]), jnp.array([100.0]))
    np.testing.assert_allclose(right, 0.0, atol=1e-30)
    np.testing.assert_allclose(wrong, 200.0, rtol=1e-6)
    grads = jax.grad(lambda r, p: disc.logistic_loss(r, p)[0], argnums=(0, 1))(jnp.array([-100.0]), jnp.array([100.0]))
    np.testing.assert_allclose(grads, [[-1.0], [1.0]])


def test_logistic_reward_hand_computed():
    # softplus(0) = log 2; softplus(ln 3) = -log(1 - 3/4) = log 4; softplus(-100) ~ e^-100 (>= 0);
    # d = 100 hits the default cap log 1e4; with max_reward = 1, log 4 > 1 is capped too.
    logits = jnp.array([0.0, math.log(3.0), -100.0, 100.0])
    reward = disc.logistic_reward(logits)
    np.testing.assert_allclose(reward, [math.log(2), math.log(4), 0.0, math.log(1e4)], rtol=1e-6, atol=1e-30)
    assert jnp.all(reward >= 0)
    np.testing.assert_allclose(disc.logistic_reward(logits, 1.0), [math.log(2), 1.0, 0.0, 1.0], rtol=1e-6, atol=1e-30)


def test_style_reward_dispatches_and_has_no_gradient():
    logits = jnp.array([0.0, 1.0])
    np.testing.assert_allclose(disc.style_reward("least_squares", logits), [0.75, 1.0])
    np.testing.assert_allclose(disc.style_reward("logistic", logits), jax.nn.softplus(logits))
    np.testing.assert_array_equal(jax.grad(lambda d: disc.style_reward("logistic", d).sum())(logits), 0.0)
    with pytest.raises(ValueError, match="kind='hinge'"):
        disc.style_reward("hinge", logits)


def test_accuracy_hand_computed():
    # ref [0.3, -0.1, 2, 0] -> > 0 for 2 of 4; pol [-1, 0.5] -> < 0 for 1 of 2.
    acc = disc.accuracy(jnp.array([0.3, -0.1, 2.0, 0.0]), jnp.array([-1.0, 0.5]))
    np.testing.assert_allclose(
        [acc[f"disc/{k}"] for k in ("accuracy_reference", "accuracy_policy", "logit_reference", "logit_policy")],
        [0.5, 0.5, 0.55, -0.25],
        rtol=1e-6,
    )


# A linear discriminator in `mlp`'s layout: d(x) = x . w + b, w = [1, 2], b = 0.5.
LINEAR = mlp(1, ())
LINEAR_PARAMS = [{"kernel": jnp.array([[1.0], [2.0]]), "bias": jnp.array([0.5])}]


def quadratic(params, x):
    """d(x) = sum(c * x^2): grad = 2 c x, a different norm at every sample."""
    return jnp.sum(params["c"] * jnp.square(x))


QUAD_PARAMS = {"c": jnp.array([1.0, 2.0])}
# x1 = [1, 1]: grad [2, 4], |.|^2 = 20;  x2 = [0.5, -1]: grad [1, -4], |.|^2 = 17;  mean 18.5.
QUAD_X = jnp.array([[1.0, 1.0], [0.5, -1.0]])


def test_gradient_penalty_of_a_linear_discriminator_is_w_squared():
    x = jax.random.normal(jax.random.key(0), (7, 2))
    np.testing.assert_allclose(disc.gradient_penalty(LINEAR.apply, LINEAR_PARAMS, x), 5.0, rtol=1e-6)
    # Differentiable in params: d|w|^2/dw = 2w, nothing for the bias.
    grad = jax.grad(disc.gradient_penalty, argnums=1)(LINEAR.apply, LINEAR_PARAMS, x)
    np.testing.assert_allclose(grad[0]["kernel"], [[2.0], [4.0]], rtol=1e-6)
    np.testing.assert_array_equal(grad[0]["bias"], 0.0)


def test_gradient_penalty_is_per_sample():
    np.testing.assert_allclose(disc.gradient_penalty(quadratic, QUAD_PARAMS, QUAD_X), 18.5, rtol=1e-6)
    # Pytree inputs: the squared norm sums over leaves. {"a": x1[0], "b": x1[1]}-style split.
    split = {"a": QUAD_X[:, :1], "b": QUAD_X[:, 1:]}
    fn = lambda p, x: quadratic(p, jnp.concatenate([x["a"], x["b"]]))
    np.testing.assert_allclose(disc.gradient_penalty(fn, QUAD_PARAMS, split), 18.5, rtol=1e-6)


def test_every_term_is_a_mean():
    # Repeating every sample (doubling the batch) leaves each term unchanged: a sum would double.
    ref, pol = jnp.array([0.0, 2.0, -0.3]), jnp.array([0.5, -4.0])
    for loss_fn in (disc.least_squares_loss, disc.logistic_loss):
        np.testing.assert_allclose(loss_fn(jnp.tile(ref, 2), jnp.tile(pol, 3))[0], loss_fn(ref, pol)[0], rtol=1e-6)
    doubled = jnp.tile(QUAD_X, (2, 1))
    np.testing.assert_allclose(disc.gradient_penalty(quadratic, QUAD_PARAMS, doubled), 18.5, rtol=1e-6)
    kwargs = {"gradient_penalty_weight": 5.0, "policy_gradient_penalty": True, "logit_l2_weight": 0.1}
    once = disc.discriminator_loss(
        "logistic", quadratic, QUAD_PARAMS, QUAD_X, -QUAD_X[:1], **kwargs, logit_weights=lambda p: p["c"]
    )
    twice = disc.discriminator_loss(
        "logistic",
        quadratic,
        QUAD_PARAMS,
        doubled,
        jnp.tile(-QUAD_X[:1], (3, 1)),
        **kwargs,
        logit_weights=lambda p: p["c"],
    )
    chex.assert_trees_all_close(once, twice, rtol=1e-6)


def test_logit_l2_is_a_sum_of_squares():
    np.testing.assert_allclose(disc.logit_l2(jnp.array([[1.0], [2.0]])), 5.0)
    np.testing.assert_allclose(disc.logit_l2({"a": jnp.ones((2, 3)), "b": jnp.array([3.0])}), 15.0)
    assert disc.last_kernel(LINEAR_PARAMS) is LINEAR_PARAMS[0]["kernel"]


# Reference x = [0.5, 0], [0, 0.25] -> d = 1, 1 (the target); policy x = [-1, -0.25] -> d = -1.
REF = jnp.array([[0.5, 0.0], [0.0, 0.25]])
POL = jnp.array([[-1.0, -0.25]])


def test_discriminator_loss_composes_the_terms():
    # Least squares: both terms 0; penalty |w|^2 = 5, logit L2 = 1 + 4 = 5: 5 * 5 + 0.05 * 5.
    loss, m = disc.discriminator_loss("least_squares", LINEAR.apply, LINEAR_PARAMS, REF, POL, 5.0, False, 0.05)
    np.testing.assert_allclose(loss, 25.25, rtol=1e-6)
    np.testing.assert_allclose([m["disc/gradient_penalty"], m["disc/logit_l2"], m["disc/loss"]], [5.0, 5.0, 25.25])
    assert set(m) == METRIC_NAMES | {"disc/gradient_penalty", "disc/logit_l2", "disc/loss"}
    # Logistic: softplus(-1) for the reference term, softplus(-1) for the policy term.
    loss, m = disc.discriminator_loss("logistic", LINEAR.apply, LINEAR_PARAMS, REF, POL, 5.0, True, 0.05)
    np.testing.assert_allclose(loss, 2 * math.log1p(math.exp(-1)) + 25.25, rtol=1e-6)
    np.testing.assert_allclose(m["disc/gradient_penalty_policy"], 5.0, rtol=1e-6)


def test_policy_gradient_penalty_averages_the_two_sets():
    # Reference penalty 18.5 (QUAD_X); policy x = [2, 0]: grad [4, 0], 16. Averaged: 17.25.
    # Logits: ref 1 + 2 = 3 and 0.25 + 2 = 2.25; pol 4: LS terms (4 + 1.5625) / 2 + 25.
    # logit_weights = c: l2 = 5, weight 0 here.
    common = ("least_squares", quadratic, QUAD_PARAMS, QUAD_X, jnp.array([[2.0, 0.0]]), 1.0)
    kw = {"logit_weights": lambda p: p["c"]}
    ref_only, m1 = disc.discriminator_loss(*common, False, **kw)
    both, m2 = disc.discriminator_loss(*common, True, **kw)
    ls = (4.0 + 1.5625) / 2 + 25.0
    np.testing.assert_allclose([ref_only, both], [ls + 18.5, ls + 17.25], rtol=1e-6)
    np.testing.assert_allclose([m2["disc/gradient_penalty"], m2["disc/gradient_penalty_policy"]], [18.5, 16.0])
    assert "disc/gradient_penalty_policy" not in m1


def test_apply_fn_output_shape_and_input_errors():
    with pytest.raises(ValueError, match=r"one logit \(shape \(\) or \(1,\)\), got \(2,\)"):
        disc.gradient_penalty(lambda p, x: x, None, REF)
    with pytest.raises(ValueError, match="kind='wasserstein'"):
        disc.discriminator_loss("wasserstein", LINEAR.apply, LINEAR_PARAMS, REF, POL)
    with pytest.raises(ValueError, match="inputs must be arrays with one common leading"):
        disc.gradient_penalty(quadratic, QUAD_PARAMS, {"a": jnp.zeros((2, 1)), "b": jnp.zeros((3, 1))})
    with pytest.raises(ValueError, match="policy must be arrays"):
        disc.discriminator_loss("logistic", LINEAR.apply, LINEAR_PARAMS, REF, jnp.float32(1.0))


def test_jit_and_vmap_agree_with_eager():
    rng = np.random.default_rng(0)
    ref, pol = jnp.asarray(rng.normal(size=(4, 6)), jnp.float32), jnp.asarray(rng.normal(size=(4, 3)), jnp.float32)
    for loss_fn in (disc.least_squares_loss, disc.logistic_loss):
        batched = jax.jit(jax.vmap(loss_fn))(ref, pol)
        for i in range(4):
            row = jax.tree.map(lambda x, i=i: x[i], batched)
            chex.assert_trees_all_close(row, loss_fn(ref[i], pol[i]), rtol=1e-6)
    for reward_fn in (disc.least_squares_reward, disc.logistic_reward):
        np.testing.assert_allclose(jax.jit(jax.vmap(reward_fn))(ref), reward_fn(ref), rtol=1e-6)
    # The composed loss over a batch of parameter sets (a vmapped ensemble of linear discriminators).
    params = [{"kernel": jnp.asarray(rng.normal(size=(3, 2, 1)), jnp.float32), "bias": jnp.zeros((3, 1))}]
    loss_fn = jax.jit(disc.discriminator_loss, static_argnums=(0, 1, 6))
    losses, m = jax.vmap(lambda p: loss_fn("least_squares", LINEAR.apply, p, REF, POL, 5.0, True, 0.01))(params)
    for i in range(3):
        one = [jax.tree.map(lambda x, i=i: x[i], params[0])]
        np.testing.assert_allclose(
            losses[i],
            disc.discriminator_loss("least_squares", LINEAR.apply, one, REF, POL, 5.0, True, 0.01)[0],
            rtol=1e-5,
        )
        np.testing.assert_allclose(m["disc/gradient_penalty"][i], jnp.sum(one[0]["kernel"] ** 2), rtol=1e-5)


def test_optimizer_decays_kernels_only_and_clips():
    opt = disc.discriminator_optimizer(0.1, weight_decay=0.5, max_grad_norm=1.0)
    params = [{"kernel": jnp.array([[2.0], [4.0]]), "bias": jnp.array([3.0])}]
    zero = jax.tree.map(jnp.zeros_like, params)
    updates, _ = opt.update(zero, opt.init(params), params)
    # Zero gradient: Adam's step is 0; decoupled decay -lr * wd * w = -0.05 w on the kernel only.
    np.testing.assert_allclose(updates[0]["kernel"], [[-0.1], [-0.2]], rtol=1e-6)
    np.testing.assert_array_equal(updates[0]["bias"], 0.0)
    # A gradient of global norm 10 is clipped to norm 1 before Adam: first moment (1 - b1) * g / 10.
    grads = [{"kernel": jnp.array([[6.0], [0.0]]), "bias": jnp.array([8.0])}]
    _, state = opt.update(grads, opt.init(params), params)
    mu = optax.tree_utils.tree_get(state, "mu")
    np.testing.assert_allclose(mu[0]["bias"], [0.1 * 0.8], rtol=1e-6)
    for bad, match in [
        ({"learning_rate": 0.0}, "learning_rate=0.0"),
        ({"learning_rate": 1.0, "weight_decay": -1.0}, "weight_decay=-1.0"),
        ({"learning_rate": 1.0, "max_grad_norm": 0.0}, "max_grad_norm=0.0"),
    ]:
        with pytest.raises(ValueError, match=match):
            disc.discriminator_optimizer(**bad)


@pytest.mark.parametrize("kind", ["least_squares", "logistic"])
def test_training_separates_two_distributions(kind):
    # Reference ~ N(0, I), policy ~ N(2, I) in 4 dims (means 4 apart, Bayes accuracy 98%): a trained
    # discriminator tells them apart and the style reward ranks reference above policy.
    k_ref, k_pol, k_init = jax.random.split(jax.random.key(0), 3)
    reference, policy = jax.random.normal(k_ref, (128, 4)), 2.0 + jax.random.normal(k_pol, (128, 4))
    net = mlp(1, (32, 32))
    params = net.init(k_init, reference[0])
    optimizer = disc.discriminator_optimizer(3e-3, weight_decay=1e-4, max_grad_norm=1.0)

    def step(carry, _):
        params, opt_state = carry
        grads, metrics = jax.grad(disc.discriminator_loss, argnums=2, has_aux=True)(
            kind, net.apply, params, reference, policy, 5.0, False, 0.05
        )
        updates, opt_state = optimizer.update(grads, opt_state, params)
        return (optax.apply_updates(params, updates), opt_state), metrics

    (params, _), metrics = jax.jit(lambda c: jax.lax.scan(step, c, length=100))((params, optimizer.init(params)))
    assert metrics["disc/loss"][-1] < 0.5 * metrics["disc/loss"][0]
    assert metrics["disc/accuracy_reference"][-1] > 0.85 and metrics["disc/accuracy_policy"][-1] > 0.85
    logits = jax.vmap(net.apply, (None, 0))(params, jnp.concatenate([reference, policy]))[:, 0]
    reward = disc.style_reward(kind, logits)
    assert reward[:128].mean() > reward[128:].mean() + 0.3
