"""RerunSink and RrdOutput: the .rrd read back value for value, reproducible, one render path."""

from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pytest

rr = pytest.importorskip("rerun")
from rerun.chunk import RrdReader  # noqa: E402

from corraoi.engine.block import SlotBlock  # noqa: E402
from corraoi.errors import OutputError  # noqa: E402
from corraoi.files.partial import partial_path  # noqa: E402
from corraoi.recorder.rerun.layout import one_run_blueprint  # noqa: E402
from corraoi.recorder.rerun.names import new_recording, run_path  # noqa: E402
from corraoi.recorder.rerun.output import RrdOutput  # noqa: E402
from corraoi.recorder.rerun.sink import RerunSink  # noqa: E402
from corraoi.recorder.slotlog.reader import open_log  # noqa: E402

from .rrd_util import RERUN, read_rrd, strict_rerun  # noqa: E402, F401


def write_rrd(path: Path, config, blocks, **kw) -> Path:
    with RrdOutput(config, rrd_path=path, **kw) as out:
        with RerunSink(out.recording, config.label, config) as sink:
            for b in blocks:
                sink.write(b)
    return path


def test_the_rrd_holds_every_slot_value_for_value(tmp_path, make_config, engine):
    config = make_config("aoi-aware-cucb", horizon=2600, seed=5)
    blocks = engine(config)
    ref = SlotBlock.concat(blocks)
    path = write_rrd(tmp_path / "run.rrd", config, blocks)
    data = read_rrd(path)
    base = "/" + run_path(config.label)
    t = np.arange(1, 2601)

    def scalars(name: str, expect_t=t) -> np.ndarray:
        slots, values = data[f"{base}/{name}"]
        assert np.array_equal(slots, expect_t), name
        assert all(len(v) == 1 for v in values), name
        return np.array([v[0] for v in values])

    assert np.array_equal(scalars("aoi"), ref.aoi)
    assert np.array_equal(scalars("oracle_aoi"), ref.oracle_aoi)
    assert np.array_equal(scalars("regret"), ref.regret)
    assert np.array_equal(scalars("estimator"), ref.estimator)  # float64, exactly
    assert np.array_equal(scalars("x"), ref.x + 1)
    ok = ref.success
    assert np.array_equal(scalars("arm/success", t[ok]), ref.arm[ok] + 1)
    assert np.array_equal(scalars("arm/failure", t[~ok]), ref.arm[~ok] + 1)
    assert ref.override.any()
    assert np.array_equal(scalars("override", t[ref.override]), ref.arm[ref.override] + 1)
    for name in ("mu_hat", "pulls"):
        slots, values = data[f"{base}/{name}"]
        assert np.array_equal(slots, t)
        assert np.array_equal(np.array(values), getattr(ref, name))
    for k in range(config.instance.K):
        member = ref.candidates[:, k]
        if member.any():
            assert np.array_equal(
                scalars(f"candidates/{k + 1}", t[member]), np.full(member.sum(), k + 1)
            )
        else:
            assert f"{base}/candidates/{k + 1}" not in data
    assert not ref.candidates.all()  # the competitive set did exclude arms


def test_styling_is_static_and_the_blueprint_is_embedded(tmp_path, make_config, engine):
    config = make_config(horizon=1000)
    path = write_rrd(tmp_path / "run.rrd", config, engine(config))
    reader = RrdReader(path)
    (recording,) = reader.recordings()
    assert recording.application_id == "corraoi"
    assert len(reader.blueprints()) == 1
    static = {}
    for chunk in reader.stream():
        if chunk.is_static:
            static[chunk.entity_path] = chunk.to_record_batch().to_pydict()
    base = "/" + run_path(config.label)
    assert static[f"{base}/aoi"]["SeriesLines:names"] == [["AoI [slots]"]]
    oracle = static[f"{base}/oracle_aoi"]  # dotted: points, no line, named
    assert oracle["SeriesPoints:names"] == [["oracle AoI, best arm k* [slots]"]]
    assert "SeriesLines:names" not in oracle
    arms = [f"arm {k}" for k in range(1, 5)]  # an arm's line and its true mean: one name
    assert static[f"{base}/mu_hat"]["SeriesLines:names"] == [arms]
    assert static[f"{base}/mu_true"]["SeriesLines:names"] == [arms]
    assert static[f"{base}/pulls"]["SeriesLines:names"] == [arms]
    for k in range(1, 5):
        assert static[f"{base}/true_means/{k}"]["SeriesPoints:names"] == [[f"arm {k}"]]
    assert static[f"{base}/arm/failure"]["SeriesPoints:names"] == [["failure"]]
    assert static[f"{base}/arm/best"]["SeriesLines:names"] == [["best arm k* = 2"]]
    about = static[f"{base}/about"]["TextDocument:text"][0][0]
    assert "cucb" in about and "seed 0" in about and "**best k\\***" in about
    texts = []
    for chunk in reader.stream(store=reader.blueprints()[0]):
        for column in chunk.to_record_batch().columns:
            if "string" in str(column.type):  # view names, origins, queries
                texts.append(str(column.to_pylist()))
    blueprint_text = " ".join(texts)
    views = ("AoI [slots]: policy (line), oracle k* (black dots)", "AoI regret [slot-ages]",
             "arm played", "candidate set", "[probability]")  # fmt: skip
    for view in (*views, run_path(config.label), "$origin/candidates/**"):
        assert view in blueprint_text


