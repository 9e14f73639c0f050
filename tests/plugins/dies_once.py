"""A plug-in whose first attempt kills the process running it (a dying Dask worker).

The marker file named by $CORRAOI_TEST_MARKER records that the worker died once; the retry
then runs normally. With $CORRAOI_TEST_ALWAYS_DIE set it dies every time.
"""

import os

import numpy as np

from corraoi.policies import Policy


class DiesOnce(Policy):
    name = "dies-once"

    def select(self, t, state):
        marker = os.environ.get("CORRAOI_TEST_MARKER", "")
        if t == 50 and state.seeds[0] >= 4 and marker:
            if os.environ.get("CORRAOI_TEST_ALWAYS_DIE") or not os.path.exists(marker):
                open(marker, "w").close()
                os._exit(1)
        return state.rng.argmax(state.mu_hat + 1.0 / np.sqrt(state.pulls + 1))
