"""Forced-exploration baselines Q-UCB and Q-TS, as AoI papers compare against them.

Krishnasamy, Sen, Johari, Shakkottai (2021), "Learning unknown service rates in queues: a
multiarmed bandit approach", Operations Research 69(1): at slot t, with probability
min(1, 3 K ln^2 t / t) play an arm chosen uniformly at random; otherwise Q-UCB plays
argmax mu_hat_k + sqrt(ln^2 t / (2 n_k)) (after one pull of each arm) and Q-TS samples
Beta(S_k + 1, F_k + 1) as TS does.

Random draws, in order: one uniform for the exploration coin every slot (t >= 2; at t = 1 the
probability is 0 and no draw is made), one more for the explored arm.
"""

from __future__ import annotations

from collections.abc import Mapping

from .api import CompiledPolicy, GpuForm
from .registry import register
from .variants import family

REFERENCE = "Krishnasamy, Sen, Johari, Shakkottai (2021), Operations Research 69(1)"


class QUCB(CompiledPolicy):
    """Q-UCB: explore w.p. min(1, 3K ln^2 t / t), else argmax mu_hat + ln t / sqrt(2 n_k)."""

    name = "q-ucb"
    color = (23, 190, 207)  # cyan
    reference = REFERENCE
    forced = "corraoi.policies.builtin_hooks:q_ucb_forced"
    score = "corraoi.policies.builtin_hooks:q_ucb_score"
    gpu = GpuForm("q_ucb")


class QTS(CompiledPolicy):
    """Q-TS: explore w.p. min(1, 3K ln^2 t / t), else Beta(S+1, F+1) sampling."""

    name = "q-ts"
    color = (188, 189, 34)  # olive
    reference = REFERENCE
    forced = "corraoi.policies.builtin_hooks:q_ts_forced"
    score = "corraoi.policies.builtin_hooks:ts_beta_score"
    update = "corraoi.policies.builtin_hooks:ts_beta_update"
    gpu = GpuForm("q_ts")

    @classmethod
    def state_size(cls, K: int, params: Mapping[str, float]) -> int:
        return 4 * K  # each arm's cached sampler constants


POLICIES = {
    cls.name: cls
    for fam in (
        family(QUCB, correlated_name="cq-ucb", correlated_color=(0, 170, 170)),
        family(QTS, correlated_name="cq-ts", correlated_color=(160, 160, 0)),
    )
    for cls in fam
}

for _cls in POLICIES.values():
    register(_cls)
