"""The pure pieces reinforcement-learning algorithms are composed from.

Each is a small function with its array shapes and time indices in its docstring,
tested against hand-computed values under jit and vmap; `mjzoo.algorithms.ppo` is
assembled from them, and so can a user's own algorithm be (docs/own-algorithm.md
writes an A2C from them).

    collection      auto-resetting batched experience, time-major (`collect`, `Collector`)
    evaluation      deterministic first-episode returns from a policy (`evaluate`)
    actions         [-1, 1] actions onto a task's controls (`to_controls`)
    advantages      generalized advantage estimation (`gae`)
    losses          vanilla, clipped and KL-penalized policy gradients, value loss
    learner         epochs x shuffled minibatches of updates (`learn`)
    normalization   running observation statistics
    networks        MLP and GRU policies/critics as (init, apply) pairs
    distributions   the tanh-squashed Gaussian policy head
"""

from mjzoo.learning import (
    actions,
    advantages,
    collection,
    distributions,
    evaluation,
    learner,
    losses,
    networks,
    normalization,
)
from mjzoo.learning.actions import to_controls
from mjzoo.learning.advantages import gae
from mjzoo.learning.collection import (
    Collector,
    Policy,
    Transitions,
    collect,
    feed_forward,
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
from mjzoo.learning.networks import Network, RecurrentNetwork, gru_mlp, mlp
from mjzoo.learning.normalization import (
    RunningStats,
    init_stats,
    normalize,
    update_stats,
)

__all__ = [
    "Collector",
    "Evaluation",
    "Network",
    "Policy",
    "RecurrentNetwork",
    "RunningStats",
    "Transitions",
    "actions",
    "advantages",
    "clipped_surrogate_loss",
    "collect",
    "collection",
    "distributions",
    "episode_steps",
    "evaluate",
    "evaluation",
    "feed_forward",
    "gae",
    "gru_mlp",
    "init_stats",
    "kl_penalty_loss",
    "learn",
    "learner",
    "losses",
    "mlp",
    "networks",
    "normalization",
    "normalize",
    "normalize_advantages",
    "policy_gradient_loss",
    "to_controls",
    "update_stats",
    "value_loss",
]
