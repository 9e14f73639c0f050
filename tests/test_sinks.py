"""One sink protocol (issue 23): everything in the recorder that takes a run's slots or a
sweep's points implements ``write``, ``close`` and ``abort`` and is a context manager, by
deriving from ``corraoi.recorder.sink.Sink``; leaving the ``with`` through an error aborts."""

from __future__ import annotations

import importlib
import inspect
import pkgutil
from pathlib import Path

import pytest

import corraoi.recorder
from corraoi.files.partial import partial_path
from corraoi.recorder.sink import Sink


def _writers() -> dict[str, type]:
    found = {}
    for info in pkgutil.walk_packages(corraoi.recorder.__path__, "corraoi.recorder."):
        module = importlib.import_module(info.name)
        for name, obj in vars(module).items():
            if (inspect.isclass(obj) and obj.__module__ == module.__name__
                    and callable(getattr(obj, "write", None))
                    and callable(getattr(obj, "close", None))):  # fmt: skip
                found[f"{module.__name__}.{name}"] = obj
    return found


def test_every_writer_of_the_recorder_is_a_sink():
    writers = _writers()
    # the sinks of a run (MCAP, Rerun in and out of process, Foxglove live) and of a sweep
    for name in ("McapSink", "RerunSink", "RemoteRecording", "FoxgloveSlotSink",
                 "FoxgloveSweepSink", "SweepMcapSink", "SweepRerunSink"):  # fmt: skip
        assert any(key.endswith(f".{name}") for key in writers), name
    not_sinks = sorted(k for k, cls in writers.items() if not issubclass(cls, Sink))
    assert not_sinks == []
    for cls in writers.values():
        assert callable(cls.abort) and hasattr(cls, "__enter__") and hasattr(cls, "__exit__")


def test_an_error_inside_the_with_aborts_and_leaves_the_partial_file(tmp_path: Path):
    from corraoi.engine.block import RunConfig
    from corraoi.face.slots import slots_of
    from corraoi.model.instance import load_instance
    from corraoi.policies import make_policy
    from corraoi.recorder.slotlog.sink import McapSink

    config = RunConfig(load_instance("I1"), make_policy("ucb"), 3, 50)
    out = tmp_path / "a.mcap"
    with pytest.raises(RuntimeError, match="boom"), McapSink(out, config) as sink:
        for block in slots_of(config):
            sink.write(block)
            raise RuntimeError("boom")
    assert not out.exists() and partial_path(out).stat().st_size > 0


class _Collect(Sink):
    """A user's own sink: keeps the slots it is given and how it was ended."""

    def __init__(self) -> None:
        self.t: list[int] = []
        self.ended: list[str] = []

    def write(self, block):  # type: ignore[no-untyped-def]
        self.t += [int(v) for v in block.t]

    def close(self) -> None:
        self.ended.append("close")

    def abort(self) -> None:
        self.ended.append("abort")


def test_record_run_hands_every_block_to_the_sinks_it_is_given(tmp_path: Path):
    from corraoi.engine.block import RunConfig
    from corraoi.face.recording import record_run
    from corraoi.model.instance import load_instance
    from corraoi.policies import make_policy
    from corraoi.recorder.slotlog.reader import open_log

    config = RunConfig(load_instance("I1"), make_policy("cucb"), 4, 2500)
    mine = _Collect()
    out = record_run(config, tmp_path / "a.mcap", sinks=[mine])
    assert mine.t == list(range(1, 2501)) and mine.ended == ["close"]
    assert list(open_log(out.mcap).read_all().t) == mine.t
    # stopped after the first block: the sink is closed with the slots so far
    stopped = _Collect()
    record_run(config, tmp_path / "b.mcap", sinks=[stopped], should_stop=lambda: True)
    assert stopped.t == list(range(1, 1001)) and stopped.ended == ["close"]


def test_a_failed_run_aborts_the_sinks(tmp_path: Path):
    from corraoi.engine.block import RunConfig
    from corraoi.errors import PolicyRuntimeError
    from corraoi.face.recording import record_run
    from corraoi.model.instance import load_instance
    from corraoi.policies import make_policy

    plugin = tmp_path / "late.py"
    plugin.write_text(
        "import numpy as np\nfrom corraoi.policies import Policy\n"
        "class Late(Policy):\n    name = 'late'\n"
        "    def select(self, t, state):\n"
        "        if t > 1500:\n            raise RuntimeError('tired')\n"
        "        return np.zeros(state.runs, dtype=np.int64)\n"
    )
    config = RunConfig(load_instance("I1"), make_policy(f"{plugin}:Late"), 0, 3000)
    mine = _Collect()
    with pytest.raises(PolicyRuntimeError, match="tired"):
        record_run(config, tmp_path / "c.mcap", sinks=[mine])
    assert mine.t == list(range(1, 1501)) and mine.ended == ["abort"]
