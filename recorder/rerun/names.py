"""What one run's Rerun recording is called: its application and recording ids, its timeline
and its entities' paths.

Entities (timeline ``slot``, a sequence; arms and states numbered from 1), under
``runs/<label>`` (:func:`run_path`):

==================  =====================================================================
``aoi``             age of information after the slot (line)
``oracle_aoi``      age of the oracle playing the best arm on the same hidden path (dots)
``regret``          pathwise AoI regret sum (aoi - oracle_aoi) (line)
``estimator``       the paper's estimator sum aoi - t / mu* (line)
``arm/success``     the arm played, at the slots where it delivered (points)
``arm/failure``     the arm played, at the slots where it failed (points)
``override``        the arm played, at the slots where the AoI-aware rule chose it (points)
``x``               the hidden state X_t (points)
``mu_hat``          empirical mean of every arm after the slot, K series
``mu_true``         true mean of every arm (constant: two points a batch), ``mu_k (true)``
``pulls``           pulls of every arm after the slot, K series
``candidates/<k>``  the value k at the slots where arm k was in the candidate set (points)
``about``           the run configuration (static markdown)

:mod:`recorder.rerun.static` logs what they look like, :mod:`recorder.rerun.sink` their data
and :mod:`recorder.rerun.layout` arranges them.
"""

from __future__ import annotations

import hashlib
import json

import rerun as rr

from corraoi.engine.block import RunConfig

APPLICATION_ID = "corraoi"
TIMELINE = "slot"
ROOT = "runs"

#: Entities of a run, relative to :func:`run_path` (``candidates`` has one child per arm).
ENTITIES = (
    "aoi",
    "oracle_aoi",
    "regret",
    "estimator",
    "arm/success",
    "arm/failure",
    "override",
    "x",
    "mu_hat",
    "mu_true",
    "pulls",
    "candidates",
    "about",
)


def run_path(label: str) -> str:
    """``runs/<label>``, the label escaped as one entity path part."""
    return f"{ROOT}/{rr.escape_entity_path_part(label)}"


def run_recording_id(config: RunConfig) -> str:
    """A recording id that depends on the run configuration only (reproducible files)."""
    digest = hashlib.sha256(json.dumps(config.to_dict(), sort_keys=True).encode()).hexdigest()
    return f"corraoi-run-{digest[:16]}"


def new_recording(
    config: RunConfig,
    *,
    recording_id: str | None = None,
    application_id: str = APPLICATION_ID,
) -> rr.RecordingStream:
    """A RecordingStream for one run: explicit id, no wall-clock timeline, named by label.

    It starts with a buffered sink: attach destinations (``set_sinks``, ``save``, ...)
    before sending data, or use :class:`RrdOutput`.
    """
    rec = rr.RecordingStream(
        application_id,
        recording_id=recording_id or run_recording_id(config),
        send_properties=False,
    )
    rec.set_log_time_enabled(False)
    rec.set_log_tick_enabled(False)
    rec.send_recording_name(config.label)
    return rec


__all__ = [
    "APPLICATION_ID",
    "ENTITIES",
    "ROOT",
    "TIMELINE",
    "new_recording",
    "run_path",
    "run_recording_id",
]
