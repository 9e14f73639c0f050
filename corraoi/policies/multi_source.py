"""Multi-source forms of the built-in policies: several sources share the channels (issue 43).

Each form is a subclass of a single-source policy with its hooks unchanged and a rule that
shares the channels (:attr:`~corraoi.policies.api.CompiledPolicy.multi_source`), run once
per source by the engine's kernel of many sources (``corraoi/engine/_sources_kernel.py``,
which documents each rule):

* ``rhorand-<base>``: rhoRand (Anandkumar, Michael, Tang, Swami 2011; SMPyBandits'
  ``rhoRand``): each source aims at the r-th best of its own indices, r uniform in 1..M at
  the start and drawn again after each collision. A run of one source is the base policy's.
* ``mctopm-<base>``: MCTopM (Besson and Kaufmann 2018; SMPyBandits' ``MCTopM``).
* ``centralized-<base>``: a coordinator gives each source in turn the best of its indices
  among the channels still free: no collision ever, what decentralization is measured
  against.

The bases: UCB and TS, their correlated forms CUCB and CTS, and the AoI-aware form of each
(the AoI-aware rule per source, with the source's own age and means). docs/model.md, "Many
sources", pins the model and the feedback each rule uses.
"""

from __future__ import annotations

from .api import CompiledPolicy
from .paper import POLICIES
from .registry import register

#: The rules, with what ``corraoi policies`` says of them and where they come from.
RULES: dict[str, tuple[str, str]] = {
    "rhorand": (
        "rhoRand: the r-th best index, r redrawn uniformly in 1..M after a collision",
        "Anandkumar, Michael, Tang, Swami (2011); SMPyBandits rhoRand",
    ),
    "mctopm": (
        "MCTopM: a seat among its M best indices, kept until it leaves them",
        "Besson and Kaufmann (2018), ALT; SMPyBandits MCTopM",
    ),
    "centralized": (
        "centralized: each source in turn takes its best index among the free channels",
        "a coordinated baseline (no collisions)",
    ),
}
#: The single-source policies that have multi-source forms.
BASES = ("ucb", "cucb", "aoi-aware-ucb", "aoi-aware-cucb", "ts", "cts", "aoi-aware-ts",
         "aoi-aware-cts")  # fmt: skip


def multi_form(base: type[CompiledPolicy], rule: str) -> type[CompiledPolicy]:
    """``base`` shared among sources by ``rule`` (a subclass: the same hooks and flags)."""
    what, ref = RULES[rule]
    name = f"{rule}-{base.name}"
    attrs = {
        "name": name,
        "multi_source": rule,
        "gpu": None,
        "paper": False,
        "theorem": None,
        "summary": f"{base.describe().rstrip('.')}; many sources, {what}.",
        "reference": "; ".join(r for r in (base.reference, ref) if r),
        "__module__": __name__,
        "__doc__": base.__doc__,
    }
    cls_name = "".join(w.capitalize() for w in name.replace("-", " ").split())
    return type(cls_name, (base,), attrs)


FORMS = {f"{rule}-{b}": multi_form(POLICIES[b], rule) for rule in RULES for b in BASES}

for _cls in FORMS.values():
    register(_cls)
