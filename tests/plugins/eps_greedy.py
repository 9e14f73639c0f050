# eps_greedy.py
"""epsilon-greedy as a plain-Python corraoi plug-in (the example of docs/extending.md)."""

import numpy as np

from corraoi.policies import Param, Policy


class EpsilonGreedy(Policy):
    """With probability epsilon a uniformly random arm, otherwise the best empirical mean."""

    name = "eps-greedy"
    params = {"epsilon": Param(0.1, "exploration probability", low=0.0, high=1.0)}
    color = (0, 0, 0)

    def select(self, t, state):
        # every array has one row per run: this decides all runs at once
        explore = state.rng.random() < self.epsilon
        random_arm = state.rng.integers(state.arms)
        greedy = state.rng.argmax(state.mu_hat)  # ties uniformly at random
        return np.where(explore | (t <= state.arms), random_arm, greedy)
