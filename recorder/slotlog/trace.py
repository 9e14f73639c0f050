"""A slot log's hidden path as a trace channel's states (``--channel trace:RUN.mcap``).

The core names this reader in ``corraoi.model.channels.TRACE_READERS``: reading the slot log is
the recorder's job, replaying states is the core's.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from corraoi.errors import ConfigError
from corraoi.model.instance import Instance

from .reader import open_log


def states_of_log(path: Path, instance: Instance, where: str) -> np.ndarray:
    """The 0-based states ``x`` of every slot of the log at ``path`` (a cut-short log gives
    the slots it holds), refused when its instance has another number of states."""
    log = open_log(path)
    if log.config.instance.n_states != instance.n_states:
        raise ConfigError(
            f"{where}: the log's instance {log.config.instance.name} has "
            f"{log.config.instance.n_states} states, instance {instance.name} has "
            f"{instance.n_states}"
        )
    blocks = [b.x for b in log.blocks()]
    return np.concatenate(blocks).astype(np.int64) if blocks else np.zeros(0, np.int64)
