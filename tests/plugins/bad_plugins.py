"""Plug-ins that misbehave, one way each (tests/test_plugins.py)."""

import numpy as np

from corraoi.policies import Param, Policy


class OutOfRange(Policy):
    name = "out-of-range"

    def select(self, t, state):
        arms = np.zeros(state.runs, dtype=np.int64)
        if t >= 5:
            arms[:] = state.arms  # one past the last arm
        return arms


class NaNArm(Policy):
    name = "nan-arm"

    def select(self, t, state):
        return np.full(state.runs, np.nan if t >= 3 else 0.0)


class WrongShape(Policy):
    name = "wrong-shape"

    def select(self, t, state):
        return np.zeros((state.runs, 2), dtype=np.int64)


class Raises(Policy):
    name = "raises"
    params = {"at": Param(7.0, "slot at which to fail", low=1.0, integer=True)}

    def select(self, t, state):
        if t >= self.at:
            raise ZeroDivisionError("boom")
        return np.zeros(state.runs, dtype=np.int64)


class NotAPolicy:
    pass
