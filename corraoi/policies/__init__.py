"""Scheduling policies: the policy API, the built-ins and the registry.

Write your own (``docs/extending.md``)::

    from corraoi.policies import Param, Policy

    class EpsilonGreedy(Policy):
        name = "eps-greedy"
        params = {"epsilon": Param(0.1, "exploration probability", low=0, high=1)}

        def select(self, t, state):
            ...

and run it with ``corraoi record --policy eps_greedy.py:EpsilonGreedy``.

Importing this package is light; the built-ins (numba) load on first use of the registry.
"""

from __future__ import annotations

from .api import RGB, CompiledPolicy, GpuForm, Param, Policy, PolicyBase, PolicySpec, gpu_form
from .registry import (
    ENTRY_POINT_GROUP,
    available,
    builtins,
    make_policies,
    make_policy,
    paper_names,
    parse_param_assignments,
    parse_policy_names,
    resolve,
    unknown_policy_message,
)
from .variants import AOI_PREFIX

__all__ = [
    "AOI_PREFIX",
    "ENTRY_POINT_GROUP",
    "RGB",
    "CompiledPolicy",
    "GpuForm",
    "Param",
    "Policy",
    "PolicyBase",
    "PolicySpec",
    "available",
    "builtins",
    "gpu_form",
    "make_policies",
    "make_policy",
    "paper_names",
    "parse_param_assignments",
    "parse_policy_names",
    "resolve",
    "unknown_policy_message",
]
