"""Policies for channels that drift: sliding-window UCB and discounted Thompson sampling.

* ``sw-ucb``: Garivier and Moulines (2011), "On upper-confidence bound policies for switching
  bandit problems" (ALT): the index of arm k is its mean over the last ``window`` slots plus
  sqrt(c ln(min(t, window)) / N_k), N_k its pulls within the window; an arm not pulled within
  the window has an infinite index (ties uniformly at random).
* ``d-ts``: Raj and Kalyani (2017), "Taming non-stationary bandits: a Bayesian approach"
  (arXiv:1707.09727): every slot all arms' success and failure counts are multiplied by
  ``gamma`` and the played arm's gain its reward; arm k samples Beta(S_k + 1, F_k + 1).

Their correlated forms are left out on purpose: the candidate set rests on pseudo-rewards
estimated from the whole history, which a drifting channel invalidates. The AoI-aware form
uses the whole-history mu_hat, as for every policy.
"""

from __future__ import annotations

from collections.abc import Mapping

from .api import CompiledPolicy, GpuForm, Param
from .paper import C_PARAM
from .registry import register
from .variants import family


class SWUCB(CompiledPolicy):
    """Sliding-window UCB: mean and count over the last `window` slots."""

    name = "sw-ucb"
    params = {
        "window": Param(500.0, "slots in the sliding window", low=1.0, high=1e7, integer=True),
        "c": C_PARAM,
    }
    color = (227, 119, 194)  # pink
    reference = "Garivier and Moulines (2011), ALT"
    score = "corraoi.policies.builtin_hooks:sw_ucb_score"
    update = "corraoi.policies.builtin_hooks:sw_ucb_update"
    gpu = GpuForm("sw_ucb", uses_state=True)

    @classmethod
    def state_size(cls, K: int, params: Mapping[str, float]) -> int:
        return 2 * K + 2 * int(params["window"])


class DTS(CompiledPolicy):
    """Discounted Thompson sampling: counts decay by `gamma` every slot."""

    name = "d-ts"
    params = {"gamma": Param(0.95, "discount factor of the counts", low=0.0, high=1.0,
                             open_low=True)}  # fmt: skip
    color = (255, 152, 150)  # salmon
    reference = "Raj and Kalyani (2017), arXiv:1707.09727"
    score = "corraoi.policies.builtin_hooks:d_ts_score"
    update = "corraoi.policies.builtin_hooks:d_ts_update"
    gpu = GpuForm("d_ts", uses_state=True)

    @classmethod
    def state_size(cls, K: int, params: Mapping[str, float]) -> int:
        return 2 * K


POLICIES = {
    cls.name: cls
    for fam in (family(SWUCB, correlated_name=None), family(DTS, correlated_name=None))
    for cls in fam
}

for _cls in POLICIES.values():
    register(_cls)
