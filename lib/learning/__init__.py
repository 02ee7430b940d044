"""The pure pieces reinforcement-learning algorithms are composed from.

Each is a small function with its array shapes and time indices in its docstring,
tested against hand-computed values under jit and vmap; `mjzoo.algorithms.ppo` is
assembled from them, and so can a user's own algorithm be (docs/own-algorithm.md
writes an A2C from them).

    algorithm       an RL algorithm as a value the harness drives (`Algorithm`)
    collection      auto-resetting batched experience, time-major (`collect`, `Collector`)
    hyperparams     checking and splitting an algorithm's numbers (`check_ranges`, `split_fields`)
    evaluation      deterministic first-episode returns from a policy (`evaluate`)
    actions         [-1, 1] actions onto a task's controls (`to_controls`)
    advantages      generalized advantage estimation (`gae`)
    losses          vanilla, clipped and KL-penalized policy gradients, value loss
    learner         epochs x shuffled minibatches of updates (`learn`)
    normalization   running observation statistics
    networks        MLP and GRU policies/critics as (init, apply) pairs
    distributions   the tanh-squashed Gaussian policy head
    discriminators  AMP's least-squares and logistic losses, style rewards, gradient penalty
    replay          a jit-able FIFO replay buffer of samples (`Replay`)
    motion_features AMP's features of a frame, one function for simulation and reference
"""

from mjzoo.learning import (
    actions,
    advantages,
    algorithm,
    collection,
    discriminators,
    distributions,
    evaluation,
    hyperparams,
    learner,
    losses,
    motion_features,
    networks,
    normalization,
    replay,
)
from mjzoo.learning.actions import to_controls
from mjzoo.learning.advantages import gae
from mjzoo.learning.algorithm import Algorithm, TrainingWarning
from mjzoo.learning.collection import (
    Actor,
    Collector,
    Transitions,
    collect,
    feed_forward,
)
from mjzoo.learning.discriminators import (
    discriminator_loss,
    gradient_penalty,
    least_squares_loss,
    least_squares_reward,
    logistic_loss,
    logistic_reward,
    style_reward,
)
from mjzoo.learning.evaluation import Evaluation, episode_steps, evaluate
from mjzoo.learning.learner import learn
from mjzoo.learning.losses import (
    clipped_surrogate_loss,
    kl_penalty_loss,
    normalize_advantages,
    policy_gradient_loss,
    value_loss,
)
from mjzoo.learning.motion_features import feature_layout, feature_size, frames_features, with_feature_window
from mjzoo.learning.networks import Network, RecurrentNetwork, gru_mlp, mlp
from mjzoo.learning.normalization import (
    RunningStats,
    init_stats,
    normalize,
    update_stats,
)
from mjzoo.learning.replay import Replay

__all__ = [
    "Actor",
    "Algorithm",
    "Collector",
    "Evaluation",
    "Network",
    "RecurrentNetwork",
    "Replay",
    "RunningStats",
    "TrainingWarning",
    "Transitions",
    "actions",
    "advantages",
    "algorithm",
    "clipped_surrogate_loss",
    "collect",
    "collection",
    "discriminator_loss",
    "discriminators",
    "distributions",
    "episode_steps",
    "evaluate",
    "evaluation",
    "feature_layout",
    "feature_size",
    "feed_forward",
    "frames_features",
    "gae",
    "gradient_penalty",
    "gru_mlp",
    "hyperparams",
    "init_stats",
    "kl_penalty_loss",
    "learn",
    "learner",
    "least_squares_loss",
    "least_squares_reward",
    "logistic_loss",
    "logistic_reward",
    "losses",
    "mlp",
    "motion_features",
    "networks",
    "normalization",
    "normalize",
    "normalize_advantages",
    "policy_gradient_loss",
    "replay",
    "style_reward",
    "to_controls",
    "update_stats",
    "value_loss",
    "with_feature_window",
]
