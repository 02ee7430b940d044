"""iLQR: Newton-like steps on the plan from MJX's derivatives (jax.jacfwd), which C MuJoCo's rollouts lack.

    config = ilqr.Config(horizon_steps=50, iterations=4)    # structure: static under jit
    hyperparams = ilqr.Hyperparams(regularization=1e-2)      # numbers: pytree leaves
    state = ilqr.init(config, task, hyperparams)
    state, controls = jax.jit(ilqr.plan, static_argnums=0)(config, task, state, env_state, key)

Iterative LQR (Li and Todorov 2004) with the regularization and line search of Tassa,
Erez and Todorov (2012). The state is the planning task's x = (qpos, qvel, act); the plan
is one control per planning step, u_0 .. u_{H-1} (`PlannerState.knots` [H, nu], read
linearly between steps by a simulation with another timestep). The cost of a step is
minus the task's reward after it, l_t(x, u) = -r(x, u, f(x, u)), and the last step also
pays -V(f(x, u)) for a `terminal_value` V: the cost every planner here minimizes
(`mjzoo.planning.masked_cost`; steps after a termination of the nominal rollout count 0).
Each iteration, around the nominal trajectory (x^, u^):

    f_x, f_u                 jax.jacfwd of the task's transition (MJX's forward-mode AD)
    l_x, l_u                 jax.jacfwd of l_t, through the same step
    l_xx, l_uu, l_ux         central differences of those gradients (the reward's curvature
                             through one step included; the dynamics' own second
                             derivatives in the value recursion dropped: iLQR, not DDP)
    backward, t = H-1 .. 0, from V_x = 0, V_xx = 0:
      Q_x = l_x + f_x' V_x,  Q_u = l_u + f_u' V_x
      Q_xx = l_xx + f_x' V_xx f_x,  Q_uu = l_uu + f_u' V_xx f_u,  Q_ux = l_ux + f_u' V_xx f_x
      k = -(Q_uu+ + mu I)^-1 Q_u,  K = -(Q_uu+ + mu I)^-1 Q_ux    (free controls; Q_uu+: PSD part)
      V_x = Q_x + K' Q_uu k + K' Q_u + Q_ux' k,  V_xx = Q_xx + K' Q_uu K + K' Q_ux + Q_ux' K
    forward, for the step sizes alpha = 1, beta, .., beta^(L-1) at once (vmapped rollouts):
      u_t = clip(u^_t + alpha k_t + K_t (x_t - x^_t), low, high)

The lowest-cost candidate replaces the plan if it costs less (so the cost never rises),
and mu <- max(mu / Delta, mu_min); if none does, the plan and its derivatives stay and
mu <- mu Delta (a shorter, more cautious step). Q_uu's negative eigenvalues are floored at
0 before mu is added, so the step is always a descent direction.
The loop (`lax.while_loop`) ends after `iterations`, once a step lowers the cost by less
than `tolerance` x max(|cost|, 1), or when mu passes mu_max; mu carries over to the next
replan, which starts from the last plan shifted to the current time.

Control limits, by box projection: the forward pass clips each control into its range,
and the backward pass solves for the free controls only, a control being clamped when
the nominal sits at a limit and the unconstrained step pushes past it (its k and row of
K are zero): Box-DDP's active set (Tassa, Mansard and Todorov 2014) taken from one
Newton step instead of its box QP.

The derivatives cost (2n + 1) n forward-mode passes per planning step, n = nx + nu: cheap for a pendulum or a cart-pole, heavy for a
humanoid. Quaternion coordinates are differentiated as four numbers (the regularization
absorbs the redundant direction). MJX-JAX only: C MuJoCo rollouts (`backend="native"`)
and MJX-Warp have no JAX derivatives, and `Ensemble`s' risk measures are for sampling.
Defaults: 25 planning steps, 4 iterations, 8 step sizes (beta = 0.5), mu_0 = 1e-3,
Delta = 4, mu in [1e-6, 1e8], tolerance 1e-4.
"""

