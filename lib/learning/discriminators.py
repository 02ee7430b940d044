"""Discriminator losses, style rewards and regularizers for adversarial imitation (AMP).

In AMP (Peng et al., 2021) a discriminator scores motion features (e.g. a pair of
consecutive poses): trained to tell reference-motion samples from the policy's own, its
output becomes the policy's "style" reward. Here the discriminator emits one logit d per
sample, and two formulations are offered:

  least squares (LSGAN; the AMP paper's choice): targets d = +1 for reference samples,
    d = -1 for the policy's; reward max(0, 1 - (d - 1)^2 / 4), which is 1 at the
    reference target and 0 at the policy target.
  logistic (GAIL; the paper's baseline): D = sigmoid(d) is the probability that a
    sample is reference motion; reward -log(1 - D) = softplus(d), capped.

Every term is a MEAN over its own samples, so neither the size of a batch nor the ratio
of reference to policy samples changes a term's weight.

    import jax, optax
    from mjzoo.learning import discriminators as disc, networks

    net = networks.mlp(1, (1024, 512))
    params = net.init(key, reference[0])
    apply_fn = lambda p, x: net.apply(p, x)[0]           # one sample [F] -> logit []
    optimizer = disc.discriminator_optimizer(1e-4, weight_decay=1e-4, max_grad_norm=1.0)
    opt_state = optimizer.init(params)

    (loss, metrics), grads = jax.value_and_grad(disc.discriminator_loss, argnums=2, has_aux=True)(
        "least_squares", apply_fn, params, reference, policy, gradient_penalty_weight=5.0)
    updates, opt_state = optimizer.update(grads, opt_state, params)
    params = optax.apply_updates(params, updates)
    reward = disc.style_reward("least_squares", jax.vmap(apply_fn, (None, 0))(params, policy))
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any
from typing import Literal

import chex
import jax
import jax.numpy as jnp
import optax

__all__ = [
    "LOGISTIC_MAX_REWARD",
    "accuracy",
    "discriminator_loss",
    "discriminator_optimizer",
    "gradient_penalty",
    "last_kernel",
    "least_squares_loss",
    "least_squares_reward",
    "logistic_loss",
    "logistic_reward",
    "logit_l2",
    "style_reward",
]

Array = jax.Array
PyTree = Any
Kind = Literal["least_squares", "logistic"]
ApplyFn = Callable[[PyTree, PyTree], Array]

# -log(1e-4): the logistic reward's default cap, reached at D = 1 - 1e-4 (d ~ 9.21);
# the AMP authors' code clamps 1 - D at 1e-4 in the same place.
LOGISTIC_MAX_REWARD = math.log(1e4)
_KINDS = ("least_squares", "logistic")


def accuracy(reference_logits: Array, policy_logits: Array) -> dict[str, Array]:
    """How well the discriminator separates the two sets (diagnostics, no gradient).

    Args:
      reference_logits: [B] logits of reference-motion samples.
      policy_logits: [B'] logits of policy samples.

    Returns:
      Scalars "disc/accuracy_reference" (fraction of reference logits > 0),
      "disc/accuracy_policy" (fraction of policy logits < 0), "disc/logit_reference"
      and "disc/logit_policy" (the mean logit of each set).
    """
    chex.assert_rank([reference_logits, policy_logits], 1)
    ref, pol = jax.lax.stop_gradient((reference_logits, policy_logits))
    return {
        "disc/accuracy_reference": jnp.mean((ref > 0).astype(jnp.float32)),
        "disc/accuracy_policy": jnp.mean((pol < 0).astype(jnp.float32)),
        "disc/logit_reference": jnp.mean(ref),
        "disc/logit_policy": jnp.mean(pol),
    }


def _loss_with_metrics(reference_term: Array, policy_term: Array, ref: Array, pol: Array) -> tuple[Array, dict]:
    metrics = {"disc/loss_reference": reference_term, "disc/loss_policy": policy_term}
    metrics = jax.lax.stop_gradient(metrics) | accuracy(ref, pol)
    return reference_term + policy_term, metrics


def least_squares_loss(reference_logits: Array, policy_logits: Array) -> tuple[Array, dict[str, Array]]:
    """The least-squares (LSGAN) discriminator loss of the AMP paper, to be minimized.

      loss = mean((d_ref - 1)^2) + mean((d_pol + 1)^2)

    As in the paper's equation, there is no factor 1/2 on either term.

    Args:
      reference_logits: [B] logits of reference-motion samples (target +1).
      policy_logits: [B'] logits of policy samples (target -1); B' may differ from B.

    Returns:
      (loss, metrics): loss a scalar; metrics the two terms, "disc/loss_reference" and
      "disc/loss_policy", and the `accuracy` diagnostics.
    """
    chex.assert_rank([reference_logits, policy_logits], 1)
    reference_term = jnp.mean(jnp.square(reference_logits - 1.0))
    policy_term = jnp.mean(jnp.square(policy_logits + 1.0))
    return _loss_with_metrics(reference_term, policy_term, reference_logits, policy_logits)


def least_squares_reward(logits: Array) -> Array:
    """The style reward that matches `least_squares_loss`: max(0, 1 - (d - 1)^2 / 4).

    1 at the reference target d = +1, 0 at the policy target d = -1 (and below), 0.75
    at d = 0; it falls off again for d > 1, where the loss pushes d back to 1.

    Args:
      logits: [...] discriminator logits.

    Returns:
      [...] rewards in [0, 1].
    """
    return jnp.maximum(0.0, 1.0 - 0.25 * jnp.square(logits - 1.0))


def logistic_loss(reference_logits: Array, policy_logits: Array) -> tuple[Array, dict[str, Array]]:
    """The logistic (binary cross-entropy) discriminator loss, D = sigmoid(d), minimized.

      loss = mean(-log D(d_ref)) + mean(-log(1 - D(d_pol)))
           = mean(softplus(-d_ref)) + mean(softplus(d_pol))

    Computed through `jax.nn.softplus`, so it stays finite for any logit.

    Args:
      reference_logits: [B] logits of reference-motion samples (label 1).
      policy_logits: [B'] logits of policy samples (label 0).

    Returns:
      (loss, metrics) as `least_squares_loss` returns them.
    """
    chex.assert_rank([reference_logits, policy_logits], 1)
    reference_term = jnp.mean(jax.nn.softplus(-reference_logits))
    policy_term = jnp.mean(jax.nn.softplus(policy_logits))
    return _loss_with_metrics(reference_term, policy_term, reference_logits, policy_logits)


def logistic_reward(logits: Array, max_reward: float | Array = LOGISTIC_MAX_REWARD) -> Array:
    """The style reward that matches `logistic_loss`: min(-log(1 - D), max_reward).

    -log(1 - sigmoid(d)) = softplus(d): log 2 at d = 0, -> 0 as d -> -inf (it is never
    negative, so no lower clip is needed) and ~d for large d. The cap keeps one sample
    the discriminator is sure of from dominating the returns; the default,
    `LOGISTIC_MAX_REWARD` = log(1e4) ~ 9.21, is reached at D = 1 - 1e-4.

    Args:
      logits: [...] discriminator logits.
      max_reward: scalar > 0, the upper clip.

    Returns:
      [...] rewards in [0, max_reward].
    """
    chex.assert_rank(max_reward, 0)
    return jnp.minimum(jax.nn.softplus(logits), max_reward)


def _scalar_logit(apply_fn: ApplyFn) -> Callable[[PyTree, PyTree], Array]:
    """Wraps a per-sample apply_fn so it returns a scalar; [1] (an `mlp(1)`) is accepted."""

    def logit(params: PyTree, x: PyTree) -> Array:
        out = apply_fn(params, x)
        if jnp.shape(out) not in ((), (1,)):
            raise ValueError(f"apply_fn must map one sample to one logit (shape () or (1,)), got {jnp.shape(out)}")
        return jnp.reshape(out, ())

    return logit


def _batch_size(name: str, inputs: PyTree) -> int:
    sizes = {jnp.shape(x)[0] if jnp.ndim(x) >= 1 else None for x in jax.tree.leaves(inputs)}
    if len(sizes) != 1 or None in sizes:
        raise ValueError(f"{name} must be arrays with one common leading (sample) axis, got sizes {sizes}")
    return sizes.pop()


def _logits_and_penalty(apply_fn: ApplyFn, params: PyTree, inputs: PyTree) -> tuple[Array, Array]:
    """Logits [B] and mean per-sample squared input-gradient norm, from one pass."""
    logits, grads = jax.vmap(jax.value_and_grad(_scalar_logit(apply_fn), argnums=1), in_axes=(None, 0))(params, inputs)
    squared_norms = sum(jnp.sum(jnp.reshape(jnp.square(g), (g.shape[0], -1)), axis=1) for g in jax.tree.leaves(grads))
    return logits, jnp.mean(squared_norms)


def gradient_penalty(apply_fn: ApplyFn, params: PyTree, inputs: PyTree) -> Array:
    """The gradient penalty: mean over samples of |d logit / d input|^2.

      penalty = mean_i || grad_x d(x_i) ||^2

    The gradient is taken per sample (`jax.vmap` of `jax.grad`), so each norm is exact
    whatever the network (the gradient of a batch sum would mix samples wherever the
    network couples them, e.g. through batch statistics). AMP penalizes it on
    reference samples; its equation writes the weight as w_gp / 2 with w_gp = 10, which
    is a weight of 5 on this function (no factor 1/2 here).

    Args:
      apply_fn: (params, x) -> logit for ONE sample x (shape () or (1,)); vmapped here.
      params: the discriminator's parameters.
      inputs: [B, ...] samples (an array, or a pytree of arrays with leading axis B).

    Returns:
      Scalar penalty, differentiable in `params`.
    """
    _batch_size("gradient_penalty: inputs", inputs)
    return _logits_and_penalty(apply_fn, params, inputs)[1]


def logit_l2(logit_layer_weights: PyTree) -> Array:
    """Sum of squares of the logit (last) layer's weights, as AMP's code penalizes them.

    A SUM, not a mean, as AMP implementations penalize it (with weights 0.01 to 0.05).
    Pass the kernel only (see `last_kernel`); biases are not penalized.

    Args:
      logit_layer_weights: an array (e.g. the [H, 1] kernel) or a pytree of arrays.

    Returns:
      Scalar.
    """
    return sum(jnp.sum(jnp.square(w)) for w in jax.tree.leaves(logit_layer_weights))


def last_kernel(params: list[dict[str, Array]]) -> Array:
    """The logit layer's kernel in `mjzoo.learning.networks.mlp`'s params: params[-1]["kernel"]."""
    return params[-1]["kernel"]


def _check_kind(kind: str) -> None:
    if kind not in _KINDS:
        raise ValueError(f"kind={kind!r} must be one of {_KINDS}")


def discriminator_loss(
    kind: Kind,
    apply_fn: ApplyFn,
    params: PyTree,
    reference: PyTree,
    policy: PyTree,
    gradient_penalty_weight: float | Array = 5.0,
    policy_gradient_penalty: bool = False,
    logit_l2_weight: float | Array = 0.0,
    logit_weights: Callable[[PyTree], PyTree] = last_kernel,
) -> tuple[Array, dict[str, Array]]:
    """The whole discriminator objective of AMP, to be minimized over `params`.

      loss = <kind>_loss(d(reference), d(policy))
             + gradient_penalty_weight * penalty
             + logit_l2_weight * logit_l2(logit_weights(params))

    penalty is `gradient_penalty` on the reference samples or, with
    `policy_gradient_penalty`, the average of the reference and the policy penalties
    (so turning it on does not double the regularization).

    Args:
      kind: "least_squares" or "logistic".
      apply_fn: (params, x) -> logit for ONE sample (shape () or (1,)).
      params: the discriminator's parameters.
      reference: [B, F] reference-motion features (or a pytree with leading axis B).
      policy: [B', F] policy features (e.g. half fresh, half from a `replay` buffer).
      gradient_penalty_weight: scalar >= 0 (5.0 is the AMP paper's w_gp / 2 = 10 / 2).
      policy_gradient_penalty: also penalize the gradient at policy samples (static).
      logit_l2_weight: scalar >= 0 on the sum of squares of the logit layer's weights.
      logit_weights: params -> the weights `logit_l2` penalizes; `last_kernel` fits
        `mjzoo.learning.networks.mlp`.

    Returns:
      (loss, metrics): the `<kind>_loss` metrics plus "disc/gradient_penalty" (and
      "disc/gradient_penalty_policy" when computed), "disc/logit_l2" and "disc/loss".
    """
    _check_kind(kind)
    _batch_size("discriminator_loss: reference", reference)
    _batch_size("discriminator_loss: policy", policy)
    chex.assert_rank([gradient_penalty_weight, logit_l2_weight], 0)
    ref_logits, penalty = _logits_and_penalty(apply_fn, params, reference)
    metrics = {"disc/gradient_penalty": penalty}
    if policy_gradient_penalty:
        pol_logits, policy_penalty = _logits_and_penalty(apply_fn, params, policy)
        metrics["disc/gradient_penalty_policy"] = policy_penalty
        penalty = 0.5 * (penalty + policy_penalty)
    else:
        pol_logits = jax.vmap(_scalar_logit(apply_fn), in_axes=(None, 0))(params, policy)
    loss_fn = least_squares_loss if kind == "least_squares" else logistic_loss
    loss, kind_metrics = loss_fn(ref_logits, pol_logits)
    l2 = logit_l2(logit_weights(params))
    loss = loss + gradient_penalty_weight * penalty + logit_l2_weight * l2
    metrics = jax.lax.stop_gradient(metrics | {"disc/logit_l2": l2, "disc/loss": loss})
    return loss, kind_metrics | metrics


def style_reward(kind: Kind, logits: Array, max_reward: float | Array = LOGISTIC_MAX_REWARD) -> Array:
    """The style reward of `kind` for [...] logits: `least_squares_reward` or
    `logistic_reward` (with `max_reward`, which the least-squares reward ignores: it is
    at most 1). Returns [...], without gradient (a reward is data to the policy)."""
    _check_kind(kind)
    logits = jax.lax.stop_gradient(logits)
    return least_squares_reward(logits) if kind == "least_squares" else logistic_reward(logits, max_reward)


def _is_kernel(params: PyTree) -> PyTree:
    return jax.tree.map(lambda x: jnp.ndim(x) >= 2, params)


def _known(value: Any) -> bool:
    """A host number (not a traced one, nor an array of several)."""
    return not isinstance(value, jax.core.Tracer) and jnp.ndim(value) == 0


def discriminator_optimizer(
    learning_rate: float | optax.Schedule,
    weight_decay: float = 1e-4,
    max_grad_norm: float | None = None,
) -> optax.GradientTransformation:
    """Adam for the discriminator, with decoupled weight decay and gradient clipping.

      clip_by_global_norm(max_grad_norm)  (skipped when None)
      -> adamw(learning_rate, weight_decay, mask = leaves of rank >= 2)

    Weight decay applies to weight matrices (kernels) only, never to biases; it is
    AdamW's decoupled decay (lr * weight_decay * w per step), not an L2 term in the loss.

    Args:
      learning_rate: > 0 (traced or not), or an optax schedule.
      weight_decay: >= 0 (traced or not).
      max_grad_norm: > 0 (traced or not; inf: no effect), or None for no clipping.

    Returns:
      An optax `GradientTransformation`; `update` needs the params (for the decay).
    """
    # Numbers are checked where they are numbers: traced ones (a hyperparameter sweep) are
    # the caller's to check (AMP's Hyperparams are, on the host).
    if _known(learning_rate) and not callable(learning_rate) and not learning_rate > 0:
        raise ValueError(f"discriminator_optimizer: learning_rate={learning_rate!r} must be > 0 or a schedule")
    if _known(weight_decay) and not weight_decay >= 0:
        raise ValueError(f"discriminator_optimizer: weight_decay={weight_decay!r} must be >= 0")
    if max_grad_norm is not None and _known(max_grad_norm) and not max_grad_norm > 0:
        raise ValueError(f"discriminator_optimizer: max_grad_norm={max_grad_norm!r} must be > 0 or None")
    adam = optax.adamw(learning_rate, weight_decay=weight_decay, mask=_is_kernel)
    return adam if max_grad_norm is None else optax.chain(optax.clip_by_global_norm(max_grad_norm), adam)
