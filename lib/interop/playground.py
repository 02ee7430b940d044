"""MuJoCo Playground environments as mjzoo tasks, for PPO, AMP and the sampling planners.

    task = mjzoo.interop.playground.task("CartpoleBalance")             # by Playground's name
    task = mjzoo.interop.playground.task("CheetahRun", ctrl_dt=0.02)    # its config, overridden
    task = mjzoo.interop.playground.task(my_env)                        # any bare `MjxEnv`
    mjzoo train ppo playground:CartpoleBalance                          # from the command line

Needs ``pip install 'mjzoo[playground]'`` (the `playground` package, `mujoco_playground`).
One Playground transition becomes one mjzoo transition:

  Playground State        mjzoo State
  data, obs               data, obs (a dict observation stays a dict: PPO's `policy_obs_key`)
  reward                  the one reward term ``"playground"``: `reward` and ``metrics["reward/playground"]``
  done                    terminated (Playground's `done` ends an episode without bootstrap)
  (episode_length)        truncated, by `mjzoo.with_time_limit` at the config's `episode_length`
  metrics[k]              ``metrics["playground/<k>"]``: the env's own reward components
                          (``"playground/reward/upright"``) kept apart from mjzoo's reward terms
  info                    ``info["playground"]``: the env's info as it returned it, its ``"rng"``
                          (uint32 key data) included; the env's randomness comes from there, as
                          under Playground's own wrappers, so mjzoo's step key is not used

Playground's reset is given ``jax.random.key_data(key)`` of mjzoo's reset key. The task is
guarded against diverging physics (`mjzoo.with_divergence_guard`, ``metrics["diverged"]``).

How the env object passes through `jax.jit`: it is a Python object holding Python numbers
(its config, reward constants), so it is bound as static pytree metadata (`tree.StaticValue`,
equal by identity): tasks made from one env share a trace; a second env of the same name
compiles again. The physics model is `task.model`, a leaf: while the env's reset or step
is traced, its ``_mjx_model`` is set to the model the task is called with (Playground's own
domain-randomization wrapper does the same), so edits of `task.model` (masses, gains,
`mjzoo.with_domain_randomization`) apply without recompiling. The env's other numbers are
trace constants: `mjzoo.params` finds no named numbers and `with_params` has nothing to
change; change them with config overrides, which build a new env (and compile again).

Physics defaults to MJX's JAX implementation (Playground's DM Control configs say
``impl="warp"``): pass ``impl="warp"`` for MuJoCo Warp. Native C rollouts
(`mjzoo.planning.native`) cannot replay these tasks: Playground steps MJX itself.
"""

from __future__ import annotations

import atexit
import difflib
import functools
import inspect
import shutil
import subprocess
import tempfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import jax.numpy as jnp
from mujoco_playground import MjxEnv
from mujoco_playground import registry
from mujoco_playground._src import dm_control_suite
from mujoco_playground._src import locomotion
from mujoco_playground._src import manipulation
from mujoco_playground._src import mjx_env

from mjzoo import physics
from mjzoo import robots
from mjzoo.catalog import tracking
from mjzoo.interop import _foreign
from mjzoo.types import Task

__all__ = ["task", "load", "names", "brax_ppo_config", "NAME"]

NAME = "playground"  # the reward term's name, the info key and the metrics prefix
DEFAULT_IMPL = "jax"  # runs on any device; Playground's DM Control configs default to Warp
# Playground's done ends an episode (its time limit is a wrapper's, which mjzoo's replaces).
_KIND = _foreign.Kind(NAME, model_attr="_mjx_model", data_field="data", state_type=mjx_env.State)


# --- finding and loading envs -----------------------------------------------------------


def names() -> list[str]:
    """Every env in Playground's registry, sorted."""
    return sorted(registry.ALL_ENVS)


def offline_names() -> list[str]:
    """The envs whose assets ship with the package (the DM Control Suite), sorted."""
    return sorted(dm_control_suite.ALL_ENVS)


def robots_of(name: str) -> tuple[str, ...]:
    """The Menagerie robots env `name` loads (none for the DM Control Suite)."""
    envs = {**locomotion._envs, **manipulation._envs}
    if _checked_name(name) not in envs:
        return ()
    module = getattr(envs[name], "func", envs[name]).__module__  # mujoco_playground._src.<suite>.<folder>.<file>
    folder = "/".join(module.split(".")[2:4])
    if folder == "manipulation/franka_emika_panda_robotiq":
        return ("franka_emika_panda", "robotiq_2f85_v4")
    return tuple(robot for robot, f in robots.models.PLAYGROUND_FOLDERS.items() if f == folder)


def needs_network(name: str) -> bool:
    """Whether loading `name` needs robot models that no offline source here holds
    (`mjzoo.robots`: a user's folder, the mujoco-menagerie package's cache, EnvPool's
    wheels), and Playground's own clone of Menagerie is absent too."""
    if mjx_env.MENAGERIE_PATH.exists():
        return False
    return any(all(s.path is None for s in robots.where(r)) for r in robots_of(name))