from __future__ import annotations

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from mjzoo import checks
from mjzoo import planning
from mjzoo.planning import PlannerState
from mjzoo.planning import TerminalValue
from mjzoo.planning.ensembles import Ensemble
from mjzoo.planning.learned import as_terminal_value
from mjzoo.planning.learned import committed
from mjzoo.planning.native import Native
from mjzoo.planning.sampling import _concrete
from mjzoo.running import fill_transition_entries
from mjzoo.running import transition
from mjzoo.types import State
from mjzoo.types import Task

__all__ = ["Config", "Hyperparams", "ILQRState", "BACKENDS", "init", "plan", "linearize", "backward", "rollout"]

Array = jax.Array
BACKENDS = ("mjx",)  # where `mjzoo.planning.realtime.Problem` may run it ("auto" picks mjx)


@dataclasses.dataclass(frozen=True, kw_only=True)
class Config:
    """iLQR's structure, a static argument of `plan`.

    Attributes:
      horizon_steps: planning steps per plan (H), each its own control.
      iterations: the most iLQR iterations per replan.
      line_search_steps: step sizes alpha = beta^i, i < L, tried at once in each forward pass (L).
      unroll: `lax.scan` unroll of the rollout loop.
      linearize_steps: planning steps linearized at once (vmapped; a `lax.map` runs the
        groups in turn). None: one at a time on a CPU, where larger batches run no
        faster and can hang (jaxlib 0.10's batched LAPACK solves wait on the thread pool
        they run in: two at once on a 2-core CPU wait forever, as MJX's contact solver's
        did at a 30-step horizon), the whole horizon on an accelerator.
    """

    horizon_steps: int = 25
    iterations: int = 4
    line_search_steps: int = 8
    unroll: int = 1
    linearize_steps: int | None = None

    def __post_init__(self) -> None:
        checks.fields(
            "ilqr.Config",
            self,
            {
                "horizon_steps": (self.horizon_steps >= 1, ">= 1"),
                "iterations": (self.iterations >= 1, ">= 1"),
                "line_search_steps": (self.line_search_steps >= 1, ">= 1"),
                "unroll": (self.unroll >= 1, ">= 1"),
                "linearize_steps": (self.linearize_steps is None or self.linearize_steps >= 1, "None or >= 1"),
            },
        )

    # What the closed loop reads of a plan (`planning.shift`, `planning.control_at`): one
    # knot per step, linear between them (exact at the steps, where float time may land
    # a hair before one).
    @property
    def num_knots(self) -> int:
        return self.horizon_steps

    @property
    def interpolation(self) -> str:
        return "linear"

    @property
    def num_samples(self) -> int:
        """Rollouts per iteration: the line search's candidates (the viewer's traces)."""
        return self.line_search_steps


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True, kw_only=True)
class Hyperparams:
    """iLQR's numbers: pytree leaves in `PlannerState.hyperparams`, swept by vmapping
    over planner states. Concrete values are checked at construction.

    Attributes:
      regularization: mu_0, added to Q_uu (cost / control^2), >= 0: the first replan's.
      regularization_factor: Delta > 1, mu's factor after a failed or successful step.
      regularization_min: mu's floor after a success, >= 0.
      regularization_max: past it a replan stops trying, > 0.
      step_decay: beta in (0, 1), the line search's ratio between step sizes.
      tolerance: a relative cost decrease below which a replan stops, >= 0.
      termination_cost: cost added once to a rollout whose task terminates.
    """

    regularization: float | Array = 1e-3
    regularization_factor: float | Array = 4.0
    regularization_min: float | Array = 1e-6
    regularization_max: float | Array = 1e8
    step_decay: float | Array = 0.5
    tolerance: float | Array = 1e-4
    termination_cost: float | Array = 0.0

    def __post_init__(self) -> None:
        names = [f.name for f in dataclasses.fields(self)]
        checks.fields(
            "ilqr.Hyperparams", self, {n: (not isinstance(getattr(self, n), (str, bool)), "a number") for n in names}
        )
        if _concrete(self):
            decay = np.logical_and(np.greater(self.step_decay, 0), np.less(self.step_decay, 1))
            checks.fields(
                "ilqr.Hyperparams",
                self,
                {
                    "regularization": (np.greater_equal(self.regularization, 0), ">= 0"),
                    "regularization_factor": (np.greater(self.regularization_factor, 1), "> 1"),
                    "regularization_min": (np.greater_equal(self.regularization_min, 0), ">= 0"),
                    "regularization_max": (np.greater(self.regularization_max, 0), "> 0"),
                    "step_decay": (decay, "in (0, 1)"),
                    "tolerance": (np.greater_equal(self.tolerance, 0), ">= 0"),
                    "termination_cost": (np.isfinite(self.termination_cost), "finite"),
                },
            )


