# selfish_ucb.py
"""Selfish UCB for several sources, as a plain-Python corraoi plug-in (docs/extending.md)."""

import numpy as np

from corraoi import Choice
from corraoi.policies import Policy


class SelfishUCB(Policy):
    """Each source plays the best UCB index of its own deliveries: a collision is a loss."""

    name = "selfish-ucb"
    multi_source = "own"  # each source is an instance of its own, seeing its own state

    def reset(self, state):
        self.delivered = np.zeros((state.runs, state.arms))  # this source's deliveries

    def select(self, t, state):
        pulls = np.maximum(state.pulls, 1)
        index = self.delivered / pulls + np.sqrt(2 * np.log(max(t, 2)) / pulls)
        index[state.pulls == 0] = np.inf  # every arm once first
        return Choice(state.rng.argmax(index), scores=index)  # ties uniformly at random

    def update(self, t, arms, rewards, state):
        # rewards: the channel was ON; state.collided: another source picked it too
        self.delivered[np.arange(state.runs), arms] += rewards * ~state.collided
