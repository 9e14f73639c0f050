"""An example plug-in package: epsilon-greedy, registered as the entry point eps-greedy."""

import numpy as np

from corraoi.policies import Param, Policy


class EpsilonGreedy(Policy):
    """With probability epsilon a uniformly random arm, otherwise the best empirical mean."""

    name = "eps-greedy"
    params = {"epsilon": Param(0.1, "exploration probability", low=0.0, high=1.0)}

    def select(self, t, state):
        explore = state.rng.random() < self.epsilon
        random_arm = state.rng.integers(state.arms)
        greedy = state.rng.argmax(state.mu_hat)
        return np.where(explore | (t <= state.arms), random_arm, greedy)
