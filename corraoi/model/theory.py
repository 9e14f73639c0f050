"""Closed-form facts about an instance: means, pseudo-rewards, competitive arms, regret bounds.

All indices are 0-based here; ``InstanceTheory.to_dict`` numbers arms from 1.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from .instance import Instance, weighted_sums

#: Two means closer than this are a tie (for the best arm and for competitiveness).
TIE_TOL = 1e-12


def pseudo_reward_table(inst: Instance, *, support_only: bool = True) -> np.ndarray:
    """``s[l, k, r] = max{Y[l, x] : Y[k, x] = r}`` as float, NaN where no state gives ``r``.

    With ``support_only`` (the theory's definition) only states with ``p_x > 0`` count.
    Policies know ``Y`` but not ``p``, so they use ``support_only=False``
    (see :func:`policy_pseudo_rewards`).
    """
    Y = inst.Y.astype(bool)
    mask = inst.p > 0 if support_only else np.ones(inst.n_states, dtype=bool)
    K = inst.K
    s = np.full((K, K, 2), np.nan)
    for r in (0, 1):
        # states where arm k gives reward r: (K, n)
        given = (Y == bool(r)) & mask[None, :]
        has = given.any(axis=1)  # (K,)
        # s[l, k, r] = any(Y[l, x] for x with given[k, x])
        val = (Y[:, None, :] & given[None, :, :]).any(axis=2).astype(np.float64)
        val[:, ~has] = np.nan
        s[:, :, r] = val
    return s


def policy_pseudo_rewards(inst: Instance) -> np.ndarray:
    """The pseudo-reward table a policy may use: from ``Y`` alone, over every state.

    A reward ``r`` that arm ``k`` can never give gets the conservative pseudo-reward 1
    (it never occurs, so it never enters an estimate).
    """
    s = pseudo_reward_table(inst, support_only=False)
    return np.where(np.isnan(s), 1.0, s)


@dataclass(frozen=True)
class InstanceTheory:
    """Theory values of an instance with respect to its best arm."""

    mu: np.ndarray
    best_arm: int
    best_tied: tuple[int, ...]
    gaps: np.ndarray
    phi: np.ndarray  # phi_{l, k*} for every arm l (phi_{k*, k*} = mu*)
    pseudo_gap: np.ndarray
    competitive: tuple[int, ...]  # sub-optimal competitive arms (k* excluded)
    strictly_competitive: tuple[int, ...]
    pseudo_rewards: np.ndarray  # s[l, k, r]

    @property
    def C(self) -> int:  # noqa: N802 - the paper's notation
        return len(self.competitive)

    @property
    def mu_star(self) -> float:
        return float(self.mu[self.best_arm])

    def to_dict(self) -> dict[str, Any]:
        """The JSON of ``corraoi instance show --json``: arms numbered from 1."""
        K = self.mu.size
        table = {
            f"{l + 1},{k + 1}": [
                _num(self.pseudo_rewards[l, k, 0]),
                _num(self.pseudo_rewards[l, k, 1]),
            ]
            for l in range(K)
            for k in range(K)
        }
        return {
            "mu": [round(float(v), 12) for v in self.mu],
            "best_arm": self.best_arm + 1,
            "best_arm_tied_with": [a + 1 for a in self.best_tied if a != self.best_arm],
            "gaps": [round(float(v), 12) for v in self.gaps],
            "phi": [round(float(v), 12) for v in self.phi],
            "pseudo_gap": [round(float(v), 12) for v in self.pseudo_gap],
            "competitive": [a + 1 for a in self.competitive],
            "strictly_competitive": [a + 1 for a in self.strictly_competitive],
            "C": self.C,
            "pseudo_rewards": table,
        }


def _num(v: float) -> float | None:
    return None if math.isnan(v) else float(v)


def analyse(inst: Instance) -> InstanceTheory:
    """The theory of ``inst``, computed once per instance object and kept on it.

    A recorded run asks for it from the engine, both sinks and the summary; the instance's
    arrays are read-only, and so are the theory's, so the kept value cannot go stale.
    """
    kept = inst.__dict__.get("_theory")
    if kept is None:
        kept = compute_theory(inst)
        for value in vars(kept).values():
            if isinstance(value, np.ndarray):
                value.setflags(write=False)
        object.__setattr__(inst, "_theory", kept)  # Instance is frozen: a cache, not state
    return kept


def compute_theory(inst: Instance) -> InstanceTheory:
    """The theory of ``inst`` computed afresh, every time (:func:`analyse` keeps it)."""
    mu = inst.mu
    top = float(mu.max())
    tied = tuple(int(k) for k in np.flatnonzero(mu >= top - TIE_TOL))
    best = tied[0]  # ties: lowest index
    s = pseudo_reward_table(inst, support_only=True)
    ybest = inst.Y[best].astype(int)
    # phi_{l,k*} = sum_x p_x s_{l,k*}(Y_{k*}(x)); states with p_x = 0 contribute nothing
    vals = s[:, best, :][:, ybest]  # (K, n): s_{l,k*}(Y_{k*}(x))
    vals = np.where(inst.p[None, :] > 0, vals, 0.0)  # 0 or 1: s is a maximum of rewards
    phi = weighted_sums(vals, inst.p)
    mu_star = float(mu[best])
    pseudo_gap = mu_star - phi
    pseudo_gap[best] = 0.0
    others = [k for k in range(inst.K) if k != best]
    competitive = tuple(k for k in others if pseudo_gap[k] <= TIE_TOL)
    strictly = tuple(k for k in others if pseudo_gap[k] < -TIE_TOL)
    return InstanceTheory(
        mu=mu,
        best_arm=best,
        best_tied=tied,
        gaps=mu_star - mu,
        phi=phi,
        pseudo_gap=pseudo_gap,
        competitive=competitive,
        strictly_competitive=strictly,
        pseudo_rewards=s,
    )
