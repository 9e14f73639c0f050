"""The paper's twelve policies: UCB, Thompson sampling (Beta and Gaussian priors), their
correlated forms CUCB and CTS, and the AoI-aware form of each.

UCB: Auer, Cesa-Bianchi, Fischer (2002), "Finite-time analysis of the multiarmed bandit
problem". TS: Agrawal and Goyal (2012). CUCB/CTS: Gupta, Joshi, Yagan (2019), "A unified
approach to translate classical bandit algorithms to the structured bandit setting" (the
candidate set A_t + {k_emp}). AoI-aware rule: Fatale, Bhandari, Narula, Prakash, Prasad
(2020), "Age of information bandits" as used by the correlated AoI paper (appendix).
"""

from __future__ import annotations

from collections.abc import Mapping

from .api import CompiledPolicy, GpuForm, Param
from .registry import register
from .variants import family

C_PARAM = Param(2.0, "UCB exploration constant: index mu_hat + sqrt(c ln t / n)", low=0.0,
                open_low=True)  # fmt: skip
BETA_PARAM = Param(1.0, "Gaussian TS variance scale: N(mu_hat, beta / (n + 1))", low=0.0,
                   open_low=True)  # fmt: skip


class UCB(CompiledPolicy):
    """UCB: play each arm once, then argmax mu_hat + sqrt(c ln t / n_k)."""

    name = "ucb"
    params = {"c": C_PARAM}
    color = (31, 119, 180)  # blue
    reference = "Auer, Cesa-Bianchi, Fischer (2002)"
    forced = "corraoi.policies.hooks:first_unpulled"
    score = "corraoi.policies.builtin_hooks:ucb_score"
    gpu = GpuForm("ucb")
    paper = True


class TS(CompiledPolicy):
    """Thompson sampling with Beta(S_k + 1, F_k + 1) posteriors."""

    name = "ts"
    color = (255, 127, 14)  # orange
    reference = "Agrawal and Goyal (2012)"
    score = "corraoi.policies.builtin_hooks:ts_beta_score"
    update = "corraoi.policies.builtin_hooks:ts_beta_update"
    gpu = GpuForm("ts_beta")  # no cached constants on the GPU: no state
    paper = True

    @classmethod
    def state_size(cls, K: int, params: Mapping[str, float]) -> int:
        return 4 * K  # each arm's cached sampler constants


class TSGauss(CompiledPolicy):
    """Thompson sampling with Gaussian samples N(mu_hat_k, beta / (n_k + 1))."""

    name = "ts-gauss"
    params = {"beta": BETA_PARAM}
    color = (140, 86, 75)  # brown
    reference = "Agrawal and Goyal (2013), Gaussian priors"
    score = "corraoi.policies.builtin_hooks:ts_gauss_score"
    gpu = GpuForm("ts_gauss")
    paper = True


CORRELATED_REF = "Gupta, Joshi, Yagan (2019): candidate set A_t + {k_emp}"

_FAMILIES = [
    family(UCB, correlated_name="cucb", correlated_color=(44, 160, 44),
           correlated_theorem="cucb", correlated_reference=CORRELATED_REF),
    family(TS, correlated_name="cts", correlated_color=(214, 39, 40),
           correlated_theorem="cts", correlated_reference=CORRELATED_REF),
    family(TSGauss, correlated_name="cts-gauss", correlated_color=(148, 103, 189),
           correlated_theorem="cts", correlated_reference=CORRELATED_REF),
]  # fmt: skip

#: The paper's twelve, in the order its tables list them: the plain policies, their
#: correlated forms, then the AoI-aware form of each.
POLICIES = {cls.name: cls for i in range(4) for fam in _FAMILIES for cls in [fam[i]]}

for _cls in POLICIES.values():
    register(_cls)
