"""One sink protocol (issue 23): everything in the recorder that takes a run's slots or a
sweep's points implements ``write``, ``close`` and ``abort`` and is a context manager, by
deriving from ``recorder.paths.Sink``; leaving the ``with`` through an error aborts."""

from __future__ import annotations

import importlib
import inspect
import pkgutil
from pathlib import Path

import pytest

import recorder
from recorder.paths import Sink, partial_path


def _writers() -> dict[str, type]:
    found = {}
    for info in pkgutil.iter_modules(recorder.__path__):
        module = importlib.import_module(f"recorder.{info.name}")
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
    from corraoi.block import RunConfig
    from corraoi.instance import load_instance
    from corraoi.policies import make_policy
    from corraoi.slots import slots_of
    from recorder.mcap_sink import McapSink

    config = RunConfig(load_instance("I1"), make_policy("ucb"), 3, 50)
    out = tmp_path / "a.mcap"
    with pytest.raises(RuntimeError, match="boom"), McapSink(out, config) as sink:
        for block in slots_of(config):
            sink.write(block)
            raise RuntimeError("boom")
    assert not out.exists() and partial_path(out).stat().st_size > 0
