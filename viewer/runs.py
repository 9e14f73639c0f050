"""Opening logs for the viewer and naming runs: shared by replay, compare, diff and info."""

from __future__ import annotations

import os
import re
from collections import Counter
from collections.abc import Sequence
from typing import TYPE_CHECKING, Any, Union

if TYPE_CHECKING:
    from corraoi.recorder.slotlog.reader import RunLog

#: What the viewer functions accept for a log: a path or an opened RunLog.
LogLike = Union[str, "os.PathLike[str]", "RunLog"]

_UNSAFE = re.compile(r"[^A-Za-z0-9_.+-]+")


def as_log(log: LogLike, *, verify: bool = True) -> RunLog:
    """An opened RunLog (opening ``log`` when it is a path; LogError for bad input).

    ``verify`` checks every chunk (CRC, decompression) now; without it a damaged chunk is
    found when it is read.
    """
    from corraoi.recorder.slotlog.reader import RunLog, open_log

    if isinstance(log, RunLog):
        return log
    return open_log(log, verify=verify)


def require_slots(log: RunLog, what: str) -> RunLog:
    """``log`` if it holds at least one slot; a LogError (exit 2) naming it otherwise.

    A writer killed before its first chunk reached the disk leaves a valid file with no
    slot: there is nothing to replay, compare or recover.
    """
    if log.n_slots == 0:
        from corraoi.errors import LogError

        raise LogError(
            f"{log.path}: no complete slot in the log ({log.summary}); nothing to {what}"
        )
    return log


def safe_label(text: str) -> str:
    """``text`` as one Rerun entity path part: letters, digits and ``_ . + -`` only."""
    return _UNSAFE.sub("_", text).strip("_") or "run"


def config_key(log: RunLog) -> dict[str, Any]:
    """What tells runs apart for labelling: instance, seed, horizon, parameters."""
    cfg = log.config
    return {
        "instance": cfg.instance_name,
        "seed": cfg.seed,
        "horizon": cfg.horizon,
        "params": tuple(sorted(cfg.policy.params.items())),
    }


def unique_labels(logs: Sequence[RunLog]) -> list[str]:
    """One label per run: the policy name, plus instance, seed, horizon or parameters where
    runs of the same policy need telling apart, plus ``-2``, ``-3`` ... for true twins.

    ``ucb, cucb`` on one seed gives ``ucb, cucb``; two ucb runs with seeds 0 and 1 give
    ``ucb-s0, ucb-s1``; ucb on I1 and on I2 gives ``ucb-I1, ucb-I2``.
    """
    names = [log.config.policy.name for log in logs]
    keys = [config_key(log) for log in logs]
    labels = list(names)
    for name in set(names):
        group = [i for i, n in enumerate(names) if n == name]
        if len(group) < 2:
            continue
        varying = [
            k for k in ("instance", "seed", "horizon", "params")
            if len({repr(keys[i][k]) for i in group}) > 1
        ]  # fmt: skip
        for i in group:
            parts = [name]
            cfg = logs[i].config
            for k in varying:
                if k == "instance":
                    parts.append(cfg.instance_name)
                elif k == "seed":
                    parts.append(f"s{cfg.seed}")
                elif k == "horizon":
                    parts.append(f"T{cfg.horizon}")
                else:
                    params = sorted(cfg.policy.params.items())
                    parts.append(",".join(f"{p}{v:g}" for p, v in params))
            labels[i] = "-".join(parts)
    labels = [safe_label(x) for x in labels]
    counts = Counter(labels)
    seen: Counter[str] = Counter()
    out = []
    for x in labels:
        if counts[x] > 1:
            seen[x] += 1
            out.append(x if seen[x] == 1 else f"{x}-{seen[x]}")
        else:
            out.append(x)
    # a suffixed twin could collide with a real label ("ucb-2"): number until unique
    final: list[str] = []
    for x in out:
        y, n = x, 2
        while y in final:
            y, n = f"{x}-{n}", n + 1
        final.append(y)
    return final
