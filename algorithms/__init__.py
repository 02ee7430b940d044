"""Algorithms as modules of pure functions, each consuming a `mjzoo.Task`.

    ppo                   proximal policy optimization (Config, init, update, train,
                          policy, evaluate)
    amp                   adversarial motion priors: PPO with a discriminator's style
                          reward for moving like a reference motion (the same contract)
    sac                   soft actor-critic: off-policy, a replay of parallel env steps,
                          entropy tuned automatically (the same contract)
    fast_td3              FastTD3: TD3 with a categorical critic, n-step returns, many
                          envs and large batches (the same contract)
    mppi                  model-predictive path integral control  (Config, init, plan)
    cem                   the cross-entropy method                  (Config, init, plan)
    predictive_sampling   keep the best of samples around the plan  (Config, init, plan)
    dial                  DIAL-MPC: MPPI iterated with annealed noise (Config, init, plan)
    cma_es                CMA-ES over the plan's knots              (Config, init, plan)
    ilqr                  iLQR on MJX's derivatives (MJX only)     (Config, init, plan)

Each is assembled from `mjzoo.learning` or `mjzoo.planning` pieces; docs/design.md
gives the contract a new algorithm follows. Modules load on first use.
"""

from mjzoo import lazy

MODULES = ("ppo", "amp", "sac", "fast_td3", "mppi", "cem", "predictive_sampling", "dial", "cma_es", "ilqr")

__all__ = list(MODULES)

__getattr__, __dir__ = lazy.submodules(__name__, MODULES)