@jax.tree_util.register_dataclass
@dataclasses.dataclass(frozen=True, kw_only=True)
class ILQRState(PlannerState):
    """`PlannerState` (knots: the plan's [H, nu] controls; std: zeros) plus mu
    (`regularization` []), the last replan's `iterations` [] and its `costs`
    [iterations + 1]: the plan's cost before the first iteration and after each
    (repeated once the loop stopped)."""

    regularization: Array
    iterations: Array
    costs: Array


def _check_task(task: object) -> Task:
    if isinstance(task, Native):
        raise TypeError(
            "ilqr: differentiates the planning task's MJX physics (jax.jacfwd), and native C MuJoCo "
            "rollouts have no JAX derivatives (their finite differences, mjd_transitionFD, are not "
            "wired in): plan with backend 'mjx'"
        )
    if isinstance(task, Ensemble):
        raise TypeError("ilqr: plans on one model; an Ensemble's risk over models is for the sampling planners")
    if not isinstance(task, Task):
        raise TypeError(f"ilqr: the planning task must be a mjzoo.Task, got {type(task).__name__}")
    return task


def init(
    config: Config, task: Task, hyperparams: Hyperparams | None = None, *, knots: Array | None = None
) -> ILQRState:
    """A zero plan (clipped into the limits) or the warm-start `knots` [H, nu], holding
    `hyperparams` (default `Hyperparams()`), mu = its `regularization`."""
    task = _check_task(task)
    hyperparams = Hyperparams() if hyperparams is None else hyperparams
    planning.sampling.check_hyperparams(hyperparams, Hyperparams)
    low, high = planning.control_limits(task)
    shape = (config.horizon_steps, low.shape[0])
    if knots is None:
        knots = jnp.clip(jnp.zeros(shape, jnp.float32), low, high)
    elif jnp.shape(knots) != shape:
        raise ValueError(
            f"ilqr.init: warm-start knots must have shape {shape} (horizon_steps, nu), got {jnp.shape(knots)}"
        )
    hyperparams = jax.tree.map(lambda x: jnp.asarray(x, jnp.float32), hyperparams)
    zero, inf = jnp.zeros((), jnp.float32), jnp.full((), jnp.inf, jnp.float32)
    return committed(
        ILQRState(
            knots=jnp.asarray(knots, jnp.float32),
            std=jnp.zeros(shape, jnp.float32),
            time=zero,
            dt=zero,
            cost=inf,
            hyperparams=hyperparams,
            regularization=hyperparams.regularization,
            iterations=zero,
            costs=jnp.full((config.iterations + 1,), jnp.inf, jnp.float32),
        )
    )


# --- the pieces: state vectors, rollouts, derivatives, the backward pass ------------------


def _vector(state: State) -> Array:
    """[nx] x = (qpos, qvel, act)."""
    data = state.data
    return jnp.concatenate([data.qpos, data.qvel, data.act])


def _with_vector(state: State, x: Array) -> State:
    """`state` with its physics at x (derived quantities are recomputed by the next step)."""
    data = state.data
    nq, nv = data.qpos.shape[0], data.qvel.shape[0]
    return state.replace(data=data.replace(qpos=x[:nq], qvel=x[nq : nq + nv], act=x[nq + nv :]))


