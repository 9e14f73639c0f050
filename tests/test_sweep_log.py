"""The sweep log (MCAP) and the sweep Rerun recording: round trips of a real small sweep,
JSON Schema conformance, byte-reproducibility, cut-short files and one-line errors."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from collections import defaultdict
from collections.abc import Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import Writer

from corraoi._version import __version__
from corraoi.errors import LogError, SweepLogError, UsageError
from corraoi.experiments.montecarlo import checkpoint_point, run_sweep, sweep_config
from corraoi.model.instance import load_instance
from corraoi.policies import make_policies
from corraoi.recorder.style import POLICY_COLORS, lighter, policy_color
from corraoi.recorder.sweeplog.log import SweepMcapSink
from corraoi.recorder.sweeplog.read import read_sweep
from corraoi.recorder.vocab import NS_PER_SLOT, SWEEP_METADATA
from corraoi.recorder.vocab import SWEEP_END_METADATA as END_METADATA
from corraoi.recorder.vocab import SWEEP_SCHEMA_NAME as SCHEMA_NAME
from corraoi.recorder.vocab import SWEEP_TOPIC as TOPIC
from corraoi.stats import SweepPoint

POLICIES = ("ucb", "cucb", "aoi-aware-cucb", "cts")
CHECKPOINTS = (1, 2, 3, 5, 8, 13, 21, 34, 55, 89, 100, 150, 200, 250, 300)

Sweep = tuple[dict[str, Any], list[SweepPoint]]


def small_sweep(
    policies: Sequence[str] = POLICIES, *, runs: int = 6, horizon: int = 300, instance: str = "I1"
) -> Sweep:
    """(config, points) of a real sweep with checkpoints; no helper name starts with test_."""
    inst = load_instance(instance)
    specs = make_policies(policies)
    config = sweep_config(
        inst, specs, runs=runs, horizon=horizon, seed=3, checkpoints=list(CHECKPOINTS)
    )
    points: list[SweepPoint] = []
    run_sweep(
        inst,
        specs,
        runs=runs,
        horizon=horizon,
        seed=3,
        checkpoints=CHECKPOINTS,
        on_checkpoint=lambda p, snap: points.append(checkpoint_point(p, snap)),
    )
    points.sort(key=lambda p: p.t)  # log-time order, as a sweep folder's log is written
    return config, points


def write_log(path: Path, sweep: Sweep, **kwargs: Any) -> Path:
    config, points = sweep
    with SweepMcapSink(path, config, fsync=False, **kwargs) as sink:
        for p in points:
            sink.write(p)
    return path


@pytest.fixture(scope="module")
def sweep() -> Sweep:
    return small_sweep()


# ---------------------------------------------------------------------------- MCAP


def test_round_trip_exact(tmp_path: Path, sweep: Sweep):
    config, points = sweep
    assert len(points) == len(POLICIES) * len(CHECKPOINTS)
    path = write_log(tmp_path / "sweep.mcap", sweep)
    log = read_sweep(path)
    assert log.config == config
    assert log.policies == list(POLICIES)
    assert log.status == "complete" and log.complete
    assert log.messages == len(points)
    assert log.library == f"corraoi/{__version__}"
    assert (log.instance_name, log.runs, log.horizon, log.K) == ("I1", 6, 300, 4)
    by_policy: dict[str, list[SweepPoint]] = defaultdict(list)
    for p in points:
        by_policy[p.policy].append(p)
    for name, pts in by_policy.items():
        c = log.curves[name]
        assert c.t.tolist() == list(CHECKPOINTS)
        assert c.regret_mean.tolist() == [p.regret_mean for p in pts]
        assert c.regret_ci95.tolist() == [p.regret_ci95 for p in pts]
        assert c.estimator_mean.tolist() == [p.estimator_mean for p in pts]
        assert c.estimator_ci95.tolist() == [p.estimator_ci95 for p in pts]
        assert np.array_equal(c.pull_share, np.stack([p.pull_share for p in pts]))
        assert c.pull_share.shape == (len(CHECKPOINTS), 4)
        assert np.allclose(c.pull_share.sum(axis=1), 1.0)
    # the values are a real sweep's: regret at t=1 is 0 or positive and grows for UCB
    assert log.curves["ucb"].regret_mean[-1] > log.curves["ucb"].regret_mean[0]


def test_messages_follow_the_stored_schema(tmp_path: Path, sweep: Sweep):
    jsonschema = pytest.importorskip("jsonschema")
    config, points = sweep
    path = write_log(tmp_path / "sweep.mcap", sweep)
    with open(path, "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None
        (channel,) = summary.channels.values()
        schema = summary.schemas[channel.schema_id]
        assert (channel.topic, channel.message_encoding) == (TOPIC, "json")
        assert (schema.name, schema.encoding) == (SCHEMA_NAME, "jsonschema")
        validator = jsonschema.Draft202012Validator(json.loads(schema.data))
        validator.check_schema(validator.schema)
        seen = []
        for _, _, message in reader.iter_messages(log_time_order=False):
            row = json.loads(message.data)
            validator.validate(row)
            assert message.log_time == message.publish_time == row["t"] * NS_PER_SLOT
            seen.append((message.sequence, row["policy"], row["t"]))
        meta = {m.name: m.metadata for m in reader.iter_metadata()}
    assert [s[0] for s in seen] == list(range(1, len(points) + 1))
    assert [s[1:] for s in seen] == [(p.policy, p.t) for p in points]
    sweep_meta = meta[SWEEP_METADATA]
    assert all(isinstance(v, str) for v in sweep_meta.values())
    assert json.loads(sweep_meta["config"]) == config
    assert sweep_meta["instance"] == "I1" and sweep_meta["runs"] == "6"
    assert json.loads(sweep_meta["policies"]) == list(POLICIES)
    assert meta[END_METADATA]["status"] == "complete"
    assert meta[END_METADATA]["messages"] == str(len(points))
    # a bad point is refused by the schema: it can fail
    validator.validate(points[0].to_dict())
    bad = points[0].to_dict()
    bad["pull_share"] = bad["pull_share"][:3]
    with pytest.raises(jsonschema.ValidationError):
        validator.validate(bad)


def test_single_run_leaves_out_the_half_widths(tmp_path: Path):
    jsonschema = pytest.importorskip("jsonschema")
    one = small_sweep(("ts",), runs=1, horizon=50)
    path = write_log(tmp_path / "one.mcap", one)
    with open(path, "rb") as f:
        reader = make_reader(f)
        schema = next(iter(reader.get_summary().schemas.values()))  # type: ignore[union-attr]
        rows = [json.loads(m.data) for _, _, m in reader.iter_messages()]
    # version 2: an undefined half-width is an absent key (Foxglove rejects null types)
    assert rows and all("regret_ci95" not in r and "estimator_ci95" not in r for r in rows)
    for r in rows:
        jsonschema.validate(r, json.loads(schema.data))
    curve = read_sweep(path).curves["ts"]
    assert np.isnan(curve.regret_ci95).all() and np.isfinite(curve.regret_mean).all()


def test_byte_identical_for_the_same_inputs(tmp_path: Path, sweep: Sweep):
    a = write_log(tmp_path / "a" / "sweep.mcap", sweep)
    b = write_log(tmp_path / "b" / "sweep.mcap", sweep)
    assert a.read_bytes() == b.read_bytes()
    config, points = sweep
    other = (config, [*points[:-1], SweepPoint(**{**points[-1].__dict__, "regret_mean": 0.5})])
    c = write_log(tmp_path / "c" / "sweep.mcap", other)
    assert c.read_bytes() != a.read_bytes()


def test_partial_until_closed_and_flushed_while_running(tmp_path: Path, sweep: Sweep):
    config, points = sweep
    path = tmp_path / "sweep.mcap"
    part = tmp_path / "sweep.mcap.partial"
    P = len(POLICIES)
    with SweepMcapSink(path, config, flush_every=4, fsync=False) as sink:
        for p in points[: 5 * P + 3]:  # five checkpoints of every policy, then three points
            sink.write(p)
        assert not path.exists() and part.exists()
        snapshot = tmp_path / "snapshot.mcap"
        shutil.copyfile(part, snapshot)  # what a killed sweep would leave
        for p in points[5 * P + 3 :]:
            sink.write(p)
    assert path.exists() and not part.exists()
    cut = read_sweep(snapshot)
    assert cut.status == "truncated" and not cut.complete
    assert cut.policies == list(POLICIES)
    full = read_sweep(path)
    for name in POLICIES:  # five chunks of flush_every = 4 reached the disk; not the three
        assert np.array_equal(cut.curves[name].t, CHECKPOINTS[:5])
        assert np.array_equal(cut.curves[name].regret_mean, full.curves[name].regret_mean[:5])


def test_points_are_logged_in_slot_order_and_checkers_agree(tmp_path: Path, sweep: Sweep):
    """MCAP checkers want log times that never go back: the writer refuses a point of an
    earlier slot than the last one, and a whole log has its messages and its chunks in
    log-time order, which ``rerun mcap check`` reports as ok."""
    config, points = sweep
    path = write_log(tmp_path / "sweep.mcap", sweep, flush_every=4)
    with open(path, "rb") as f:
        reader = make_reader(f)
        times = [m.log_time for _, _, m in reader.iter_messages(log_time_order=False)]
        chunks = [(c.message_start_time, c.message_end_time)
                  for c in reader.get_summary().chunk_indexes]  # fmt: skip
    assert times == sorted(times) and len(times) == len(points)
    assert all(a[1] <= b[0] for a, b in zip(chunks, chunks[1:], strict=False))
    exe = Path(sys.executable).parent / "rerun"
    if exe.exists():
        out = subprocess.run([str(exe), "mcap", "check", str(path)], capture_output=True,
                             text=True, check=True).stdout  # fmt: skip
        assert "PROBLEM" not in out and re.search(r"^ok\s+1\s", out, re.M), out
    by_policy = sorted(points, key=lambda p: POLICIES.index(p.policy))  # policy by policy
    with pytest.raises(ValueError, match=r"t=1 after a point at t=300 \(points come in slot"):
        write_log(tmp_path / "other.mcap", (config, by_policy))


def test_exception_leaves_an_interrupted_partial_file(tmp_path: Path, sweep: Sweep):
    config, points = sweep
    path = tmp_path / "sweep.mcap"
    with pytest.raises(KeyboardInterrupt), SweepMcapSink(path, config, fsync=False) as sink:
        for p in points[:20]:
            sink.write(p)
        raise KeyboardInterrupt
    assert not path.exists()
    log = read_sweep(tmp_path / "sweep.mcap.partial")
    assert log.status == "interrupted" and log.messages == 20
    with pytest.raises(SweepLogError, match="sweep.mcap.partial exists: the sweep did not finish"):
        read_sweep(path)


def test_close_twice_and_bad_points(tmp_path: Path, sweep: Sweep):
    config, points = sweep
    sink = SweepMcapSink(tmp_path / "s.mcap", config, fsync=False)
    sink.write(points[0])
    with pytest.raises(ValueError, match="t must increase"):
        sink.write(points[0])
    short = SweepPoint(**{**points[1].__dict__, "pull_share": np.ones(3) / 3})
    with pytest.raises(ValueError, match="3 entries, the instance has 4 arms"):
        sink.write(short)
    sink.close()
    sink.close()
    with pytest.raises(ValueError, match="closed"):
        sink.write(points[1])
    assert read_sweep(tmp_path / "s.mcap").messages == 1


def _one_line(exc: pytest.ExceptionInfo[BaseException], path: Path) -> str:
    text = str(exc.value)
    assert "\n" not in text and str(path) in text
    assert isinstance(exc.value, LogError) and isinstance(exc.value, UsageError)
    assert exc.value.exit_code == 2  # type: ignore[attr-defined]
    return text


def test_reader_errors(tmp_path: Path, sweep: Sweep, record_mcap):
    missing = tmp_path / "none.mcap"
    with pytest.raises(SweepLogError) as exc:
        read_sweep(missing)
    assert "no such sweep log" in _one_line(exc, missing)

    write_log(tmp_path / "dir" / "sweep.mcap", sweep)
    with pytest.raises(SweepLogError) as exc:
        read_sweep(tmp_path / "dir")
    text = _one_line(exc, tmp_path / "dir")
    assert "is a directory" in text and "did you mean" in text

    text_file = tmp_path / "notes.txt"
    text_file.write_text("hello\n")
    with pytest.raises(SweepLogError) as exc:
        read_sweep(text_file)
    assert "not an MCAP file" in _one_line(exc, text_file)

    other = tmp_path / "other.mcap"
    with open(other, "wb") as f:
        w = Writer(f)
        w.start()
        sid = w.register_schema("other.Thing", "jsonschema", b"{}")
        cid = w.register_channel("/other", "json", sid)
        w.add_message(cid, log_time=1, data=b"{}", publish_time=1)
        w.finish()
    with pytest.raises(SweepLogError) as exc:
        read_sweep(other)
    assert f"no {SCHEMA_NAME} channel {TOPIC}" in _one_line(exc, other)

    slot_log, _, _ = record_mcap("cucb", horizon=50)
    with pytest.raises(SweepLogError) as exc:
        read_sweep(slot_log)
    assert "a per-slot run log, not a sweep log" in _one_line(exc, slot_log)

    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    with pytest.raises(SweepLogError) as exc:
        read_sweep(empty)
    assert "not an MCAP file" in _one_line(exc, empty)


def test_newer_format_is_refused(tmp_path: Path, sweep: Sweep, monkeypatch):
    import corraoi.recorder.sweeplog.log as sweep_log

    real = sweep_log.sweep_metadata
    monkeypatch.setattr(
        sweep_log, "sweep_metadata", lambda c, **k: {**real(c, **k), "format_version": "99"}
    )
    path = write_log(tmp_path / "new.mcap", sweep)
    monkeypatch.undo()
    with pytest.raises(SweepLogError) as exc:
        read_sweep(path)
    assert "newer corraoi" in _one_line(exc, path)


# ---------------------------------------------------------------------------- Rerun


def _rrd_contents(path: Path) -> tuple[dict[str, dict[int, float]], dict[str, dict], set[str]]:
    """(values by entity and slot, static components by entity, timelines) of an .rrd."""
    from rerun.chunk import RrdReader

    values: dict[str, dict[int, float]] = defaultdict(dict)
    static: dict[str, dict] = {}
    timelines: set[str] = set()
    for chunk in RrdReader(path).stream():
        data = chunk.to_record_batch().to_pydict()
        if chunk.is_static:
            static[chunk.entity_path] = data
            continue
        timelines.update(chunk.timeline_names)
        if "Scalars:scalars" in data:
            for t, v in zip(data["slot"], data["Scalars:scalars"], strict=True):
                values[chunk.entity_path][t] = v[0]
    return values, static, timelines


def _rgba(rgb: tuple[int, int, int]) -> int:
    r, g, b = rgb
    return (r << 24) | (g << 16) | (b << 8) | 0xFF


def test_rerun_recording_holds_the_curves(tmp_path: Path, sweep: Sweep):
    from rerun.chunk import RrdReader

    from corraoi.recorder.sweeplog.layout import sweep_recording_id
    from corraoi.recorder.sweeplog.recording import open_sweep_recording

    config, points = sweep
    path = tmp_path / "sweep.rrd"
    with open_sweep_recording(path, config, flush_every=7) as sink:
        for p in points:
            sink.write(p)
        assert not path.exists()
    assert path.exists() and not (tmp_path / "sweep.rrd.partial").exists()
    reader = RrdReader(path)
    (store,) = reader.recordings()
    assert store.recording_id == sweep_recording_id(config) and store.application_id == "corraoi"
    assert len(reader.blueprints()) == 1
    values, static, timelines = _rrd_contents(path)
    assert timelines == {"slot"}  # no log_time: reproducible
    for p in points:
        base = f"/sweep/regret/{p.policy}"
        assert values[base][p.t] == p.regret_mean
        assert values[f"{base}/lo"][p.t] == p.regret_mean - p.regret_ci95  # type: ignore[operator]
        assert values[f"{base}/hi"][p.t] == p.regret_mean + p.regret_ci95  # type: ignore[operator]
        assert values[f"/sweep/estimator/{p.policy}"][p.t] == p.estimator_mean
        for k in range(4):
            assert values[f"/sweep/pulls/{p.policy}/{k + 1}"][p.t] == p.pull_share[k]
    assert len(values["/sweep/regret/cucb"]) == len(CHECKPOINTS)
    # styling: the AoI-aware variant shares cucb's colour, is thinner and has markers
    green = _rgba(POLICY_COLORS["cucb"])
    plain, aware = static["/sweep/regret/cucb"], static["/sweep/regret/aoi-aware-cucb"]
    assert plain["SeriesLines:colors"] == aware["SeriesLines:colors"] == [[green]]
    assert aware["SeriesLines:widths"][0][0] < plain["SeriesLines:widths"][0][0]
    assert "SeriesPoints:markers" in aware and "SeriesPoints:markers" not in plain
    assert static["/sweep/regret/ucb"]["SeriesLines:colors"] == [[_rgba(policy_color("ucb"))]]
    band = static["/sweep/regret/cucb/lo"]
    assert band["SeriesLines:colors"] == [[_rgba(lighter(POLICY_COLORS["cucb"], 0.45))]]
    assert band["SeriesLines:names"] == [["cucb"]]  # one legend entry per policy
    assert static["/sweep/pulls/cts/3"]["SeriesLines:names"] == [["arm 3"]]


def test_the_rules_of_several_sources_carry_their_markers_in_the_recording(
        tmp_path: Path, sweep: Sweep):  # fmt: skip
    # the rules of one base policy share its colour (as in the sweep figure): each rule's
    # curves carry its marker, an AoI-aware form the rule's marker and the thinner line
    import dataclasses

    import rerun as rr

    from corraoi.recorder.style import MARKER_RULE, RULE_MARKERS
    from corraoi.recorder.sweeplog.recording import RULE_SHAPES, open_sweep_recording

    config, points = sweep
    names = {"ucb": "rhorand-ucb", "cucb": "mctopm-cucb",
             "aoi-aware-cucb": "chairs-aoi-aware-cucb", "cts": "centralized-cts"}  # fmt: skip
    renamed = {**config, "policies": [{**e, "name": names[e["name"]]}
                                      for e in config["policies"]]}  # fmt: skip
    path = tmp_path / "rules.rrd"
    with open_sweep_recording(path, renamed, flush_every=7) as sink:
        for pt in points:
            sink.write(dataclasses.replace(pt, policy=names[pt.policy]))
    _, static, _ = _rrd_contents(path)
    shape = rr.components.MarkerShape
    want = {"rhorand-ucb": None, "mctopm-cucb": shape.Square,
            "chairs-aoi-aware-cucb": shape.Circle, "centralized-cts": shape.Up}  # fmt: skip
    for name, marker in want.items():
        got = static[f"/sweep/regret/{name}"].get("SeriesPoints:markers")
        assert got == (None if marker is None else [[marker.value]]), (name, got)
    assert {m for m in RULE_MARKERS.values() if m} <= set(RULE_SHAPES)  # every rule has one
    mctopm = static["/sweep/regret/mctopm-cucb"]
    chairs = static["/sweep/regret/chairs-aoi-aware-cucb"]
    assert mctopm["SeriesLines:colors"] == chairs["SeriesLines:colors"]  # cucb's, both
    assert chairs["SeriesLines:widths"][0][0] < mctopm["SeriesLines:widths"][0][0]
    # large enough to tell a square from a circle: larger than the AoI-aware cross
    assert mctopm["SeriesPoints:marker_sizes"] == [[MARKER_RULE]] and MARKER_RULE > 2.5


def test_rerun_sink_on_a_caller_recording_and_single_run(tmp_path: Path):
    import rerun as rr

    from corraoi.recorder.sweeplog.layout import sweep_blueprint
    from corraoi.recorder.sweeplog.recording import SweepRerunSink

    config, points = small_sweep(("ts", "aoi-aware-ts"), runs=1, horizon=40)
    rec = rr.RecordingStream("corraoi", recording_id="test-sweep")
    path = tmp_path / "mine.rrd"
    rec.save(path, default_blueprint=sweep_blueprint(config))
    with SweepRerunSink(rec, config) as sink:
        for p in points:
            sink.write(p)
    rec.disconnect()
    values, _, timelines = _rrd_contents(path)
    assert timelines == {"slot"}
    ts = [p for p in points if p.policy == "ts"]
    assert values["/sweep/regret/ts"] == {p.t: p.regret_mean for p in ts}
    assert "/sweep/regret/ts/lo" not in values  # one run: no band


def test_rerun_recordings_compare_equal(tmp_path: Path, sweep: Sweep):
    from corraoi.recorder.sweeplog.recording import open_sweep_recording

    exe = Path(sys.executable).parent / "rerun"
    if not exe.exists():
        pytest.skip("the rerun CLI is not installed")
    config, points = sweep
    paths = [tmp_path / "a.rrd", tmp_path / "b.rrd", tmp_path / "c.rrd"]
    for i, path in enumerate(paths):
        with open_sweep_recording(path, config) as sink:
            for p in points if i < 2 else points[:-1]:
                sink.write(p)
    same = subprocess.run([str(exe), "rrd", "compare", *map(str, paths[:2])], capture_output=True)
    assert same.returncode == 0, same.stderr.decode()
    diff = subprocess.run([str(exe), "rrd", "compare", *map(str, paths[::2])], capture_output=True)
    assert diff.returncode != 0


def test_channel_metadata_carries_the_format_version(tmp_path):
    from mcap.reader import make_reader

    from corraoi.model.instance import load_instance
    from corraoi.policies import make_policies
    from corraoi.recorder.sweeplog.log import SweepMcapSink
    from corraoi.recorder.vocab import SWEEP_FORMAT_VERSION as FORMAT_VERSION

    specs = make_policies(["ucb"])
    config = sweep_config(load_instance("I1"), specs, runs=2, horizon=10, seed=0, checkpoints=[10])
    path = tmp_path / "s.mcap"
    with SweepMcapSink(path, config):
        pass
    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    (channel,) = summary.channels.values()
    assert channel.metadata == {"format_version": str(FORMAT_VERSION)}
