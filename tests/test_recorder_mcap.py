"""McapSink: what it writes, slot for slot, and how it finishes (or does not)."""

from __future__ import annotations

import errno
import json
from pathlib import Path

import numpy as np
import pytest
from jsonschema import Draft202012Validator
from mcap.reader import make_reader

from corraoi.engine.block import RunConfig, SlotBlock
from corraoi.errors import OutputError, WriteError
from corraoi.files import partial as partial_file
from corraoi.files.partial import partial_path
from corraoi.recorder.slotlog.reader import open_log
from corraoi.recorder.slotlog.sink import McapSink
from corraoi.recorder.vocab import NS_PER_SLOT
from corraoi.recorder.vocab import SLOT_TOPIC as TOPIC


@pytest.mark.parametrize("policy", ["cucb", "ts", "aoi-aware-cts", "aoi-aware-ucb"])
def test_round_trip_equals_the_engine_slot_for_slot(record_mcap, policy):
    path, config, ref = record_mcap(policy, horizon=2345, seed=3)
    log = open_log(path)
    assert (log.n_slots, log.status, log.cut_short, log.finished) == (2345, "complete", False, True)
    assert log.format_version == 1
    assert log.config.to_dict() == config.to_dict()
    got = log.read_all()
    assert got.equals(ref)
    # the values compared are not trivially equal: the run did something
    assert ref.regret[-1] != 0 and len(np.unique(ref.arm)) > 1
    if policy.startswith("aoi-aware"):
        assert ref.override.any() and np.array_equal(got.override, ref.override)


def test_the_file_is_byte_identical_across_runs_and_engine_block_sizes(record_mcap):
    a, _, _ = record_mcap(horizon=3100, name="a.mcap")
    b, _, _ = record_mcap(horizon=3100, name="b.mcap")
    c, _, _ = record_mcap(horizon=3100, name="c.mcap", block=337)
    assert a.read_bytes() == b.read_bytes() == c.read_bytes()
    d, _, _ = record_mcap(horizon=3100, name="d.mcap", seed=1)
    assert d.read_bytes() != a.read_bytes()


def test_every_message_validates_against_the_stored_schema_and_counts_from_one(record_mcap):
    path, config, ref = record_mcap("cts", horizon=1500)
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        assert summary.statistics.message_count == 1500
        (schema,) = summary.schemas.values()
        assert schema.name == "corraoi.SlotEvent" and schema.encoding == "jsonschema"
        validator = Draft202012Validator(json.loads(schema.data))
        Draft202012Validator.check_schema(validator.schema)
        rows = []
        for _, channel, message in reader.iter_messages(topics=[TOPIC]):
            assert channel.message_encoding == "json"
            row = json.loads(message.data)
            validator.validate(row)
            assert message.log_time == message.publish_time == row["t"] * NS_PER_SLOT
            assert message.sequence == row["t"]
            rows.append(row)
    assert [r["t"] for r in rows] == list(range(1, 1501))
    assert [r["arm"] for r in rows] == (ref.arm + 1).tolist()
    assert [r["x"] for r in rows] == (ref.x + 1).tolist()
    assert min(r["arm"] for r in rows) == 1 and max(r["arm"] for r in rows) == 4
    cands = [r["candidates"] for r in rows]
    assert cands == [list(np.flatnonzero(m) + 1) for m in ref.candidates]
    assert any(len(c) < 4 for c in cands)  # the correlated policy did shrink the set
    assert [r["mu_hat"] for r in rows] == ref.mu_hat.tolist()
    # an invalid message is caught by the same schema: the check can fail
    bad = dict(rows[0], arm=0)
    assert not validator.is_valid(bad)


