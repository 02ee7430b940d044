"""Conformance: every registered env, bare and under a stack of every combinator, and
each combinator the stack leaves out alone on the cheapest env, passes `mjzoo.testing.check_task` (jit, vmap,
shapes and dtypes, finite values, determinism per key, no retrace for new numbers, the
time limit) with one compile, and a task rebuilt by its factory with other weights and a
heavier body runs under that compile. (The full env x combinator matrix costs a compile
per cell: the stack puts every env through every combinator at the price of one.)

The stack ("all") nests them as the catalog says they must (docs/catalog.md): action
filters, trackers, commands, history, terminations and randomization inside the episode's
time limit and auto-reset, which the curriculum's tasks add (with force pushes), and the
curriculum outside them. Left out of it: "resets" (its `observe` is the pendulum's own),
"time_limit" and "auto_reset" (the curriculum's tasks have them). Combinators keep
their state in records of their own (`State.layers`), so the stack applies some twice:
"domain_randomization" next to "randomizers", "action_history" next to the
"reward_terms" entry's, "force_pushes" next to the curriculum's. The "twice" case nests
time limits and observation noises around an action repeat: the inner limit still
truncates at its own step count, which check_task's time-limit check sees."""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import pytest

import mjzoo
import mjzoo.envs
from mjzoo import names
from mjzoo.catalog import actuators
from mjzoo.catalog import commands
from mjzoo.catalog import curriculum
from mjzoo.catalog import events
from mjzoo.catalog import observations
from mjzoo.catalog import randomizers
from mjzoo.catalog import resets
from mjzoo.catalog import rewards
from mjzoo.catalog import terminations
from mjzoo.catalog import trackers
from mjzoo.envs import pendulum
from mjzoo.testing import TaskReport
from mjzoo.testing import check_task

# Every env is made with episodes of LIMIT steps, so that check_task sees its time limit
# within its rollout of STEPS (a longer limit costs it a second compile).
LIMIT, STEPS = 6, 10


def _heavier(model, key):
    return {"body_mass": model.body_mass * jax.random.uniform(key, model.body_mass.shape, minval=0.8, maxval=1.2)}


def _alive(model, state, action, next_state):
    return jnp.float32(1.0)


def _head(obs):
    return obs[:2]


def _pendulum_observe(model, state):
    return pendulum.observe(state.data)


def _last_body(t: mjzoo.Task) -> str:
    return [n for n in names.all_names(t.mj_model, "body") if not n.startswith("<")][-1]  # "<body 13>": unnamed


def _first_joint(t: mjzoo.Task) -> str:
    return names.all_names(t.mj_model, "joint", names.joints(t.mj_model, None, "conformance")[:1])[0]


def _pushed(t: mjzoo.Task, level: float) -> mjzoo.Task:
    """`t` pushed with forces up to 2 level N inside a 5-step auto-resetting episode."""
    pushed = events.with_force_pushes(t, _last_body(t), (0.04, 0.1), (2 * level, 2 * level, 0), 0.04)
    return mjzoo.with_auto_reset(mjzoo.with_time_limit(pushed, 5))


def _randomized(t: mjzoo.Task) -> mjzoo.Task:
    m = t.mj_model
    draw = randomizers.combine(
        randomizers.scale_masses(m),
        randomizers.add_masses(m, -0.01, 0.01),
        randomizers.shift_com(m),
        randomizers.scale_damping(m),
        randomizers.scale_armature(m),
        randomizers.scale_friction(m),
    )
    return mjzoo.with_domain_randomization(t, draw)


def _terminated(t: mjzoo.Task) -> mjzoo.Task:
    return terminations.with_terminations(
        t,
        {
            "fast": terminations.bad_velocity(100.0),
            "long": terminations.episode_length(1000),
            "low": terminations.base_too_low(t.mj_model, -10.0, body=_last_body(t)),
        },
    )


