"""Networks as pairs of pure functions over explicit parameter pytrees.

Like optax's `GradientTransformation`, a `Network` is a NamedTuple of `init` and
`apply`; its parameters are a plain pytree of arrays (lists and dicts), so they pass
through `jax.jit`, `optax` and checkpoints with no framework in between, and their
layout is part of the documented interface.

Initialization: weights are LeCun-normal (truncated normal with variance 1/fan_in),
biases zero, and the last layer's weights are multiplied by `output_scale` (PPO uses
0.01 for the policy head, so the initial policy is near its mean action). The GRU's
recurrent weights are orthogonal, so the hidden state neither grows nor vanishes
through the recurrence at initialization.
"""

from __future__ import annotations

from typing import Any
from typing import Callable
from typing import NamedTuple
from typing import Sequence

import jax
import jax.numpy as jnp

__all__ = ["Network", "RecurrentNetwork", "mlp", "gru_mlp"]

Array = jax.Array
PyTree = Any


class Network(NamedTuple):
    """A feed-forward network as two pure functions.

    Attributes:
      init: ``(key, example_input) -> params``; only the example's last dim is read.
      apply: ``(params, input) -> output``.
    """

    init: Callable[[Array, Array], PyTree]
    apply: Callable[[PyTree, Array], Array]


class RecurrentNetwork(NamedTuple):
    """A recurrent network as three pure functions.

    Attributes:
      init: ``(key, example_input) -> params``.
      initial_carry: ``() -> carry``, the state at the start of an episode.
      apply: ``(params, carry, input, reset) -> (carry, output)``. `reset` is a bool
        scalar (or one per batch element) meaning "this input starts a new episode":
        the initial carry is used in place of the given one.
    """

    init: Callable[[Array, Array], PyTree]
    initial_carry: Callable[[], PyTree]
    apply: Callable[[PyTree, PyTree, Array, Array], tuple[PyTree, Array]]


def _dense_init(key: Array, in_size: int, out_size: int, scale: float = 1.0) -> dict[str, Array]:
    kernel = jax.nn.initializers.lecun_normal()(key, (in_size, out_size), jnp.float32)
    return {"kernel": scale * kernel, "bias": jnp.zeros((out_size,), jnp.float32)}


def _dense(layer: dict[str, Array], x: Array) -> Array:
    return x @ layer["kernel"] + layer["bias"]


def _layer_norm(x: Array, eps: float = 1e-5) -> Array:
    """x normalized over its last axis, in float32 whatever its dtype."""
    y = x.astype(jnp.float32)
    y = (y - jnp.mean(y, axis=-1, keepdims=True)) * jax.lax.rsqrt(jnp.var(y, axis=-1, keepdims=True) + eps)
    return y.astype(x.dtype)


def _check_positive(name: str, field: str, values: Any) -> None:
    """Raises unless every one of `values` (an int or a sequence of ints) is an int >= 1."""
    items = tuple(values) if isinstance(values, Sequence) else (values,)
    if any(isinstance(v, bool) or not isinstance(v, int) or v < 1 for v in items):
        raise ValueError(f"{name}: {field}={values!r} must be positive integers")


def _input_size(name: str, example_input: Array) -> int:
    shape = jnp.shape(example_input)
    if len(shape) < 1:
        raise ValueError(f"{name}: the example input must have a feature axis, got shape {shape}")
    return int(shape[-1])


def mlp(
    output_size: int,
    hidden_sizes: Sequence[int] = (256, 256),
    activation: Callable[[Array], Array] = jax.nn.swish,
    output_scale: float = 1.0,
    compute_dtype: Any = jnp.float32,
    layer_norm: bool = False,
) -> Network:
    """A multi-layer perceptron: dense layers with `activation` between them, none after
    the last.

    Params: a list of ``{"kernel": [in, out], "bias": [out]}``, one per layer, the
    output layer last.

    Args:
      output_size: the size of the output's last axis.
      hidden_sizes: sizes of the hidden layers, in order; () gives a linear map.
      activation: applied elementwise after each hidden layer.
      output_scale: factor on the output layer's initial weights.
      compute_dtype: the dtype of the hidden layers' arithmetic. `jnp.bfloat16` is mixed
        precision: params stay float32 (so do gradients and the optimizer), the input
        and hidden weights are cast, and the output layer runs in float32, so a value
        head of large returns keeps its resolution.
      layer_norm: normalize each hidden layer's pre-activations to zero mean and unit
        variance over its features (no learned scale, so the params are the same);
        off-policy critics use it against value overestimation.

    Returns:
      A `Network` whose apply maps [..., in] -> [..., output_size] (float32), for any
      leading batch dims.
    """
    _check_positive("mlp", "output_size", output_size)
    _check_positive("mlp", "hidden_sizes", hidden_sizes)
    sizes = (*hidden_sizes, output_size)

    def init(key: Array, example_input: Array) -> list[dict[str, Array]]:
        in_sizes = (_input_size("mlp.init", example_input), *sizes[:-1])
        keys = jax.random.split(key, len(sizes))
        return [
            _dense_init(k, i, o, output_scale if last else 1.0)
            for k, i, o, last in zip(keys, in_sizes, sizes, [False] * (len(sizes) - 1) + [True])
        ]

    def apply(params: list[dict[str, Array]], x: Array) -> Array:
        expected = params[0]["kernel"].shape[0]
        if jnp.ndim(x) < 1 or jnp.shape(x)[-1] != expected:
            raise ValueError(f"mlp.apply: input shape {jnp.shape(x)} must end in the input size {expected}")
        x = x.astype(compute_dtype)
        for layer in params[:-1]:
            x = _dense(jax.tree.map(lambda p: p.astype(compute_dtype), layer), x)
            x = activation(_layer_norm(x) if layer_norm else x)
        return _dense(params[-1], x.astype(jnp.float32))

    return Network(init=init, apply=apply)