@functools.lru_cache(maxsize=1)
def _menagerie_folder() -> Path:
    """This process's Menagerie folder for Playground: links to each robot's folder,
    wherever `mjzoo.robots` found it (Playground reads one folder, the wheels are two)."""
    folder = tempfile.mkdtemp(prefix="mjzoo-menagerie-")
    atexit.register(shutil.rmtree, folder, True)  # the links only: rmtree does not follow them
    return Path(folder)


def _point_playground_at_models(name: str) -> None:
    """Sets Playground's ``MENAGERIE_PATH`` to a folder linking the robots `name` needs,
    as `mjzoo.robots` resolves them; nothing on disk of Playground's is changed. A
    Menagerie clone of Playground's own, where one exists, is left in charge."""
    needed, current = robots_of(name), mjx_env.MENAGERIE_PATH
    if not needed or (current.exists() and current != _menagerie_folder()):
        return
    folder = _menagerie_folder()
    for robot in needed:
        if not (folder / robot).exists():
            (folder / robot).symlink_to(robots.menagerie(robot), target_is_directory=True)
    mjx_env.MENAGERIE_PATH = folder


def _checked_name(name: str) -> str:
    if name not in registry.ALL_ENVS:
        close = difflib.get_close_matches(name, registry.ALL_ENVS, n=3, cutoff=0.5)
        hint = f" (did you mean {', '.join(close)}?)" if close else ""
        raise KeyError(
            f"unknown Playground env {name!r}{hint}; the DM Control Suite envs: {', '.join(offline_names())}"
        )
    return name


def config_defaults(name: str) -> dict[str, Any]:
    """The env's config as flat ``{"a.b": value}`` overrides (the keys `task` takes), with
    ``impl`` the adapter's default."""
    flat = _flattened(registry.get_default_config(_checked_name(name)).to_dict())
    return {**flat, "impl": DEFAULT_IMPL} if "impl" in flat else flat


def _flattened(config: dict, prefix: str = "") -> dict[str, Any]:
    flat = {}
    for key, value in config.items():
        if isinstance(value, dict):
            flat.update(_flattened(value, f"{prefix}{key}."))
        else:
            flat[f"{prefix}{key}"] = value
    return flat


def load(name: str, **config_overrides: Any) -> MjxEnv:
    """Playground's env `name` with its default config and `config_overrides` (flat keys,
    "vision_config.nworld" for nested ones); ``impl`` defaults to "jax". On Warp, its
    model's overflow prints are off (`mjzoo.physics.quiet`), for mjzoo and any other trainer.

    The robots of the locomotion and manipulation envs come from `mjzoo.robots` (offline
    from EnvPool's wheels with ``pip install 'mjzoo[robots]'``): Playground is pointed at
    them instead of cloning Menagerie from GitHub.

    Raises KeyError for an unknown env (naming near ones), TypeError for an unknown
    override or one of the wrong type, `mjzoo.robots.ModelNotFoundError` when a robot's
    model is nowhere to be found, RuntimeError when Playground's own fetch of it fails.
    """
    allowed = config_defaults(name)
    unknown = sorted(set(config_overrides) - set(allowed))
    if unknown:
        raise TypeError(f"playground:{name}: unknown config override(s) {unknown}; its config: {sorted(allowed)}")
    overrides = {**({"impl": DEFAULT_IMPL} if "impl" in allowed else {}), **config_overrides}
    _point_playground_at_models(name)
    try:
        env = registry.load(name, config_overrides=overrides)
    except subprocess.CalledProcessError as error:  # locomotion and manipulation clone their robots
        raise RuntimeError(
            f"playground:{name}: could not fetch its robot assets (mujoco_menagerie, cloned from "
            f"GitHub at first use): {error}"
        ) from error
    except (TypeError, ValueError) as error:  # ConfigDict's type check names the field
        raise TypeError(f"playground:{name}: config override rejected: {error}") from error
    env._mjx_model = physics.quiet(env._mjx_model)  # for whoever steps it: mjzoo, Brax
    _fit_to_current_jax(env)
    return env


def _fit_to_current_jax(env: MjxEnv) -> None:
    """Playground's LEAP cube envs measure the cube's orientation error with
    ``jnp.clip(x, a_max=1.0)``, a keyword JAX 0.10 removed: this env object (not its class)
    gets the same error written for today's JAX, for whoever steps it (mjzoo, Brax)."""
    if hasattr(env, "_cube_orientation_error") and "a_max" not in inspect.signature(jnp.clip).parameters:
        env._cube_orientation_error = functools.partial(_cube_orientation_error, env)