def rollout(
    task: Task,
    start: State,
    controls: Array,
    gains: Array,
    reference: Array,
    keys: Array,
    low: Array,
    high: Array,
    terminal_value: TerminalValue | None = None,
    termination_cost: float | Array = 0.0,
    unroll: int = 1,
) -> tuple[Array, State, State, Array]:
    """A rollout under the affine policy u_t = clip(controls_t + gains_t (x_t - reference_t)).

    Args:
      controls: [H, nu] feedforward controls (u^ + alpha k).
      gains: [H, nu, nx] feedback gains K.
      reference: [H, nx] the states x^ the feedback is measured from.
      keys: [H] one key per step (shared by every candidate: common random numbers).

    Returns:
      ([H, nu] the controls applied, `State` [H] each step's start, the final `State`,
      [] the cost `planning.masked_cost` gives; +inf for NaN physics or controls).
    """

    def body(s: State, inputs) -> tuple[State, tuple]:
        u_ff, k_fb, x_ref, key = inputs
        u = jnp.clip(u_ff + k_fb @ (_vector(s) - x_ref), low, high)
        nxt = transition(task, s, u, key)
        return nxt, (u, s, nxt.reward, nxt.terminated)

    final, (applied, states, rewards, terminated) = jax.lax.scan(
        body, start, (controls, gains, reference, keys), unroll=unroll
    )
    value = terminal_value(task.model, final) if terminal_value is not None else 0.0
    cost = planning.masked_cost(rewards, terminated, value, termination_cost)
    finite = jnp.isfinite(cost) & jnp.all(jnp.isfinite(applied))  # NaN gains: a failed backward pass
    return applied, states, final, jnp.where(finite, cost, jnp.inf)


def linearize(
    task: Task,
    states: State,
    controls: Array,
    keys: Array,
    weights: Array,
    value_weights: Array,
    terminal_value: TerminalValue | None = None,
    steps_at_once: int | None = None,
) -> tuple[Array, Array, Array]:
    """Derivatives of each step around a trajectory, by forward-mode AD through MJX.

    The step's cost is c_t(x, u) = -weights_t r_t - value_weights_t V(next state). Its
    curvature is the central difference of AD gradients at z +- eps_i e_i (eps_i =
    1e-3 max(1, |z_i|)): exact for a quadratic cost, and one first-order program, where
    forward-over-forward AD through an MJX step compiles twice as long.

    Args:
      states: `State` [H], each step's start; controls: [H, nu]; keys: [H].
      weights, value_weights: [H] (0 or 1: which rewards count, where the value is paid).
      steps_at_once: steps vmapped together, groups in turn (`Config.linearize_steps`);
        None: all H.

    Returns:
      (f_z [H, nx, n] = d x_{t+1} / d(x, u), c_z [H, n], c_zz [H, n, n]), n = nx + nu.
    """
    nx = _vector(jax.tree.map(lambda leaf: leaf[0], states)).shape[0]

    def step(state: State, u: Array, key: Array, weight: Array, value_weight: Array):
        def next_and_cost(z: Array) -> Array:  # [nx + 1]
            nxt = transition(task, _with_vector(state, z[:nx]), z[nx:], key)
            cost = -weight * nxt.reward
            if terminal_value is not None:
                cost = cost - value_weight * terminal_value(task.model, nxt)
            return jnp.concatenate([_vector(nxt), cost[None]])

        z = jnp.concatenate([_vector(state), u])
        n = z.shape[0]
        eps = 1e-3 * jnp.maximum(1.0, jnp.abs(z))
        points = jnp.concatenate([z[None], z + jnp.diag(eps), z - jnp.diag(eps)])  # [2n + 1, n]
        jacobians = jax.vmap(jax.jacfwd(next_and_cost))(points)  # [2n + 1, nx + 1, n]
        gradients = jacobians[:, nx]
        curvature = (gradients[1 : n + 1] - gradients[n + 1 :]) / (2 * eps[:, None])
        return jacobians[0, :nx], gradients[0], (curvature + curvature.T) / 2

    inputs = (states, controls, keys, weights, value_weights)
    if steps_at_once is None or steps_at_once >= controls.shape[0]:
        return jax.vmap(step)(*inputs)
    return jax.lax.map(lambda x: step(*x), inputs, batch_size=steps_at_once if steps_at_once > 1 else None)


