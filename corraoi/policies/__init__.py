"""Scheduling policies: the policy API, the built-ins and the registry.

Write your own (``docs/extending.md``)::

    from corraoi.policies import Param, Policy

    class EpsilonGreedy(Policy):
        name = "eps-greedy"
        params = {"epsilon": Param(0.1, "exploration probability", low=0, high=1)}

        def select(self, t, state):
            ...

and run it with ``corraoi record --policy eps_greedy.py:EpsilonGreedy``, or call
``corraoi.policies.register(EpsilonGreedy)`` (it works as a class decorator) and use
``--policy eps-greedy`` wherever the registering module is imported.

Importing this package is light: the built-in families below register their classes (as a
user's do) and their numba hooks load only when a kernel is built.
"""

from __future__ import annotations

from .api import RGB, Choice, CompiledPolicy, Param, Policy, PolicyBase, gpu_form
from .registry import (
    available,
    builtins,
    paper_names,
    register,
    registered,
    resolve,
)
from .spec import (
    PolicySpec,
    make_policies,
    make_policy,
    parse_param_assignments,
    parse_policy_names,
)
from .variants import AOI_PREFIX

# The built-in families, in the order `corraoi policies` lists them (the paper's twelve first):
# importing one registers its classes.
from corraoi.policies import paper, forced_exploration, drifting, multi_source  # noqa: E402, F401, I001  isort: skip

__all__ = [
    "AOI_PREFIX",
    "RGB",
    "Choice",
    "CompiledPolicy",
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
    "register",
    "registered",
    "resolve",
]