def _cube_orientation_error(env: MjxEnv, data: Any) -> Any:
    """[] rad: Playground's ``_cube_orientation_error`` of its LEAP hand envs, the angle
    of the rotation from the cube's goal to the cube (its 2 asin(|v|) of q g^-1 = (w, v))."""
    return tracking.quat_angle(env.get_cube_goal_orientation(data), env.get_cube_orientation(data))


# --- the adapter --------------------------------------------------------------------------


def task(env_or_name: str | MjxEnv, **config_overrides: Any) -> Task:
    """A Playground env as an mjzoo `Task` (see the module docstring for the mapping).

    Args:
      env_or_name: a registry name ("CartpoleBalance") or a bare `MjxEnv` instance (not a
        Playground wrapper: mjzoo's combinators replace those).
      **config_overrides: the env's config fields (`config_defaults` lists them), only with
        a name.

    Returns:
      A Task with action ``[env.action_size]``, the env's observation, one reward term,
      guarded against divergence and truncated after the config's ``episode_length``
      control steps (no time limit if the env's config has none).
    """
    if isinstance(env_or_name, str):
        env = load(env_or_name, **config_overrides)
    elif isinstance(env_or_name, MjxEnv):
        if config_overrides:
            raise TypeError(
                f"playground.task: config overrides {sorted(config_overrides)} apply when loading by "
                "name; build the env with them instead"
            )
        env = env_or_name
    else:
        raise TypeError(f"playground.task: expected a Playground env name or MjxEnv, got {type(env_or_name).__name__}")
    if env.unwrapped is not env:
        raise TypeError(
            f"playground.task: {type(env).__name__} is a Playground wrapper; pass the bare env "
            "(env.unwrapped) and use mjzoo's combinators (with_auto_reset, with_time_limit, "
            "with_domain_randomization) instead"
        )
    length = getattr(getattr(env, "_config", None), "episode_length", None)
    return _foreign.task(
        _KIND, env, _foreign.env_model(_KIND, env), env.mj_model, None if length is None else int(length)
    )


# --- Playground's tuned PPO, in mjzoo's terms ------------------------------------------------


def brax_ppo_config(name: str) -> Any:
    """Playground's tuned Brax PPO config for `name` (an ``ml_collections.ConfigDict``),
    from its suite's module: DM Control's, locomotion's or manipulation's params."""
    _checked_name(name)
    from mujoco_playground.config import dm_control_suite_params
    from mujoco_playground.config import locomotion_params
    from mujoco_playground.config import manipulation_params

    params = dm_control_suite_params
    if name in locomotion.ALL_ENVS:
        params = locomotion_params
    elif name in manipulation.ALL_ENVS:
        params = manipulation_params
    return params.brax_ppo_config(name)


def ppo_hyperparameters(name: str) -> dict[str, Any]:
    """Playground's tuned Brax PPO config for `name` as `mjzoo.algorithms.ppo.Config` fields.

    Brax collects ``batch_size * num_minibatches / num_envs`` unrolls per env per update;
    mjzoo collects one unroll that long. Networks default to Brax's (policy 4x32, value
    5x256, swish); Playground's `policy_obs_key` / `value_obs_key` are kept for an env that
    observes a dict (whose observation is then traced once), dropped for a flat one.
    """
    rl = brax_ppo_config(name)
    unrolls = max(1, rl.batch_size * rl.num_minibatches // rl.num_envs)
    network = rl.get("network_factory", {})
    config = dict(
        num_envs=rl.num_envs,
        unroll_length=rl.unroll_length * unrolls,
        num_minibatches=rl.num_minibatches,
        num_epochs=rl.num_updates_per_batch,
        learning_rate=rl.learning_rate,
        entropy_coef=rl.entropy_cost,
        discount=rl.discounting,
        reward_scaling=rl.reward_scaling,
        normalize_observations=rl.normalize_observations,
        gae_lambda=0.95,
        clip_epsilon=rl.get("clipping_epsilon", 0.3),
        max_grad_norm=rl.get("max_grad_norm", None),
        policy_hidden_sizes=tuple(network.get("policy_hidden_layer_sizes", (32,) * 4)),
        value_hidden_sizes=tuple(network.get("value_hidden_layer_sizes", (256,) * 5)),
        activation="swish",
        # Brax's PPO: a constant rate, value targets and rewards as they are (`ppo.PLAIN`,
        # which this layer does not import).
        lr_schedule="constant",
        value_normalization="none",
        reward_normalization=False,
        total_steps=rl.num_timesteps,
    )
    keys = {key: network[key] for key in ("policy_obs_key", "value_obs_key") if key in network}
    if keys and _observes_dict(name):  # Brax reads them from a dict observation alone (PandaPickCube's is flat)
        config.update(keys)
    return config


@functools.lru_cache(maxsize=None)
def _observes_dict(name: str) -> bool:
    """Whether Playground's env `name` observes a dict (loads it; its size traces a reset)."""
    return isinstance(load(name).observation_size, Mapping)
