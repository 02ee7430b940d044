"""The pieces sampling-based planners are composed from, and the closed loop they run in.

    splines       plans as K control knots, evaluated at any time (zero, linear, cubic)
    sampling      SamplingConfig (structure), SamplingHyperparams (numbers, swept by
                  vmap), configure (both from one dict of fields), PlannerState,
                  sampling around a nominal plan, warm start, the MPPI weights and
                  the CEM update
    ensembles     batched rollouts of a task's own `transition` and their costs (no
                  reward after a termination, an optional termination cost), model
                  ensembles and risk measures
    native        the same rollouts in C MuJoCo (`mujoco.rollout`), costed by the task's
                  own reward in JAX: the fast backend on a CPU
    learned       learned pieces planners call at run time (a terminal value), as
                  pytrees whose weights are leaves, and committed host-loop arguments
    closed_loop   simulate one task while planning with another, as one jit; Judo's hooks
    prior         a trained policy as any planner's prior: its plan to search around, its
                  critic as the terminal value
    realtime      the same closed loop against the wall clock, or timed offline (loads on
                  first use: the env registry needs the closed loop's hooks, not the clock)

`mjzoo.algorithms.mppi`, `cem` and `predictive_sampling` are a few lines each on top
of `sample_around`; a new planner reuses every piece here. The functions of `sampling`,
`ensembles` and `learned.as_terminal_value` are re-exported: ``mjzoo.planning.mppi_weights``.
"""

from mjzoo import lazy
from mjzoo.planning import closed_loop
from mjzoo.planning import ensembles
from mjzoo.planning import learned
from mjzoo.planning import native
from mjzoo.planning import prior
from mjzoo.planning import sampling
from mjzoo.planning import splines
from mjzoo.planning.ensembles import RISKS
from mjzoo.planning.ensembles import Ensemble
from mjzoo.planning.ensembles import aggregate
from mjzoo.planning.ensembles import base_task
from mjzoo.planning.ensembles import ensemble
from mjzoo.planning.ensembles import masked_cost
from mjzoo.planning.ensembles import rollout_costs
from mjzoo.planning.learned import TerminalValue
from mjzoo.planning.learned import as_terminal_value
from mjzoo.planning.native import Native
from mjzoo.planning.sampling import PlannerState
from mjzoo.planning.sampling import SamplingConfig
from mjzoo.planning.sampling import SamplingHyperparams
from mjzoo.planning.sampling import cem_update
from mjzoo.planning.sampling import configure
from mjzoo.planning.sampling import control_at
from mjzoo.planning.sampling import control_limits
from mjzoo.planning.sampling import controls
from mjzoo.planning.sampling import half_range
from mjzoo.planning.sampling import initial_state
from mjzoo.planning.sampling import iterate
from mjzoo.planning.sampling import mppi_weights
from mjzoo.planning.sampling import noise_ramp_profile
from mjzoo.planning.sampling import noise_std
from mjzoo.planning.sampling import sample_around
from mjzoo.planning.sampling import sample_costs
from mjzoo.planning.sampling import sample_knots
from mjzoo.planning.sampling import shift

__all__ = [
    "splines",
    "sampling",
    "ensembles",
    "learned",
    "closed_loop",
    "prior",
    "native",
    "Native",
    "realtime",
    "SamplingConfig",
    "SamplingHyperparams",
    "configure",
    "PlannerState",
    "Ensemble",
    "TerminalValue",
    "as_terminal_value",
    "RISKS",
    "ensemble",
    "base_task",
    "control_limits",
    "half_range",
    "noise_std",
    "noise_ramp_profile",
    "initial_state",
    "iterate",
    "shift",
    "sample_knots",
    "sample_around",
    "controls",
    "control_at",
    "masked_cost",
    "rollout_costs",
    "aggregate",
    "sample_costs",
    "mppi_weights",
    "cem_update",
]

__getattr__, __dir__ = lazy.submodules(__name__, ("realtime",))
