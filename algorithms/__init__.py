"""Algorithms as modules of pure functions: each consumes a `mjzoo.Task`.

Reinforcement learning (ppo, amp) and sampling-based planners (mppi, cem,
predictive_sampling) land here; see DESIGN.md for the contract they follow.
"""

__all__: list[str] = []
