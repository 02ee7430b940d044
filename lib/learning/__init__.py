"""The pure pieces reinforcement-learning algorithms are composed from.

Each is a small function with its array shapes and time indices in its docstring,
tested against hand-computed values under jit and vmap; `mjzoo.algorithms.ppo` is
assembled from them, and so can a user's own algorithm be.

    advantages      generalized advantage estimation (`gae`)
    losses          clipped surrogate, value loss, advantage normalization
    normalization   running observation statistics
    networks        MLP and GRU policies/critics as (init, apply) pairs
    distributions   the tanh-squashed Gaussian policy head
"""

from mjzoo.learning import advantages, distributions, losses, networks, normalization
from mjzoo.learning.advantages import gae
from mjzoo.learning.losses import clipped_surrogate_loss, normalize_advantages, value_loss
from mjzoo.learning.networks import Network, RecurrentNetwork, gru_mlp, mlp
from mjzoo.learning.normalization import RunningStats, init_stats, normalize, update_stats

__all__ = [
    "advantages",
    "distributions",
    "losses",
    "networks",
    "normalization",
    "gae",
    "clipped_surrogate_loss",
    "value_loss",
    "normalize_advantages",
    "Network",
    "RecurrentNetwork",
    "mlp",
    "gru_mlp",
    "RunningStats",
    "init_stats",
    "update_stats",
    "normalize",
]
