"""Runs of several sources built by hand from single-source runs, for the tests of the log,
the face and the viewer of such runs while no engine simulates them (issue 43).

Source m plays what a single-source run of ``policies[m - 1]`` on the same seed plays (the
hidden path x is the seed's, shared by every policy); where two sources play one channel
they collide and neither delivers; each source's age, its oracle's age (the orthogonal
oracle: source m on the m-th best arm, ties by lowest index) and its regret follow from
those, as the model says. Not a policy of several sources: only a consistent run to record.
"""

from __future__ import annotations

import sys
import types
from collections.abc import Iterator
from dataclasses import replace

import numpy as np

from corraoi.engine.block import SlotBlock, SourcesBlock
from corraoi.engine.simulation import simulate_run
from corraoi.errors import CorraoiError
from corraoi.policies import make_policy

#: the single-source policies the hand-made sources play, source by source
POLICIES = ("ucb", "ts", "cucb", "cts", "ucb", "ts", "cucb", "cts")


def policy_name() -> str:
    """A policy a run of several sources may name: a multi-source form once the engine has
    them (issue 43: a single-source policy with sources > 1 is then refused), else ``ucb``.
    The hand-made run plays :data:`POLICIES` whatever it names."""
    try:
        make_policy("rhorand-ucb")
    except CorraoiError:
        return "ucb"
    return "rhorand-ucb"


def sources_run(instance, seed: int, horizon: int, sources: int) -> SourcesBlock:
    """A whole run of ``sources`` sources on ``instance`` (see the module's docstring)."""
    runs = [SlotBlock.concat(list(simulate_run(instance, make_policy(p), seed, horizon)))
            for p in POLICIES[:sources]]  # fmt: skip
    x = runs[0].x
    assert all(np.array_equal(r.x, x) for r in runs)
    arms = np.stack([r.arm for r in runs])  # (M, T)
    clash = np.array([[np.count_nonzero(arms[:, t] == arms[m, t]) > 1 for t in range(horizon)]
                      for m in range(sources)])  # fmt: skip
    Y = instance.Y.astype(bool)
    mu = instance.Y.astype(float) @ np.asarray(instance.p, dtype=float)
    order = sorted(range(len(mu)), key=lambda k: (-mu[k], k))
    out = []
    for m, r in enumerate(runs):
        success = Y[r.arm, x] & ~clash[m]
        oracle = Y[order[m], x]
        aoi, oaoi = _ages(success), _ages(oracle)
        out.append(replace(r, success=success, collided=clash[m], aoi=aoi, oracle_aoi=oaoi,
                           regret=np.cumsum(aoi - oaoi)))  # fmt: skip
    return SourcesBlock(tuple(out))


def _ages(delivered: np.ndarray) -> np.ndarray:
    """The age after each slot (1 after a delivery, one more otherwise; 1 before slot 1)."""
    out = np.empty(len(delivered), dtype=np.int64)
    age = 1
    for t, d in enumerate(delivered):
        age = 1 if d else age + 1
        out[t] = age
    return out


def simulate_run_sources(
    instance, policy, seed, horizon, sources, *, block=1000, channel=None
) -> Iterator[SourcesBlock]:
    """The engine's ``simulate_run_sources`` as the face calls it, made by hand (the
    ``policy`` is not what the sources play: :data:`POLICIES` is)."""
    whole = sources_run(instance, seed, horizon, sources)
    for start in range(0, horizon, block):
        yield whole.slice(start, min(start + block, horizon))


def install(monkeypatch) -> None:
    """Make ``corraoi.engine.sources.simulate_run_sources`` the hand-made one (for a test)."""
    try:
        import corraoi.engine.sources as real  # the engine's, once it lands

        monkeypatch.setattr(real, "simulate_run_sources", simulate_run_sources)
    except ImportError:
        fake = types.ModuleType("corraoi.engine.sources")
        fake.simulate_run_sources = simulate_run_sources  # type: ignore[attr-defined]
        monkeypatch.setitem(sys.modules, "corraoi.engine.sources", fake)
