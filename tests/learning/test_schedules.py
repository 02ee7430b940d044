"""`mjzoo.learning.schedules`: the KL-adaptive learning rate, the KL early stop and its
masked update inside a `lax.scan`, and the entropy-coefficient decays, against
hand-computed values, under jit and vmap."""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from mjzoo.learning.schedules import entropy_coef_schedule
from mjzoo.learning.schedules import kl_adaptive_lr
from mjzoo.learning.schedules import kl_early_stop
from mjzoo.learning.schedules import skip_when_stopped

TARGET = 0.01  # bands: kl > 0.02 lowers the rate, 0 < kl < 0.005 raises it


@pytest.mark.parametrize(
    "kl, expected",
    [
        (0.05, 1e-3 / 1.5),  # 0.05 > 2 * 0.01
        (0.001, 1e-3 * 1.5),  # 0 < 0.001 < 0.01 / 2
        (0.01, 1e-3),  # inside [0.005, 0.02]
        (0.02, 1e-3),  # the upper band's edge is not "above"
        (0.005, 1e-3),  # the lower band's edge is not "below"
        (0.0, 1e-3),  # no movement measured: unchanged, as rsl_rl
        (math.nan, 1e-3),
    ],
)
def test_kl_adaptive_lr_bands(kl, expected):
    np.testing.assert_allclose(kl_adaptive_lr(1e-3, kl, TARGET), expected, rtol=1e-6)


def test_kl_adaptive_lr_clamps():
    # 1.2e-5 / 1.5 = 8e-6 < 1e-5 -> 1e-5;  8e-3 * 1.5 = 1.2e-2 > 1e-2 -> 1e-2.
    np.testing.assert_allclose(kl_adaptive_lr(1.2e-5, 0.05, TARGET), 1e-5, rtol=1e-6)
    np.testing.assert_allclose(kl_adaptive_lr(8e-3, 0.001, TARGET), 1e-2, rtol=1e-6)
    # Other factor and bounds: 0.1 * 2 = 0.2 -> clamped to max_lr 0.15.
    np.testing.assert_allclose(kl_adaptive_lr(0.1, 0.001, TARGET, factor=2.0, min_lr=0.01, max_lr=0.15), 0.15)
    np.testing.assert_allclose(kl_adaptive_lr(0.1, 0.05, TARGET, factor=2.0, min_lr=0.01, max_lr=0.15), 0.05)


def test_kl_adaptive_lr_jit_and_vmap():
    kls = jnp.array([0.05, 0.001, 0.01])
    expected = [1e-3 / 1.5, 1e-3 * 1.5, 1e-3]
    np.testing.assert_allclose(jax.jit(kl_adaptive_lr)(1e-3, 0.05, TARGET), 1e-3 / 1.5, rtol=1e-6)
    np.testing.assert_allclose(jax.vmap(kl_adaptive_lr, (None, 0, None))(1e-3, kls, TARGET), expected, rtol=1e-6)
    # A sweep over targets and factors with one KL of 0.03: only target 0.01 (band 0.02) lowers.
    targets, factors = jnp.array([0.01, 0.02, 0.1]), jnp.array([2.0, 3.0, 4.0])
    out = jax.jit(jax.vmap(lambda t, f: kl_adaptive_lr(1e-3, 0.03, t, f)))(targets, factors)
    # 0.03 > 0.02 -> 1e-3 / 2;  0.03 in [0.01, 0.04] -> 1e-3;  0.03 < 0.05 -> 1e-3 * 4.
    np.testing.assert_allclose(out, [5e-4, 1e-3, 4e-3], rtol=1e-6)


def test_kl_early_stop_flag():
    assert not kl_early_stop(False, 0.01, 0.02)
    assert kl_early_stop(False, 0.03, 0.02)
    assert kl_early_stop(True, 0.0, 0.02)  # the flag stays on
    assert not kl_early_stop(False, 1e6)  # the default bound, inf, never stops
    kls = jnp.array([0.01, 0.03, 0.0])
    stopped = jnp.array([False, False, True])
    out = jax.jit(jax.vmap(kl_early_stop, (0, 0, None)))(stopped, kls, 0.02)
    np.testing.assert_array_equal(out, [False, True, True])


