"""Algorithms as modules of pure functions, each consuming a `mjzoo.Task`.

    ppo                   proximal policy optimization (Config, init, update, train,
                          policy, evaluate)
    amp                   adversarial motion priors: PPO with a discriminator's style
                          reward for moving like a reference motion (the same contract)
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

MODULES = ("ppo", "amp", "mppi", "cem", "predictive_sampling", "dial", "cma_es", "ilqr")

__all__ = list(MODULES)

__getattr__, __dir__ = lazy.submodules(__name__, MODULES)
