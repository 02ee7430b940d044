"""`mjzoo.learning.networks`: shapes, initialization, the output scale, the MLP and GRU against
hand-written numpy forward passes, episode resets, jit / vmap / scan."""

from __future__ import annotations

import chex
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mjzoo.learning.networks import Network
from mjzoo.learning.networks import RecurrentNetwork
from mjzoo.learning.networks import gru_mlp
from mjzoo.learning.networks import mlp

KEY = jax.random.key(0)


def np_swish(x):
    return x / (1.0 + np.exp(-x))


def np_sigmoid(x):
    return 1.0 / (1.0 + np.exp(-x))


def np_mlp(params, x):
    """The documented MLP: swish between dense layers, nothing after the last."""
    x = np.asarray(x, np.float64)
    for i, layer in enumerate(params):
        x = x @ np.asarray(layer["kernel"], np.float64) + np.asarray(layer["bias"], np.float64)
        if i < len(params) - 1:
            x = np_swish(x)
    return x


def test_mlp_shapes_and_param_layout():
    net = mlp(4, (8, 16))
    assert isinstance(net, Network)
    params = net.init(KEY, jnp.zeros(3))
    assert [layer["kernel"].shape for layer in params] == [(3, 8), (8, 16), (16, 4)]
    for layer in params:
        np.testing.assert_array_equal(layer["bias"], 0.0)  # zero biases
    for lead in [(), (5,), (2, 3)]:
        chex.assert_shape(net.apply(params, jnp.ones(lead + (3,))), lead + (4,))


def test_mlp_matches_numpy_forward():
    net = mlp(3, (5, 6))
    params = net.init(KEY, jnp.zeros(4))
    # Non-zero biases, so the test also sees where they are added.
    params = jax.tree.map(lambda p: p + 0.1 * jnp.arange(p.size, dtype=p.dtype).reshape(p.shape) / p.size, params)
    x = np.random.default_rng(0).normal(size=(7, 4)).astype(np.float32)
    np.testing.assert_allclose(net.apply(params, jnp.asarray(x)), np_mlp(params, x), rtol=1e-5, atol=1e-6)


def test_bfloat16_compute_is_mixed_precision():
    """Hidden layers in bfloat16 (about 3 significant digits), the output layer, the
    output, the params and their gradients in float32."""
    net = mlp(2, (16, 16), compute_dtype=jnp.bfloat16)
    params = net.init(KEY, jnp.zeros(4))
    x = np.random.default_rng(1).normal(size=(32, 4)).astype(np.float32)
    out = net.apply(params, jnp.asarray(x))
    assert out.dtype == jnp.float32
    exact = np_mlp(params, x)
    np.testing.assert_allclose(out, exact, rtol=0.05, atol=0.05 * np.abs(exact).max())
    assert not np.allclose(out, exact, rtol=1e-6, atol=1e-7)  # it did compute in bfloat16
    big = {**params[-1], "bias": params[-1]["bias"] + 1000.0}  # a value head's large returns
    np.testing.assert_allclose(net.apply([*params[:-1], big], x) - out, 1000.0, rtol=0, atol=1e-3)
    grads = jax.grad(lambda p: jnp.sum(net.apply(p, x)))(params)
    assert all(g.dtype == jnp.float32 for g in jax.tree.leaves(grads))


def test_mlp_with_no_hidden_layers_is_linear():
    net = mlp(2, ())
    params = net.init(KEY, jnp.zeros(3))
    x = jnp.array([1.0, -2.0, 0.5])
    np.testing.assert_allclose(net.apply(params, x), x @ params[0]["kernel"], rtol=1e-6)
    np.testing.assert_allclose(net.apply(params, 2 * x), 2 * net.apply(params, x), rtol=1e-6)