def test_masked_scan_skips_the_steps_after_the_bound():
    """A scan of 5 "steps" that each add 1 to a param and 1 to an optimizer count; step i
    measures kl_i. With bound 0.02 the step measuring 0.03 (i = 2) and all after it are
    skipped: 2 steps applied, even though step 3 measures a small KL again."""
    kls = jnp.array([0.001, 0.01, 0.03, 0.001, 0.001])

    def run(max_kl):
        def step(carry, kl):
            params, opt_state, stopped = carry
            stopped = kl_early_stop(stopped, kl, max_kl)
            new = (jax.tree.map(lambda p: p + 1.0, params), opt_state + 1)
            params, opt_state = skip_when_stopped(stopped, (params, opt_state), new)
            return (params, opt_state, stopped), stopped

        init = ({"w": jnp.zeros(2)}, jnp.int32(0), jnp.bool_(False))
        return jax.lax.scan(step, init, kls)

    (params, count, stopped), flags = jax.jit(run)(0.02)
    np.testing.assert_array_equal(params["w"], [2.0, 2.0])
    assert count == 2 and count.dtype == jnp.int32 and stopped
    np.testing.assert_array_equal(flags, [False, False, True, True, True])
    # vmapped over bounds: inf -> 5 steps, 0.005 -> stops at step 1 (0.01 > 0.005) -> 1 step.
    (params, count, _), _ = jax.vmap(run)(jnp.array([jnp.inf, 0.02, 0.005]))
    np.testing.assert_array_equal(count, [5, 2, 1])
    np.testing.assert_array_equal(params["w"][:, 0], [5.0, 2.0, 1.0])


def test_skip_when_stopped_rejects_other_structures():
    with pytest.raises(ValueError, match="skip_when_stopped: old and new differ in structure"):
        skip_when_stopped(True, {"a": 1.0}, {"b": 1.0})


@pytest.mark.parametrize(
    "kind, progress, expected",
    [
        ("constant", 0.7, 0.01),
        ("linear", 0.0, 0.01),
        ("linear", 0.25, 0.01 + (0.001 - 0.01) * 0.25),  # 0.00775
        ("linear", 1.0, 0.001),
        ("linear", 1.5, 0.001),  # clipped to 1
        ("cosine", 0.0, 0.01),
        ("cosine", 0.5, 0.001 + (0.01 - 0.001) * 0.5),  # cos(pi / 2) = 0: halfway, 0.0055
        ("cosine", 0.25, 0.001 + 0.009 * (1 + math.sqrt(0.5)) / 2),  # cos(pi / 4) = sqrt(1/2)
        ("cosine", 1.0, 0.001),
        ("cosine", -0.5, 0.01),  # clipped to 0
    ],
)
def test_entropy_coef_schedule_hand_computed(kind, progress, expected):
    np.testing.assert_allclose(entropy_coef_schedule(kind, progress, 0.01, 0.001), expected, rtol=1e-5)


def test_entropy_coef_schedule_jit_and_vmap():
    progress = jnp.array([0.0, 0.25, 1.0])
    linear = jax.jit(jax.vmap(lambda p: entropy_coef_schedule("linear", p, 0.01, 0.001)))(progress)
    np.testing.assert_allclose(linear, [0.01, 0.00775, 0.001], rtol=1e-5)
    # Initial and final coefficients traced per member of a sweep, at progress 0.5:
    # cosine: (a + b) / 2 -> [0.5, 2.0, 0.15].
    initial, final = jnp.array([1.0, 3.0, 0.2]), jnp.array([0.0, 1.0, 0.1])
    cosine = jax.jit(jax.vmap(lambda a, b: entropy_coef_schedule("cosine", 0.5, a, b)))(initial, final)
    np.testing.assert_allclose(cosine, [0.5, 2.0, 0.15], rtol=1e-5)
    constant = jax.vmap(lambda p: entropy_coef_schedule("constant", p, 0.01, 0.0))(progress)
    np.testing.assert_allclose(constant, [0.01] * 3, rtol=1e-6)


def test_entropy_coef_schedule_rejects_an_unknown_kind():
    with pytest.raises(ValueError, match="entropy_coef_schedule: kind='exponential' must be one of constant"):
        entropy_coef_schedule("exponential", 0.5, 0.01, 0.0)
