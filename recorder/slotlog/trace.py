"""A slot log's hidden path as a trace channel's states (``--channel trace:RUN.mcap``).

Reading the slot log is the recorder's job, replaying states the core's: the top floor
hands this reader to the core (``corraoi.face.resolve.TRACE_READERS``).
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
    if log.config.n_states != instance.n_states:
        raise ConfigError(
            f"{where}: the log's instance {log.config.instance_name} has "
            f"{log.config.n_states} states, instance {instance.name} has "
            f"{instance.n_states}"
        )
    blocks = [b.x for b in log.blocks()]
    return np.concatenate(blocks).astype(np.int64) if blocks else np.zeros(0, np.int64)
