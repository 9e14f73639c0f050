"""What the command line tells about the model and the policies, without running anything:
the built-in instances with their theory, one instance's theory, regret bounds and chain, and
every policy with its parameters; and where the engine says that it compiles a kernel."""

from __future__ import annotations

import os
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    from corraoi.model.bounds import Bound
    from corraoi.model.instance import Instance
    from corraoi.model.markov import Mixing
    from corraoi.model.theory import InstanceTheory as Theory


def say_compiles(say: Callable[[str], None]) -> None:
    """``say(message)`` when the first use of a policy family compiles its kernel (seconds);
    Rerun's own log lines are silenced (its problems are reported as one line of ours)."""
    from corraoi.engine import kernel_cache

    os.environ.setdefault("RUST_LOG", "off")
    kernel_cache.on_compile = say


@dataclass(frozen=True)
class InstanceTheory:
    """An instance and what the paper's theory says of it: ``theory`` (mu, gaps, phi,
    competitive arms, C), ``bounds`` (the regret bounds at ``horizon``, by policy) and
    ``chain`` (the mixing of a Markov instance's states; None for i.i.d. states)."""

    instance: Instance
    theory: Theory
    bounds: dict[str, Bound]
    chain: Mixing | None
    horizon: int


def instance_theory(spec: str | os.PathLike[str], *, horizon: int = 10_000,
                    bound_beta: float | None = None) -> InstanceTheory:  # fmt: skip
    """The built-in instance or instance file ``spec`` with its theory and the CUCB and CTS
    bounds at ``horizon`` (``bound_beta``: Theorem 3's beta, default 2). Raises
    :class:`~corraoi.errors.InstanceError` for an instance that cannot be read."""
    from corraoi.model.bounds import DEFAULT_BOUND_BETA, cts_bound, cucb_bound
    from corraoi.model.instance import load_instance
    from corraoi.model.theory import analyse

    inst = load_instance(spec)
    theory = analyse(inst)
    bounds = {
        "cucb": cucb_bound(inst, horizon),
        "cts": cts_bound(inst, horizon, DEFAULT_BOUND_BETA if bound_beta is None else bound_beta),
    }
    chain = None
    if inst.transition is not None:
        from corraoi.model.markov import mixing

        chain = mixing(inst.transition, inst.p)
    return InstanceTheory(inst, theory, bounds, chain, horizon)


def builtin_instances() -> list[tuple[Instance, Theory]]:
    """Every built-in instance with its theory, in order."""
    from corraoi.model.instance import BUILTINS, load_instance
    from corraoi.model.theory import analyse

    return [(inst, analyse(inst)) for inst in map(load_instance, BUILTINS)]


def paper_policies() -> list[str]:
    """The paper's twelve policies (``--policy all``), in order."""
    from corraoi.policies import paper_names

    return list(paper_names())


def policy_entries() -> list[dict[str, Any]]:
    """Every policy, built-ins then plug-ins found through entry points: name, source and,
    for one that loads, its tier, summary, reference, colour and parameters (a broken entry
    point with its error)."""
    from corraoi.policies import available

    paper = set(paper_policies())
    entries = []
    for a in available():
        entry: dict[str, Any] = {"name": a.name, "source": a.source}
        if a.cls is None:
            entry.update(status="broken", error=a.error)
        else:
            entry.update(
                status="ok",
                tier=a.cls.tier,
                paper=a.name in paper,
                summary=a.cls.describe(),
                reference=a.cls.reference,
                color=list(a.cls.color) if a.cls.color else None,
                params={
                    k: {"default": p.default, "range": p.range_text(), "help": p.help}
                    for k, p in a.cls.params.items()
                },
            )
        entries.append(entry)
    return entries


__all__ = [
    "InstanceTheory", "builtin_instances", "instance_theory", "paper_policies", "policy_entries",
    "say_compiles",
]  # fmt: skip