def _scored(t: mjzoo.Task) -> mjzoo.Task:
    return rewards.terms(
        trackers.with_action_history(t, 4),
        {
            "stay_alive": (rewards.alive(t), 0.1),
            "rate_cost": (rewards.action_rate, -0.01),  # names no env uses itself
            "jerk_cost": (rewards.action_jerk, -0.01),
            "torque": (rewards.torque, -0.01),
            "energy": (rewards.energy, -0.01),
            "joint_deviation": (rewards.joint_deviation(t.mj_model), -0.01),
        },
    )


def _twice(t: mjzoo.Task) -> mjzoo.Task:
    """Two time limits and two observation noises with an action repeat between them: the
    inner limit of 5 steps is 3 repeated steps, before the outer limit of 4."""
    inner = mjzoo.with_observation_noise(mjzoo.with_time_limit(t, 5), 0.1)
    return mjzoo.with_time_limit(mjzoo.with_observation_noise(mjzoo.with_action_repeat(inner, 2), 0.05), 4)


def _reset_noise(t: mjzoo.Task) -> mjzoo.Task:
    m = t.mj_model
    noise = resets.joint_position_noise(m, 0.1), resets.joint_velocities(m, 0.5)
    return resets.with_resets(t, *noise, observe=_pendulum_observe)


COMBINATORS = {
    "bare": lambda t: t,
    "time_limit": lambda t: mjzoo.with_time_limit(t, 5),
    "auto_reset": lambda t: mjzoo.with_auto_reset(mjzoo.with_time_limit(t, 5)),
    "action_repeat": lambda t: mjzoo.with_action_repeat(t, 2),
    "reward": lambda t: mjzoo.with_reward(t, "bonus", _alive, 0.5),
    "observation_noise": lambda t: mjzoo.with_observation_noise(t, 0.1),
    "action_noise": lambda t: mjzoo.with_action_noise(t, 0.1),
    "domain_randomization": lambda t: mjzoo.with_domain_randomization(t, _heavier),
    "divergence_guard": lambda t: mjzoo.with_divergence_guard(t, 1e3),
    "observation": lambda t: mjzoo.with_observation(t, _head),
    # the locomotion catalog
    "action_latency": lambda t: actuators.with_action_latency(t, 2),
    "action_drop": lambda t: actuators.with_action_drop(t, 0.2),
    "action_filter": lambda t: actuators.with_action_filter(t, 0.5),
    "reward_clip": lambda t: mjzoo.with_reward_clip(t, -1.0, 1.0),
    "randomizers": _randomized,
    "observation_history": lambda t: observations.with_observation_history(t, 3),
    "observation_bias": lambda t: observations.with_observation_bias(t, 0.1),
    "multiplicative_observation_noise": lambda t: observations.with_multiplicative_observation_noise(t, 0.1),
    "terminations": _terminated,
    "action_history": lambda t: trackers.with_action_history(t, 3),
    "reward_terms": _scored,
    "resets": _reset_noise,
    "force_pushes": lambda t: events.with_force_pushes(t, _last_body(t), (0.04, 0.1), (2, 2, 0), 0.04),
    "velocity_command": lambda t: commands.with_velocity_command(t, resample_interval=(0.04, 0.1)),
    "joint_position_command": lambda t: commands.with_joint_position_command(
        t, [_first_joint(t)], ranges=[(-0.5, 0.5)], resample_interval=(0.04, 0.1)
    ),
    "curriculum": lambda t: curriculum.with_curriculum(functools.partial(_pushed, t), curriculum.by_steps(10)),
    "twice": _twice,
}
ALL = (  # innermost first
    "action_latency",
    "action_drop",
    "action_filter",
    "action_history",
    "reward_terms",
    "force_pushes",
    "velocity_command",
    "joint_position_command",
    "observation_history",
    "observation_bias",
    "multiplicative_observation_noise",
    "terminations",
    "action_repeat",
    "reward",
    "observation_noise",
    "action_noise",
    "randomizers",
    "domain_randomization",
    "divergence_guard",
    "reward_clip",
    "curriculum",
    "observation",
)
COMBINATORS["all"] = lambda t: functools.reduce(lambda task, name: COMBINATORS[name](task), ALL, t)
# The envs on Brax's models run in test_conformance_locomotion(_stacked).py: one process compiling
# every case crashed inside XLA's CPU compiler, and the suite frees compiled code per module.
LOCOMOTION = [
    e
    for e in mjzoo.envs.names()
    if mjzoo.envs.factory(e).__module__
    in ("mjzoo.envs.locomotion", "mjzoo.envs.joystick", "mjzoo.envs.humanoid_amp", "mjzoo.envs.deepmimic")
]
# The real robots' joysticks (mjzoo[robots]) run check_task in tests/envs/test_robot_joystick.py:
# a robot's compile costs minutes of the suite's CPU.
# So do the tracking envs' (tests/envs/test_motion_tracking.py, tests/catalog/test_tracking.py)
# and the robot MPC tasks' (tests/envs/test_robot_planning.py, test_leap_cube.py, test_panda_pick.py).
ROBOTS = [
    e
    for e in mjzoo.envs.names()
    if mjzoo.envs.factory(e).__module__
    in (
        "mjzoo.envs.robot_joystick",
        "mjzoo.envs.motion_tracking",
        "mjzoo.envs.robot_amp",
        "mjzoo.envs.robot_planning",
        "mjzoo.envs.leap_cube",
        "mjzoo.envs.panda_pick",
    )
]
ENVS = [e for e in mjzoo.envs.names() if e not in LOCOMOTION + ROBOTS]
# The stack runs on one env per model: cartpole_swingup and cartpole_amp_swingup are
# cartpole_balance's model, bare here (each "all" case costs ~50 s of the suite's CPU).
STACK_SAME_MODEL_AS = {"cartpole_swingup": "cartpole_balance", "cartpole_amp_swingup": "cartpole_balance"}
CASES = [(env, comb) for env in ENVS for comb in ("bare", "all") if comb == "bare" or env not in STACK_SAME_MODEL_AS]
# Alone, the combinators the stack leaves out; those in it run in it on every env (and
# each is unit-tested in its own module: test_combinators.py, tests/catalog/).
CASES += [("pendulum_swingup", comb) for comb in COMBINATORS if comb not in ("bare", "all", *ALL)]


