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
``about``           the run card: configuration, arms and what the views show (markdown)
``why/score``       up to LINES_UP_TO arms: every arm's score (what the policy maximised),
                    K series (as ``mu_hat``), at the slots scored; -inf (no point drawn)
                    for an arm without a finite one there (outside the candidate set)
``why/chosen``      the score of the arm played (points): up to LINES_UP_TO arms only at the
                    slots it was below the top score (elsewhere the top line is the arm
                    played), beyond at the slots the score chose it
``why/forced``      the arm played, at the slots it was not chosen by the score (points)
``why/threshold``   the AoI-aware rule's threshold 1 / max mu_hat (line, in the AoI view)
==================  =====================================================================

The ``why/`` entities come from the fields a run may lack (``score``, ``forced``,
``override_threshold``): a run without them (a log written before them, a plain-Python
plug-in that gives no scores) has none of them, and its recording is what it was before.

Presentation entities (:data:`PRESENTATION`), drawn from the same slots to make the views
read at any K (:data:`corraoi.recorder.style.LINES_UP_TO`):

====================  ===================================================================
``arm/best``          the best arm k*, a reference line (slots 1 and T, sent at the start)
``true_means/<k>``    arm k's true mean as dots at evenly spaced slots up to T (arm k's
                      shifted by k, so that equal means alternate colours), sent at the
                      start: every arm up to LINES_UP_TO arms, beyond it the arms that
                      matter (from the slot each came to matter)
``focus/<k>``         beyond LINES_UP_TO arms: arm k's empirical mean from the slot it came
                      to matter (:func:`corraoi.recorder.style.arms_that_matter`; it became the most
                      played, or was in a candidate set of at most FOCUS_MAX arms)
``bars/mean``         beyond LINES_UP_TO arms, at slot 1, every :func:`snapshot_every`-th
                      slot and the last: the empirical means of the arms in the candidate
                      set that do not matter (a bar chart, 0 for the others)
``bars/mean_other``   the same for the arms out of the candidate set
``bars/mean_true``    the true means (a static bar chart)
``bars/pulls``        the pulls of the arms that do not matter, at the same slots
``bars/mean_arm/<k>`` arm k's empirical mean, one bar in its colour, from the slot it came
                      to matter
``bars/pulls_arm/<k>`` arm k's pulls, the same way
``why/bars/score``    beyond LINES_UP_TO arms, at the bars' slots: the candidates' scores
                      (0 for the others and for the arm played)
``why/bars/chosen``   the arm played's score alone, in the policy's colour
``why/focus/<k>``     beyond LINES_UP_TO arms: arm k's score, from the slot it came to
                      matter (as ``focus/<k>``)
====================  ===================================================================

:mod:`corraoi.recorder.rerun.static` logs what they look like, :mod:`corraoi.recorder.rerun.sink`
their data and :mod:`corraoi.recorder.rerun.layout` arranges them.
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
#: The "why this arm" entities, relative to :func:`run_path`: a run that logs scores has
#: them (``why/focus`` and ``why/bars`` hold children), the others none.
WHY = (
    "why/score",
    "why/chosen",
    "why/forced",
    "why/threshold",
    "why/bars/score",
    "why/bars/chosen",
    "why/focus",
)
#: Entities drawn for the views only, relative to :func:`run_path` (``true_means`` and
#: ``focus`` have one child per arm shown).
PRESENTATION = (
    "arm/best",
    "true_means",
    "focus",
    "bars/mean",
    "bars/mean_other",
    "bars/mean_true",
    "bars/pulls",
    "bars/mean_arm",
    "bars/pulls_arm",
)
#: Snapshots of the per-arm bars in a run, about (:func:`snapshot_every`).
SNAPSHOTS = 1000
#: Dots of all the true-mean lines of a run together, about: each arm's line has
#: TRUE_DOTS // K of them (at least 8), so that where two arms' means are equal their dots
#: alternate with room between them.
TRUE_DOTS = 80


def snapshot_every(horizon: int) -> int:
    """Slots between two snapshots of the per-arm bars (also taken at slot 1 and the last
    slot): about :data:`SNAPSHOTS` in a run of ``horizon`` slots."""
    return max(1, -(-int(horizon) // SNAPSHOTS))


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
    name: str | None = None,
) -> rr.RecordingStream:
    """A RecordingStream for one run: explicit id, no wall-clock timeline, named (as the
    viewer lists it) ``name``, by default the run's label.

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
    rec.send_recording_name(name or config.label)
    return rec


__all__ = [
    "APPLICATION_ID",
    "ENTITIES",
    "PRESENTATION",
    "SNAPSHOTS",
    "TRUE_DOTS",
    "ROOT",
    "TIMELINE",
    "WHY",
    "new_recording",
    "run_path",
    "run_recording_id",
    "snapshot_every",
]