def gru_mlp(
    output_size: int,
    hidden_size: int = 64,
    mlp_hidden_sizes: Sequence[int] = (64,),
    activation: Callable[[Array], Array] = jax.nn.swish,
    output_scale: float = 1.0,
) -> RecurrentNetwork:
    """Dense encoder -> GRU cell -> MLP head, for policies and values with memory.

    With e = activation(W_e x + b_e) the encoded input and h the carry, the GRU cell
    (Cho et al., 2014, in the convention of PyTorch's `GRUCell`) is

      r  = sigmoid(W_ir e + b_ir + W_hr h + b_hr)        reset gate
      z  = sigmoid(W_iz e + b_iz + W_hz h + b_hz)        update gate
      n  = tanh(W_in e + b_in + r * (W_hn h + b_hn))     candidate state
      h' = (1 - z) * n + z * h

    and the output is mlp_head(h'). The new carry is h'.

    Params: ``{"encoder": {"kernel", "bias"}, "gru": {"input_kernel": [hidden, 3H],
    "recurrent_kernel": [H, 3H], "input_bias": [3H], "recurrent_bias": [3H]},
    "head": <mlp params>}``, gates stacked in the order (r, z, n).

    Args:
      output_size: the size of the output's last axis.
      hidden_size: H, the width of the encoder and of the GRU's state.
      mlp_hidden_sizes: hidden layers of the head.
      activation: used in the encoder and the head.
      output_scale: factor on the head's last-layer initial weights.

    Returns:
      A `RecurrentNetwork`. apply is written for one input, carry [H] and input [in],
      with reset a bool scalar; callers `jax.vmap` it. (Matching leading batch dims on
      carry, input and reset, [B, H], [B, in] and [B], also work without vmap.)
    """
    _check_positive("gru_mlp", "output_size", output_size)
    _check_positive("gru_mlp", "hidden_size", hidden_size)
    head = mlp(output_size, mlp_hidden_sizes, activation, output_scale)
    size = hidden_size

    def init(key: Array, example_input: Array) -> dict[str, PyTree]:
        in_size = _input_size("gru_mlp.init", example_input)
        k_enc, k_in, k_rec, k_head = jax.random.split(key, 4)
        # Orthogonal per gate, so each gate's recurrent map is norm-preserving.
        recurrent = jnp.concatenate(
            [jax.nn.initializers.orthogonal()(k, (size, size), jnp.float32) for k in jax.random.split(k_rec, 3)],
            axis=1,
        )
        gru = {
            "input_kernel": jax.nn.initializers.lecun_normal()(k_in, (size, 3 * size), jnp.float32),
            "recurrent_kernel": recurrent,
            "input_bias": jnp.zeros((3 * size,), jnp.float32),
            "recurrent_bias": jnp.zeros((3 * size,), jnp.float32),
        }
        return {
            "encoder": _dense_init(k_enc, in_size, size),
            "gru": gru,
            "head": head.init(k_head, jnp.zeros((size,), jnp.float32)),
        }

    def initial_carry() -> Array:
        return jnp.zeros((size,), jnp.float32)

    def apply(params: dict[str, PyTree], carry: Array, x: Array, reset: Array) -> tuple[Array, Array]:
        reset = jnp.asarray(reset)
        if jnp.shape(carry)[-1:] != (size,) or jnp.shape(reset) != jnp.shape(carry)[:-1]:
            raise ValueError(
                f"gru_mlp.apply: carry shape {jnp.shape(carry)} must be [..., {size}] and reset shape "
                f"{jnp.shape(reset)} its leading dims"
            )
        if reset.dtype != jnp.bool_:
            raise ValueError(f"gru_mlp.apply: reset must be bool, got {reset.dtype}")
        h = jnp.where(reset[..., None], initial_carry(), carry)
        e = activation(_dense(params["encoder"], x))
        h = _gru_cell(params["gru"], h, e)
        return h, head.apply(params["head"], h)

    return RecurrentNetwork(init=init, initial_carry=initial_carry, apply=apply)


def _gru_cell(params: dict[str, Array], h: Array, e: Array) -> Array:
    """One GRU step, h [..., H], e [..., H] -> h' [..., H]; equations in `gru_mlp`."""
    x_r, x_z, x_n = jnp.split(e @ params["input_kernel"] + params["input_bias"], 3, axis=-1)
    h_r, h_z, h_n = jnp.split(h @ params["recurrent_kernel"] + params["recurrent_bias"], 3, axis=-1)
    r = jax.nn.sigmoid(x_r + h_r)
    z = jax.nn.sigmoid(x_z + h_z)
    n = jnp.tanh(x_n + r * h_n)
    return (1.0 - z) * n + z * h
