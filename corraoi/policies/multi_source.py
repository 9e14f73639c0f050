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
* ``chairs-<base>``: Musical Chairs (Rosenski, Shamir and Szlak 2016; SMPyBandits'
  ``MusicalChair``): a uniform channel for the first ``t0`` slots, then a uniform one of its
  M best indices until one plays without a collision, that channel then kept for good. Each
  source is told M (the paper estimates it from the learning phase's collisions).

The bases: UCB and TS, their correlated forms CUCB and CTS, and the AoI-aware form of each
(the AoI-aware rule per source, with the source's own age and means). docs/model.md, "Many
sources", pins the model and the feedback each rule uses.
"""

from __future__ import annotations

from .api import CompiledPolicy, Param
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
    "chairs": (
        "Musical Chairs: uniform channels for t0 slots, then a uniform one of its M best "
        "until one is free, kept for good",
        "Rosenski, Shamir, Szlak (2016), ICML; SMPyBandits MusicalChair",
    ),
}
#: A plain-Python policy's ``multi_source``: each source is an instance of the class of its
#: own, whose ``select`` picks that source's channel from that source's state
#: (docs/extending.md, "Many sources").
OWN = "own"
#: Musical Chairs' parameter: its learning slots (read by the engine of many sources).
CHAIRS_LEARN = "t0"
#: Musical Chairs' learning phase (its T0). The paper's T0 depends on the gap between the
#: M-th and (M+1)-th means, which the sources do not know; 500 slots is our default (the
#: ``t0`` parameter changes it). SMPyBandits' MusicalChair takes a quarter of the horizon.
T0_PARAM = Param(500.0, "Musical Chairs' learning slots: a uniform channel each, before the "
                 "chairs", low=0.0, integer=True)  # fmt: skip
#: The single-source policies that have multi-source forms.
BASES = ("ucb", "cucb", "aoi-aware-ucb", "aoi-aware-cucb", "ts", "cts", "aoi-aware-ts",
         "aoi-aware-cts")  # fmt: skip


def multi_form(base: type[CompiledPolicy], rule: str) -> type[CompiledPolicy]:
    """``base`` shared among sources by ``rule`` (a subclass: the same hooks and flags)."""
    what, ref = RULES[rule]
    name = f"{rule}-{base.name}"
    attrs: dict[str, object] = {
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
    if rule == "chairs":  # after the base's own, which its hooks read by position
        attrs["params"] = {**base.params, CHAIRS_LEARN: T0_PARAM}
    cls_name = "".join(w.capitalize() for w in name.replace("-", " ").split())
    return type(cls_name, (base,), attrs)


FORMS = {f"{rule}-{b}": multi_form(POLICIES[b], rule) for rule in RULES for b in BASES}

for _cls in FORMS.values():
    register(_cls)