def test_the_configuration_and_the_ending_are_inside_the_file(record_mcap):
    path, config, ref = record_mcap("cucb", horizon=1200, seed=7)
    with open(path, "rb") as f:
        reader = make_reader(f)
        header = reader.get_header()
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
    assert header.library == f"corraoi/{config.version}"
    run = meta["corraoi.run"]
    assert all(isinstance(v, str) for v in run.values())
    assert RunConfig.from_dict(json.loads(run["config"])).to_dict() == config.to_dict()
    assert (run["policy"], run["instance"], run["seed"], run["horizon"]) == (
        "cucb",
        "I1",
        "7",
        "1200",
    )
    assert run["best_arm"] == "2" and json.loads(run["competitive_arms"]) == [3]
    assert json.loads(run["params"]) == {"c": 2.0}
    end = meta["corraoi.end"]
    assert end["status"] == "complete" and end["slots"] == "1200"
    assert end["regret"] == str(int(ref.regret[-1]))
    assert json.loads(end["pulls"]) == ref.pulls[-1].tolist()


@pytest.mark.parametrize("background", [False, True], ids=["in-line", "background"])
def test_a_chunk_reaches_the_disk_every_1000_slots(tmp_path, make_config, engine, background):
    """In line, the chunk that slot 2000 closes is on disk when write() returns; written
    in the background (corraoi record on more than one core), at most that chunk is still
    on its way."""
    config = make_config(horizon=5000)
    path = tmp_path / "live.mcap"
    blocks = engine(config, block=500)
    sink = McapSink(path, config, fsync=False, background=background)
    for b in blocks[:5]:  # 2500 slots handed over, the file not closed
        sink.write(b)
    live = open_log(partial_path(path))
    assert (live.status, live.finished, live.cut_short) == ("truncated", False, True)
    assert live.n_slots in ((1000, 2000) if background else (2000,))
    assert live.read_all().equals(SlotBlock.concat(blocks[: live.n_slots // 500]))
    assert not path.exists()
    for b in blocks[5:]:
        sink.write(b)
    assert sink.close() == path
    assert sink.close() == path  # twice is safe
    assert not partial_path(path).exists()
    assert open_log(path).n_slots == 5000
    with pytest.raises(ValueError):
        sink.write(blocks[0])


def test_ctrl_c_inside_the_with_block_finishes_the_file(tmp_path, make_config, engine):
    config = make_config("aoi-aware-ucb", horizon=4000)
    path = tmp_path / "int.mcap"
    blocks = engine(config, block=500)
    with pytest.raises(KeyboardInterrupt):
        with McapSink(path, config, fsync=False) as sink:
            for i, b in enumerate(blocks):
                if i == 3:
                    raise KeyboardInterrupt
                sink.write(b)
    log = open_log(path)
    assert (log.n_slots, log.status, log.finished, log.cut_short) == (
        1500,
        "interrupted",
        True,
        True,
    )
    assert log.read_all().equals(SlotBlock.concat(blocks[:3]))
    assert log.end["regret"] == str(int(blocks[2].regret[-1]))
    assert not partial_path(path).exists()


def test_any_other_error_leaves_only_the_partial_file(tmp_path, make_config, engine):
    config = make_config(horizon=4000)
    path = tmp_path / "err.mcap"
    blocks = engine(config, block=700)
    with pytest.raises(RuntimeError):
        with McapSink(path, config, fsync=False) as sink:
            for i, b in enumerate(blocks):
                if i == 4:
                    raise RuntimeError("boom")
                sink.write(b)
    assert not path.exists()
    log = open_log(partial_path(path))
    # the blocks handed over whole (4 x 700) are flushed, without a footer
    assert (log.status, log.finished, log.n_slots) == ("truncated", False, 2800)
    assert log.read_all().equals(SlotBlock.concat(blocks[:4]))


def test_refuses_to_clobber_and_to_write_into_odd_places(tmp_path, make_config, engine):
    config = make_config(horizon=10)
    blocks = engine(config)
    existing = tmp_path / "old.mcap"
    existing.write_bytes(b"keep me")
    with pytest.raises(OutputError, match="already exists.*--force"):
        McapSink(existing, config)
    assert existing.read_bytes() == b"keep me"
    with pytest.raises(OutputError, match="is a directory"):
        McapSink(tmp_path, config)
    (tmp_path / "file").write_text("x")
    with pytest.raises(OutputError, match="not a directory"):
        McapSink(tmp_path / "file" / "x.mcap", config)
    stale = tmp_path / "stale.mcap"
    partial_path(stale).write_bytes(b"half")
    with pytest.raises(OutputError, match="partial file"):
        McapSink(stale, config)
    with McapSink(existing, config, overwrite=True, fsync=False) as sink:
        sink.write(blocks[0])
    assert open_log(existing).n_slots == 10
    deep = tmp_path / "a" / "b" / "c.mcap"  # missing parents are created
    with McapSink(deep, config, fsync=False) as sink:
        sink.write(blocks[0])
    assert open_log(deep).n_slots == 10


def test_slots_must_follow_each_other(tmp_path, make_config, engine):
    config = make_config(horizon=3000)
    blocks = engine(config)
    with McapSink(tmp_path / "x.mcap", config, fsync=False) as sink:
        with pytest.raises(ValueError, match="expected to start at 1"):
            sink.write(blocks[1])
        sink.write(blocks[0])
        sink.write(blocks[1])
    assert open_log(tmp_path / "x.mcap").n_slots == 2000


class _FullDisk:
    """A file that accepts ``room`` bytes, then fails like a full disk."""

    def __init__(self, f, room: int) -> None:
        self.f, self.room = f, room

    def write(self, data) -> int:
        if self.room < len(data):
            raise OSError(errno.ENOSPC, "No space left on device")
        self.room -= len(data)
        return self.f.write(data)

    def __getattr__(self, name):
        return getattr(self.f, name)


@pytest.mark.parametrize("background", [False, True], ids=["in-line", "background"])
def test_a_full_disk_is_one_clear_error_and_no_finished_file(
    tmp_path, make_config, engine, monkeypatch, background
):
    real = partial_file.fdopen  # the seam where PartialFile opens its file
    monkeypatch.setattr(partial_file, "fdopen", lambda fd: _FullDisk(real(fd), 150_000))
    config = make_config(horizon=20_000)
    path = tmp_path / "full.mcap"
    with pytest.raises(WriteError) as info:
        with McapSink(path, config, fsync=False, background=background) as sink:
            for b in engine(config):
                sink.write(b)
    message = str(info.value)
    assert "No space left on device" in message and "full.mcap.partial" in message
    assert "\n" not in message and info.value.exit_code == 1
    assert not path.exists()
    log = open_log(partial_path(path))  # what reached the disk is still readable
    assert log.status == "truncated" and 0 < log.n_slots < 20_000


def test_a_run_stopped_before_its_first_slot_is_an_empty_log(tmp_path, make_config):
    config = make_config(horizon=100)
    with McapSink(tmp_path / "e.mcap", config, fsync=False):
        pass
    log = open_log(tmp_path / "e.mcap")
    assert (log.n_slots, log.status, log.cut_short) == (0, "interrupted", True)
    empty = log.read_all()
    assert len(empty) == 0 and empty.mu_hat.shape == (0, 4)
    assert list(log.blocks()) == []


def test_path_of_the_partial_file_is_documented_form():
    assert partial_path(Path("runs/cucb-I1-s0.mcap")) == Path("runs/cucb-I1-s0.mcap.partial")


@pytest.mark.parametrize(("channel", "version"), [("iid", 1), ("markov", 2)])
def test_the_schema_id_says_the_runs_own_format_version(tmp_path, make_config, engine,
                                                        channel, version):  # fmt: skip
    """Issue 32: a version-1 run's schema id said version 2. The schema's id and description,
    the channel's and the run metadata's format_version now agree, for either version."""
    import dataclasses

    from corraoi.model.channels import parse_channel

    config = make_config(horizon=50, instance="GE")
    config = dataclasses.replace(config, channel=parse_channel(channel, config.instance))
    assert config.format_version == version
    path = tmp_path / "v.mcap"
    with McapSink(path, config, fsync=False) as sink:
        for b in engine(config):
            sink.write(b)
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None
        (schema,) = summary.schemas.values()
        (chan,) = summary.channels.values()
        run_md = next(m for m in reader.iter_metadata() if m.name == "corraoi.run").metadata
    data = json.loads(schema.data)
    assert data["$id"] == f"urn:corraoi:slot-event:v{version}"
    assert f"corraoi.slot-log version {version})" in data["description"]
    assert chan.metadata["format_version"] == run_md["format_version"] == str(version)
    assert open_log(path).format_version == version