def compare(a: Path, b: Path) -> subprocess.CompletedProcess:
    return subprocess.run([RERUN, "rrd", "compare", str(a), str(b)], capture_output=True, text=True)


def test_same_run_same_recording_and_a_replay_renders_the_same(tmp_path, make_config, engine):
    config = make_config("cts", horizon=2200)
    blocks = engine(config)
    a = write_rrd(tmp_path / "a.rrd", config, blocks)
    b = write_rrd(tmp_path / "b.rrd", config, engine(config, block=1000))
    assert compare(a, b).returncode == 0
    # the MCAP log read back and sent through the same sink gives the same recording
    from corraoi.recorder.slotlog.sink import McapSink

    with McapSink(tmp_path / "a.mcap", config, fsync=False) as sink:
        for block in blocks:
            sink.write(block)
    replayed = write_rrd(tmp_path / "replay.rrd", config, open_log(tmp_path / "a.mcap").blocks())
    assert compare(a, replayed).returncode == 0
    # and the comparison can fail: another seed is another recording
    other_config = make_config("cts", horizon=2200, seed=1)
    other = write_rrd(tmp_path / "c.rrd", other_config, engine(other_config))
    assert compare(a, other).returncode != 0


def test_rrd_output_is_partial_until_closed_and_refuses_to_clobber(tmp_path, make_config, engine):
    config = make_config(horizon=1500)
    blocks = engine(config)
    path = tmp_path / "x.rrd"
    out = RrdOutput(config, rrd_path=path)
    sink = RerunSink(out.recording, config.label, config)
    sink.write(blocks[0])
    assert partial_path(path).exists() and not path.exists()
    assert sink.close() is None and sink.close() is None  # twice is safe
    with pytest.raises(ValueError):
        sink.write(blocks[1])
    assert out.close() == path and out.close() == path
    assert path.exists() and not partial_path(path).exists()
    assert len(read_rrd(path)["/" + run_path(config.label) + "/aoi"][0]) == 1000
    with pytest.raises(OutputError, match="already exists"):
        RrdOutput(config, rrd_path=path)
    with pytest.raises(OutputError, match="is a directory"):
        RrdOutput(config, rrd_path=tmp_path)
    aborted = tmp_path / "y.rrd"
    out = RrdOutput(config, rrd_path=aborted)
    RerunSink(out.recording, config.label, config).write(blocks[0])
    assert out.abort() == partial_path(aborted)
    assert not aborted.exists() and partial_path(aborted).exists()


def test_library_code_keeps_no_global_recording(make_config, engine):
    config = make_config(horizon=1000)
    rec = new_recording(config)
    rec.memory_recording()  # keep the data in memory: no file, no viewer
    RerunSink(rec, "label with spaces/and slash", config).write(engine(config)[0])
    assert rr.get_global_data_recording() is None
    assert rr.get_thread_local_data_recording() is None
    assert "label\\ with\\ spaces\\/and\\ slash" in run_path("label with spaces/and slash")


def test_the_blueprint_is_built_for_any_instance_size(make_config):
    config = make_config(instance="I2")
    blueprint = one_run_blueprint("x", config, window=50)
    assert isinstance(blueprint, rr.blueprint.Blueprint)