def test_init_is_deterministic_per_key_and_lecun_scaled():
    net = mlp(256, (256,))
    a, b = net.init(KEY, jnp.zeros(256)), net.init(KEY, jnp.zeros(256))
    chex.assert_trees_all_equal(a, b)
    c = net.init(jax.random.key(1), jnp.zeros(256))
    assert not np.allclose(a[0]["kernel"], c[0]["kernel"])
    # The two layers draw from different keys.
    assert not np.allclose(a[0]["kernel"], a[1]["kernel"])
    # LeCun normal: variance 1 / fan_in = 1/256, std 0.0625 (65536 samples: ~0.3% error).
    np.testing.assert_allclose(np.std(a[0]["kernel"]), 1.0 / 16.0, rtol=0.03)
    np.testing.assert_allclose(np.mean(a[0]["kernel"]), 0.0, atol=0.002)


def test_output_scale_scales_the_last_layer_only():
    x = jnp.asarray(np.random.default_rng(1).normal(size=(4, 3)), jnp.float32)
    full, small = mlp(2, (8,)), mlp(2, (8,), output_scale=0.01)
    p_full, p_small = full.init(KEY, x), small.init(KEY, x)
    chex.assert_trees_all_equal(p_full[0], p_small[0])
    np.testing.assert_allclose(p_small[1]["kernel"], 0.01 * p_full[1]["kernel"], rtol=1e-6)
    # Zero output bias at init: the output itself is scaled by 0.01.
    np.testing.assert_allclose(small.apply(p_small, x), 0.01 * full.apply(p_full, x), rtol=1e-5, atol=1e-8)


def test_mlp_clear_errors():
    net = mlp(2, (4,))
    params = net.init(KEY, jnp.zeros(3))
    with pytest.raises(ValueError, match="must end in the input size 3"):
        net.apply(params, jnp.zeros((5, 4)))
    with pytest.raises(ValueError, match="hidden_sizes"):
        mlp(2, (4, 0))
    with pytest.raises(ValueError, match="output_size"):
        mlp(0)


# --- GRU ------------------------------------------------------------------------------

H, IN, OUT = 6, 3, 2


def np_gru_mlp_step(params, h, x):
    """The documented equations, written out in float64 numpy."""
    f = lambda a: np.asarray(a, np.float64)  # noqa: E731
    e = np_swish(f(x) @ f(params["encoder"]["kernel"]) + f(params["encoder"]["bias"]))
    g = params["gru"]
    wi, wh, bi, bh = f(g["input_kernel"]), f(g["recurrent_kernel"]), f(g["input_bias"]), f(g["recurrent_bias"])
    gate = lambda w, b, v, k: v @ w[:, k * H : (k + 1) * H] + b[k * H : (k + 1) * H]  # noqa: E731
    r = np_sigmoid(gate(wi, bi, e, 0) + gate(wh, bh, h, 0))
    z = np_sigmoid(gate(wi, bi, e, 1) + gate(wh, bh, h, 1))
    n = np.tanh(gate(wi, bi, e, 2) + r * gate(wh, bh, h, 2))
    h_new = (1.0 - z) * n + z * h
    return h_new, np_mlp(params["head"], h_new)


def _gru():
    net = gru_mlp(OUT, hidden_size=H, mlp_hidden_sizes=(5,))
    params = net.init(KEY, jnp.zeros(IN))
    # Non-zero biases, distinct per gate, so a mixed-up gate order would show.
    params = jax.tree.map(lambda p: p + 0.05 * jnp.sin(jnp.arange(p.size, dtype=p.dtype).reshape(p.shape)), params)
    return net, params


def test_gru_shapes_and_init():
    net = gru_mlp(OUT, hidden_size=H, mlp_hidden_sizes=(5,))
    assert isinstance(net, RecurrentNetwork)
    params = net.init(KEY, jnp.zeros(IN))
    chex.assert_trees_all_equal(params, net.init(KEY, jnp.zeros(IN)))
    assert params["gru"]["input_kernel"].shape == (H, 3 * H) and params["gru"]["recurrent_kernel"].shape == (H, 3 * H)
    # Each gate's recurrent block is orthogonal: W^T W = I.
    for k in range(3):
        block = params["gru"]["recurrent_kernel"][:, k * H : (k + 1) * H]
        np.testing.assert_allclose(block.T @ block, np.eye(H), atol=1e-5)
    carry = net.initial_carry()
    chex.assert_shape(carry, (H,))
    np.testing.assert_array_equal(carry, 0.0)
    new_carry, out = net.apply(params, carry, jnp.ones(IN), jnp.array(False))
    chex.assert_shape([new_carry, out], [(H,), (OUT,)])