def backward(
    f_z: Array, c_z: Array, c_zz: Array, controls: Array, low: Array, high: Array, regularization: Array
) -> tuple[Array, Array]:
    """The backward pass (the module docstring's recursion) with mu = `regularization`.

    Args:
      f_z: [H, nx, nx + nu], c_z: [H, nx + nu], c_zz: [H, n, n] (`linearize`).
      controls: [H, nu] the nominal controls, for the clamped set.

    Returns:
      (k [H, nu], K [H, nu, nx]); NaN only where mu = 0 meets a singular Q_uu.
    """
    nx = f_z.shape[1]

    def body(carry, inputs):
        v_x, v_xx = carry
        fz, cz, czz, u = inputs
        f_x, f_u = fz[:, :nx], fz[:, nx:]
        q_x, q_u = cz[:nx] + f_x.T @ v_x, cz[nx:] + f_u.T @ v_x
        q_xx = czz[:nx, :nx] + f_x.T @ v_xx @ f_x
        q_uu = czz[nx:, nx:] + f_u.T @ v_xx @ f_u
        q_ux = czz[nx:, :nx] + f_u.T @ v_xx @ f_x
        # Q_uu's negative curvature (a reward concave in the controls, far from a
        # minimum) floored at 0 before mu is added: a Newton step needs it positive definite.
        values, vectors = jnp.linalg.eigh((q_uu + q_uu.T) / 2)
        q_uu_reg = (vectors * (jnp.maximum(values, 0.0) + regularization)) @ vectors.T
        # Clamped: at a limit, and the unconstrained step pushes past it.
        step = -jnp.linalg.solve(q_uu_reg, q_u)
        clamped = ((u <= low) & (step < 0)) | ((u >= high) & (step > 0))
        free = (~clamped).astype(f_z.dtype)
        reduced = q_uu_reg * free[:, None] * free[None, :] + jnp.diag(1 - free)
        factor = jnp.linalg.cholesky(reduced)
        solve = lambda b: jax.scipy.linalg.cho_solve((factor, True), b)  # noqa: E731
        k = -solve(free * q_u)
        gain = -solve(free[:, None] * q_ux)
        v_x = q_x + gain.T @ q_uu @ k + gain.T @ q_u + q_ux.T @ k
        v_xx = q_xx + gain.T @ q_uu @ gain + gain.T @ q_ux + q_ux.T @ gain
        return (v_x, (v_xx + v_xx.T) / 2), (k, gain)

    zeros = (jnp.zeros((nx,), f_z.dtype), jnp.zeros((nx, nx), f_z.dtype))
    _, (k, gains) = jax.lax.scan(body, zeros, (f_z, c_z, c_zz, controls), reverse=True)
    return k, gains


# --- one replan ------------------------------------------------------------------------