def task_for(env: str, comb: str, mass_scale: float = 1.0, **numbers) -> mjzoo.Task:
    """The case's task, its bodies `mass_scale` times as heavy. The stack keeps its env's
    long default limit: the curriculum's limit of 5 steps inside it comes first."""
    base = mjzoo.envs.make(env, **({} if comb == "all" else dict(episode_steps=LIMIT)), **numbers)
    return COMBINATORS[comb](base.replace(model=base.model.replace(body_mass=base.model.body_mass * mass_scale)))


@functools.cache
def report_for(env: str, comb: str) -> TaskReport:
    """check_task's report on a case (its one compile, shared by the case's tests)."""
    return check_task(task_for(env, comb), num_steps=STEPS)


@pytest.mark.parametrize("env,comb", CASES)
def test_conformance(env, comb):
    check_conformance(env, comb)


def check_conformance(env: str, comb: str) -> None:
    report = report_for(env, comb)
    assert report.skipped == {}  # every case has a time limit, which it keeps
    assert report.traces <= 1  # one compile (none when another test of the case ran first)


@pytest.mark.parametrize("env,comb", CASES)
def test_new_numbers_do_not_retrace(env, comb):
    check_new_numbers_do_not_retrace(env, comb)


def check_new_numbers_do_not_retrace(env: str, comb: str) -> None:
    """A task its factory builds with another weight, and then a heavier body, runs under
    the case's trace: check_task's own no-retrace check nudges the leaves of one task, and
    would miss a factory argument that ends up static."""
    report_for(env, comb)  # the one trace (cached if already run)
    changed = task_for(env, comb, mass_scale=1.5, effort_weight=0.5)
    assert check_task(changed, num_steps=STEPS).traces == 0