def test_gru_matches_numpy_step():
    net, params = _gru()
    rng = np.random.default_rng(2)
    h = rng.normal(size=H).astype(np.float32)
    for _ in range(3):  # several steps, feeding the carry back
        x = rng.normal(size=IN).astype(np.float32)
        expected_h, expected_out = np_gru_mlp_step(params, np.float64(h), x)
        h, out = net.apply(params, jnp.asarray(h), jnp.asarray(x), jnp.array(False))
        np.testing.assert_allclose(h, expected_h, rtol=1e-5, atol=1e-6)
        np.testing.assert_allclose(out, expected_out, rtol=1e-5, atol=1e-6)
        h = np.asarray(h)


def test_reset_equals_starting_from_the_initial_carry():
    net, params = _gru()
    x = jnp.array([0.3, -1.0, 2.0])
    stale = jnp.linspace(-1.0, 1.0, H)
    reset = net.apply(params, stale, x, jnp.array(True))
    fresh = net.apply(params, net.initial_carry(), x, jnp.array(False))
    chex.assert_trees_all_equal(reset, fresh)
    # Without the reset the stale carry matters.
    assert not np.allclose(net.apply(params, stale, x, jnp.array(False))[1], fresh[1])


def test_output_scale_of_the_head():
    small = gru_mlp(OUT, hidden_size=H, output_scale=0.01)
    full = gru_mlp(OUT, hidden_size=H)
    p_small, p_full = small.init(KEY, jnp.zeros(IN)), full.init(KEY, jnp.zeros(IN))
    np.testing.assert_allclose(p_small["head"][-1]["kernel"], 0.01 * p_full["head"][-1]["kernel"], rtol=1e-6)
    chex.assert_trees_all_equal(p_small["gru"], p_full["gru"])


def test_gru_scan_vmap_jit():
    net, params = _gru()
    T, B = 5, 4
    rng = np.random.default_rng(3)
    xs = jnp.asarray(rng.normal(size=(T, B, IN)), jnp.float32)
    resets = jnp.zeros((T, B), bool).at[0].set(True).at[3, 1].set(True)  # env 1 restarts at t = 3

    @jax.jit
    def unroll(params, xs, resets):
        carry0 = jnp.broadcast_to(net.initial_carry(), (B, H)) + 1.0  # garbage, reset at t = 0

        def step(carry, inputs):
            x, reset = inputs
            return jax.vmap(net.apply, in_axes=(None, 0, 0, 0))(params, carry, x, reset)

        return jax.lax.scan(step, carry0, (xs, resets))[1]

    outs = unroll(params, xs, resets)
    chex.assert_shape(outs, (T, B, OUT))
    # Env 1 from t = 3 on equals a fresh episode started at t = 3.
    h = net.initial_carry()
    for t in range(3, T):
        h, out = net.apply(params, h, xs[t, 1], jnp.array(False))
        np.testing.assert_allclose(outs[t, 1], out, rtol=1e-5, atol=1e-6)
    # Env 0 from t = 0: a fresh episode throughout (the garbage carry was reset).
    h = net.initial_carry()
    for t in range(T):
        h, out = net.apply(params, h, xs[t, 0], jnp.array(False))
        np.testing.assert_allclose(outs[t, 0], out, rtol=1e-5, atol=1e-6)
    # Leading batch dims without vmap give the same as vmap.
    carry = jnp.asarray(rng.normal(size=(B, H)), jnp.float32)
    batched = net.apply(params, carry, xs[0], resets[3])
    vmapped = jax.vmap(net.apply, in_axes=(None, 0, 0, 0))(params, carry, xs[0], resets[3])
    chex.assert_trees_all_close(batched, vmapped, rtol=1e-6)


def test_gru_clear_errors():
    net, params = _gru()
    with pytest.raises(ValueError, match="reset must be bool"):
        net.apply(params, net.initial_carry(), jnp.zeros(IN), jnp.array(0))
    with pytest.raises(ValueError, match="carry shape"):
        net.apply(params, jnp.zeros(H + 1), jnp.zeros(IN), jnp.array(False))