def plan(
    config: Config,
    task: Task,
    state: ILQRState,
    env_state: State,
    key: Array,
    terminal_value: TerminalValue | None = None,
) -> tuple[ILQRState, Array]:
    """One replan from `env_state`: up to `config.iterations` iLQR iterations from the
    last plan shifted to now. Returns (the new state, the plan's [H, nu] controls).
    `terminal_value` (model, state) -> [] values each rollout's final state; its
    gradient and curvature steer the plan's end (`planning.as_terminal_value`)."""
    task = _check_task(task)
    terminal_value = as_terminal_value(terminal_value)
    hp = state.hyperparams
    low, high = (jnp.asarray(b) for b in planning.control_limits(task))
    horizon, nu = config.horizon_steps, low.shape[0]
    state = planning.shift(config, state, env_state.data.time)
    start = fill_transition_entries(task, env_state)
    keys = jax.random.split(key, horizon)
    nx = _vector(start).shape[0]
    alphas = hp.step_decay ** jnp.arange(config.line_search_steps, dtype=jnp.float32)
    steps_at_once = config.linearize_steps
    if steps_at_once is None:
        steps_at_once = 1 if jax.default_backend() == "cpu" else horizon

    def run(controls, gains, reference):
        return rollout(
            task, start, controls, gains, reference, keys, low, high, terminal_value, hp.termination_cost, config.unroll
        )

    def derivatives(controls: Array, states: State, final: State) -> tuple[Array, Array, Array]:
        # Which steps count, from the nominal: rewards up to its first termination, the
        # value if it never terminated (`planning.masked_cost`).
        terminated = jnp.concatenate([states.terminated[1:], final.terminated[None]])
        ended = jnp.cumsum(terminated.astype(jnp.int32))
        weights = (ended - terminated.astype(jnp.int32) == 0).astype(jnp.float32)
        value_weights = jnp.zeros(horizon).at[-1].set((ended[-1] == 0).astype(jnp.float32))
        return linearize(task, states, controls, keys, weights, value_weights, terminal_value, steps_at_once)

    # One rollout program serves the first nominal (pass 0: with k = K = 0 every
    # candidate is the warm start) and each iteration's line search (passes 1..N).
    def one_pass(carry):
        i, controls, k, gains, reference, derivs, cost, mu, _, costs, dt = carry
        applied, states, finals, new_costs = jax.vmap(lambda a: run(controls + a * k, gains, reference))(alphas)
        best = jnp.argmin(new_costs)
        better = new_costs[best] < cost
        applied, states, final = jax.tree.map(lambda x: x[best], (applied, states, finals))
        decrease = jnp.where(better, cost - new_costs[best], 0.0)
        converged = (i > 0) & better & (decrease <= hp.tolerance * jnp.maximum(jnp.abs(cost), 1.0))
        shrink = jnp.maximum(mu / hp.regularization_factor, hp.regularization_min)
        grow = jnp.maximum(mu * hp.regularization_factor, jnp.maximum(hp.regularization_min, 1e-6))
        mu = jnp.where(i == 0, mu, jnp.where(better, shrink, grow))
        # A failed line search keeps the nominal and its derivatives: only mu changes.
        derivs = jax.lax.cond(
            (better | (i == 0)) & (i < config.iterations),
            lambda: derivatives(applied, states, final),
            lambda: derivs,
        )
        controls = jnp.where(better, applied, controls)
        reference = jnp.where(better, jax.vmap(_vector)(states), reference)
        dt = jnp.where(better, (final.data.time - start.data.time) / horizon, dt)
        cost = jnp.minimum(new_costs[best], cost)
        costs = jnp.where(jnp.arange(costs.shape[0]) >= i, cost, costs)
        k, gains = backward(*derivs, controls, low, high, mu)
        return i + 1, controls, k, gains, reference, derivs, cost, mu, converged, costs, dt

    def going(carry) -> Array:
        i, *_, mu, converged, _, _ = carry
        return (i <= config.iterations) & ~converged & (mu <= hp.regularization_max)

    n = nx + nu
    derivs = (jnp.zeros((horizon, nx, n)), jnp.zeros((horizon, n)), jnp.zeros((horizon, n, n)))
    mu = jnp.clip(state.regularization, hp.regularization_min, hp.regularization_max)
    first = (
        jnp.int32(0),
        jnp.clip(state.knots, low, high),
        jnp.zeros((horizon, nu)),
        jnp.zeros((horizon, nu, nx)),
        jnp.zeros((horizon, nx)),
        derivs,
        jnp.float32(jnp.inf),
        mu,
        jnp.bool_(False),
        jnp.full((config.iterations + 1,), jnp.inf, jnp.float32),
        jnp.float32(0.0),
    )
    i, controls, _, _, _, _, cost, mu, _, costs, dt = jax.lax.while_loop(going, one_pass, first)
    state = state.replace(
        knots=controls,
        dt=dt.astype(jnp.float32),
        cost=cost,
        regularization=mu,
        iterations=(i - 1).astype(jnp.float32),
        costs=costs,
    )
    return state, controls
