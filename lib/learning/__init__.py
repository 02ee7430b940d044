"""The pure pieces reinforcement-learning algorithms are composed from.

Each is a small function with its array shapes and time indices in its docstring,
tested against hand-computed values under jit and vmap; `mjzoo.algorithms.ppo` is
assembled from them, and so can a user's own algorithm be (docs/own-algorithm.md
writes an A2C from them).

    algorithm           an RL algorithm as a value the harness drives (`Algorithm`, `check_algorithm`)
    collection          auto-resetting batched experience, time-major (`collect`, `Collector`)
    hyperparams         splitting an algorithm's numbers into Config and Hyperparams (`split_fields`)
    evaluation          deterministic first-episode returns from a policy (`evaluate`)
    actions             [-1, 1] actions onto a task's controls (`to_controls`)
    advantages          generalized advantage estimation (`gae`)
    losses              vanilla, clipped and KL-penalized policy gradients, value loss
    learner             epochs x shuffled minibatches of updates (`learn`)
    normalization       running observation statistics
    value_normalization running value-target statistics and PopArt's output rescaling
    reward_scaling      rewards divided by the running spread of the discounted return
    schedules           KL-adaptive learning rate, KL early stop, entropy-coefficient decay
    guards              dropping gradient steps that are not finite (`skip_non_finite_update`)
    networks            MLP and GRU policies/critics as (init, apply) pairs
    distributions       the tanh-squashed Gaussian policy head
    discriminators      AMP's least-squares and logistic losses, style rewards, gradient penalty
    replay              a jit-able FIFO replay buffer of samples or of parallel env steps,
                        n-step returns at sampling (`Replay`, `sample_n_step`)
    targets             off-policy critic targets: twin TD, target-policy smoothing, C51's
                        categorical projection, Polyak averaging
    motion_features     AMP's features of a frame, one function for simulation and reference
"""

from mjzoo.learning import actions
from mjzoo.learning import advantages
from mjzoo.learning import algorithm
from mjzoo.learning import collection
from mjzoo.learning import discriminators
from mjzoo.learning import distributions
from mjzoo.learning import evaluation
from mjzoo.learning import guards
from mjzoo.learning import hyperparams
from mjzoo.learning import learner
from mjzoo.learning import losses
from mjzoo.learning import motion_features
from mjzoo.learning import networks
from mjzoo.learning import normalization
from mjzoo.learning import replay
from mjzoo.learning import reward_scaling
from mjzoo.learning import schedules
from mjzoo.learning import targets
from mjzoo.learning import value_normalization
from mjzoo.learning.actions import to_controls
from mjzoo.learning.advantages import gae
from mjzoo.learning.algorithm import Algorithm
from mjzoo.learning.algorithm import TrainingWarning
from mjzoo.learning.algorithm import check_algorithm
from mjzoo.learning.collection import Actor
from mjzoo.learning.collection import Collector
from mjzoo.learning.collection import Transitions
from mjzoo.learning.collection import collect
from mjzoo.learning.collection import feed_forward
from mjzoo.learning.discriminators import discriminator_loss
from mjzoo.learning.discriminators import gradient_penalty
from mjzoo.learning.discriminators import least_squares_loss
from mjzoo.learning.discriminators import least_squares_reward
from mjzoo.learning.discriminators import logistic_loss
from mjzoo.learning.discriminators import logistic_reward
from mjzoo.learning.discriminators import style_reward
from mjzoo.learning.evaluation import Evaluation
from mjzoo.learning.evaluation import evaluate
from mjzoo.learning.guards import skip_non_finite_update
from mjzoo.learning.learner import learn
from mjzoo.learning.losses import clipped_surrogate_loss
from mjzoo.learning.losses import kl_penalty_loss
from mjzoo.learning.losses import normalize_advantages
from mjzoo.learning.losses import policy_gradient_loss
from mjzoo.learning.losses import temperature_loss
from mjzoo.learning.losses import value_loss
from mjzoo.learning.motion_features import FeatureWindowState
from mjzoo.learning.motion_features import feature_layout
from mjzoo.learning.motion_features import feature_size
from mjzoo.learning.motion_features import frames_features
from mjzoo.learning.motion_features import with_feature_window
from mjzoo.learning.networks import Network
from mjzoo.learning.networks import RecurrentNetwork
from mjzoo.learning.networks import gru_mlp
from mjzoo.learning.networks import mlp
from mjzoo.learning.normalization import RunningStats
from mjzoo.learning.normalization import init_stats
from mjzoo.learning.normalization import normalize
from mjzoo.learning.normalization import update_stats
from mjzoo.learning.replay import NStep
from mjzoo.learning.replay import Replay
from mjzoo.learning.replay import sample_n_step
from mjzoo.learning.reward_scaling import RewardScaling
from mjzoo.learning.reward_scaling import init_reward_scaling
from mjzoo.learning.reward_scaling import scale_rewards
from mjzoo.learning.reward_scaling import update_reward_scaling
from mjzoo.learning.schedules import ENTROPY_SCHEDULES
from mjzoo.learning.schedules import entropy_coef_schedule
from mjzoo.learning.schedules import kl_adaptive_lr
from mjzoo.learning.schedules import kl_early_stop
from mjzoo.learning.schedules import skip_when_stopped
from mjzoo.learning.targets import categorical_projection
from mjzoo.learning.targets import categorical_support
from mjzoo.learning.targets import categorical_value
from mjzoo.learning.targets import polyak
from mjzoo.learning.targets import smoothed_action
from mjzoo.learning.targets import twin_td_target
from mjzoo.learning.value_normalization import denormalize_values
from mjzoo.learning.value_normalization import init_value_stats
from mjzoo.learning.value_normalization import normalize_values
from mjzoo.learning.value_normalization import popart_rescale
from mjzoo.learning.value_normalization import update_value_stats

__all__ = [
    "Actor",
    "Algorithm",
    "Collector",
    "ENTROPY_SCHEDULES",
    "Evaluation",
    "FeatureWindowState",
    "NStep",
    "Network",
    "RecurrentNetwork",
    "Replay",
    "RewardScaling",
    "RunningStats",
    "TrainingWarning",
    "Transitions",
    "actions",
    "advantages",
    "algorithm",
    "categorical_projection",
    "categorical_support",
    "categorical_value",
    "check_algorithm",
    "clipped_surrogate_loss",
    "collect",
    "collection",
    "denormalize_values",
    "discriminator_loss",
    "discriminators",
    "distributions",
    "entropy_coef_schedule",
    "evaluate",
    "evaluation",
    "feature_layout",
    "feature_size",
    "feed_forward",
    "frames_features",
    "gae",
    "gradient_penalty",
    "gru_mlp",
    "guards",
    "hyperparams",
    "init_reward_scaling",
    "init_stats",
    "init_value_stats",
    "kl_adaptive_lr",
    "kl_early_stop",
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
    "normalize_values",
    "policy_gradient_loss",
    "polyak",
    "popart_rescale",
    "replay",
    "reward_scaling",
    "sample_n_step",
    "scale_rewards",
    "schedules",
    "skip_non_finite_update",
    "skip_when_stopped",
    "smoothed_action",
    "style_reward",
    "targets",
    "temperature_loss",
    "to_controls",
    "twin_td_target",
    "update_reward_scaling",
    "update_stats",
    "update_value_stats",
    "value_loss",
    "value_normalization",
    "with_feature_window",
]
