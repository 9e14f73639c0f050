"""What Foxglove needs from our MCAP files: JSON schemas its parser takes, no empty summary
groups, and a layout whose panels read fields that exist. Also: v1 sweep logs still read."""

from __future__ import annotations

import json
import struct
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from click.testing import CliRunner
from mcap.reader import make_reader
from mcap.writer import CompressionType, Writer

from corraoi.cli import main
from corraoi.experiments.montecarlo import sweep_config
from corraoi.model.instance import load_instance
from corraoi.policies import make_policies, paper_names
from corraoi.recorder.sweeplog.read import read_sweep
from corraoi.recorder.vocab import SWEEP_METADATA
from corraoi.recorder.vocab import SWEEP_SCHEMA_NAME as SCHEMA_NAME
from corraoi.recorder.vocab import SWEEP_TOPIC as TOPIC

from .conftest import Recorded

DOCS = Path(__file__).resolve().parent.parent / "docs"
_SCALARS = {"boolean", "string", "number", "integer"}


def foxglove_problems(schema: dict[str, Any], where: str = "") -> list[str]:
    """What Foxglove's JSON-schema parser (mcap-support parseJsonSchema) would reject.

    It needs "type": "object" with properties at every object level; each property's type
    must be one of boolean, string, number, integer, object or array, and array items one
    of boolean, string, number, integer or object. A type list (["number", "null"]) or
    "null" is rejected.
    """
    if schema.get("type") != "object" or not isinstance(schema.get("properties"), dict):
        return [f"{where or 'root'}: expected type object with properties"]
    out = []
    for name, field in schema["properties"].items():
        path = f"{where}.{name}" if where else name
        kind = field.get("type")
        if kind == "object":
            out += foxglove_problems(field, path)
        elif kind == "array":
            item = field.get("items", {}).get("type")
            if item == "object":
                out += foxglove_problems(field["items"], path + "[]")
            elif not (isinstance(item, str) and item in _SCALARS):
                out.append(f"{path}: array items of type {item!r}")
        elif not (isinstance(kind, str) and kind in _SCALARS):
            out.append(f"{path}: type {kind!r}")
    return out


def test_the_checker_rejects_type_lists():
    bad = {"type": "object", "properties": {"ci": {"type": ["number", "null"]}}}
    assert foxglove_problems(bad) == ["ci: type ['number', 'null']"]
    nulls = {"type": "object", "properties": {"a": {"type": "array", "items": {"type": "null"}}}}
    assert foxglove_problems(nulls) == ["a: array items of type 'null'"]


_FOOTER = struct.Struct("<BQQQI")  # opcode, length, summary_start, summary_offset_start, crc


def summary_groups(path: Path) -> tuple[list[tuple[int, int, int]], list[int]]:
    """(group opcode, start, length) of every summary offset, and the opcodes of the summary
    records (summary offsets excluded), read from the file's bytes."""
    data = path.read_bytes()
    assert data.endswith(b"\x89MCAP0\r\n")
    opcode, length, summary_start, offsets_start, _ = _FOOTER.unpack_from(
        data, len(data) - 8 - _FOOTER.size
    )
    assert opcode == 0x02 and summary_start and offsets_start
    groups = []
    pos = offsets_start
    while pos < len(data) - 8 - _FOOTER.size:
        op, ln = struct.unpack_from("<BQ", data, pos)
        assert op == 0x0E  # summary offset
        groups.append(struct.unpack_from("<BQQ", data, pos + 9))
        pos += 9 + ln
    records = []
    pos = summary_start
    while pos < offsets_start:
        op, ln = struct.unpack_from("<BQ", data, pos)
        records.append(op)
        pos += 9 + ln
    return groups, records


def schemas_of(path: Path) -> list[tuple[str, dict[str, Any]]]:
    with open(path, "rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    return [(s.name, json.loads(s.data)) for s in summary.schemas.values()]


@pytest.fixture
def written_files(
    tmp_path: Path, record_mcap: Callable[..., Recorded]
) -> dict[str, Path]:
    """Every kind of MCAP file corraoi writes: slot log, recovered log, sweep log."""
    slot, _, _ = record_mcap("cts", horizon=1200)
    runner = CliRunner()
    out = tmp_path / "sw"
    res = runner.invoke(main, ["sweep", "-p", "ucb", "-n", "1", "-T", "200", "-o", str(out),
                               "--checkpoints", "8"])  # fmt: skip
    assert res.exit_code == 0, res.output
    recovered = tmp_path / "rec.mcap"
    res = runner.invoke(main, ["recover", str(slot), "-o", str(recovered)])
    assert res.exit_code == 0, res.output
    return {"slot log": slot, "sweep log": out / "sweep.mcap", "recovered": recovered}


def test_every_written_schema_parses_in_foxglove(written_files: dict[str, Path]):
    seen = set()
    for kind, path in written_files.items():
        for name, schema in schemas_of(path):
            seen.add(name)
            assert foxglove_problems(schema) == [], (kind, name)
            assert "null" not in json.dumps(schema), (kind, name)
    assert seen == {"corraoi.SlotEvent", SCHEMA_NAME}


def test_no_empty_summary_group_in_any_written_file(written_files: dict[str, Path]):
    for kind, path in written_files.items():
        groups, records = summary_groups(path)
        assert groups, kind
        for opcode, _start, length in groups:
            assert length > 0, f"{kind}: empty summary group of opcode {opcode:#x}"
            assert opcode in records, kind
        # every record of the summary belongs to a group the offsets announce
        assert sorted({g[0] for g in groups}) == sorted(set(records)), kind
        assert 0x0A not in {g[0] for g in groups}  # no attachment index group


def test_a_single_run_sweep_leaves_the_half_widths_out(written_files: dict[str, Path]):
    with open(written_files["sweep log"], "rb") as f:
        rows = [json.loads(m.data) for _, _, m in make_reader(f).iter_messages()]
    assert rows and all("regret_ci95" not in r and "estimator_ci95" not in r for r in rows)
    log = read_sweep(written_files["sweep log"])
    assert log.metadata["format_version"] == "2"
    assert np.isnan(log.curves["ucb"].regret_ci95).all()


def write_v1_sweep_log(path: Path) -> dict[str, Any]:
    """A sweep log as version 1 wrote it: null half-widths, a type list in its schema."""
    config = sweep_config(load_instance("I1"), make_policies(["ucb"]), runs=1, horizon=10,
                          seed=0, checkpoints=[5, 10])  # fmt: skip
    schema = {"type": "object", "properties": {
        "policy": {"type": "string"}, "t": {"type": "integer"},
        "regret_mean": {"type": "number"}, "regret_ci95": {"type": ["number", "null"]},
        "estimator_mean": {"type": "number"}, "estimator_ci95": {"type": ["number", "null"]},
        "pull_share": {"type": "array", "items": {"type": "number"}}}}  # fmt: skip
    with open(path, "wb") as f:
        w = Writer(f, compression=CompressionType.ZSTD)
        w.start(profile="", library="corraoi/0.1.0")
        w.add_metadata(SWEEP_METADATA, {"format": "corraoi.sweep-log", "format_version": "1",
                                        "config": json.dumps(config, sort_keys=True)})  # fmt: skip
        sid = w.register_schema(name=SCHEMA_NAME, encoding="jsonschema",
                                data=json.dumps(schema).encode())  # fmt: skip
        cid = w.register_channel(topic=TOPIC, message_encoding="json", schema_id=sid)
        for i, (t, m) in enumerate(((5, 1.0), (10, 3.0)), start=1):
            msg = {"policy": "ucb", "t": t, "regret_mean": m, "regret_ci95": None,
                   "estimator_mean": m / 2, "estimator_ci95": None,
                   "pull_share": [0.25, 0.25, 0.25, 0.25]}  # fmt: skip
            w.add_message(cid, t * 10**9, json.dumps(msg).encode(), t * 10**9, i)
        w.add_metadata("corraoi.sweep.end", {"status": "complete", "messages": "2"})
        w.finish()
    return config


def test_version_1_sweep_logs_still_read(tmp_path: Path):
    path = tmp_path / "v1.mcap"
    config = write_v1_sweep_log(path)
    log = read_sweep(path)
    assert log.status == "complete" and log.config == config and log.policies == ["ucb"]
    curve = log.curves["ucb"]
    assert curve.t.tolist() == [5, 10] and curve.regret_mean.tolist() == [1.0, 3.0]
    assert np.isnan(curve.regret_ci95).all() and np.isnan(curve.estimator_ci95).all()
    assert curve.estimator_mean.tolist() == [0.5, 1.5]


def _panel_ids(node: Any) -> list[str]:
    if isinstance(node, str):
        return [node]
    return _panel_ids(node["first"]) + _panel_ids(node["second"])


def test_the_shipped_layout_reads_fields_that_exist(written_files: dict[str, Path]):
    layout = json.loads((DOCS / "foxglove-layout.json").read_text())
    config = layout["configById"]
    ids = _panel_ids(layout["layout"])
    for pid in list(ids):
        if pid.startswith("Tab!"):
            for tab in config[pid]["tabs"]:
                ids += _panel_ids(tab["layout"])
    assert sorted(ids) == sorted(config), "every panel in the layout has a config and back"
    from corraoi.engine.block import RunConfig
    from corraoi.recorder.slotlog.encode import schema_bytes

    several = RunConfig(load_instance("I1"), make_policies(["rhorand-ucb"])[0], 0, 10, sources=2)
    fields = {
        "/corraoi/slot": dict(schemas_of(written_files["slot log"]))["corraoi.SlotEvent"],
        "/corraoi/sweep": dict(schemas_of(written_files["sweep log"]))[SCHEMA_NAME],
        # a run of several sources: source m's topic /corraoi/slot/m (the sources tab)
        "/corraoi/slot/m": json.loads(schema_bytes(several)),
    }
    used: dict[str, set[str]] = {topic: set() for topic in fields}
    policies = set()
    kinds = set()
    for pid, panel in config.items():
        kinds.add(pid.split("!")[0])
        for p in panel.get("paths", []):
            topic, _, rest = p["value"].partition("{") if "{" in p["value"] else (
                p["value"].split(".")[0], "", p["value"])  # fmt: skip
            if "{" in p["value"]:
                filt, _, field = rest.partition("}.")
                assert filt.startswith('policy=="') and filt.endswith('"'), p["value"]
                policies.add(filt[len('policy=="') : -1])
            else:
                field = rest.split(".", 1)[1]
            if topic.startswith("/corraoi/slot/"):
                assert topic.removeprefix("/corraoi/slot/") in ("1", "2", "3", "4"), topic
                topic = "/corraoi/slot/m"
            if field.endswith("[:]"):  # every arm's value: a plot against the array index
                field = field[:-3]
                assert panel["xAxisVal"] == "index", pid
                assert fields[topic]["properties"][field]["type"] == "array", p["value"]
            assert "[" not in field, p["value"]  # nothing made for one K (mu_hat[3])
            assert field in fields[topic]["properties"], p["value"]
            used[topic].add(field)
    assert {"aoi", "oracle_aoi", "regret", "arm", "success", "mu_hat", "pulls"} <= \
        used["/corraoi/slot"]  # fmt: skip
    assert "regret_mean" in used["/corraoi/sweep"]
    assert {"aoi", "regret", "arm", "collided"} <= used["/corraoi/slot/m"]
    assert policies == set(paper_names())
    assert {"Plot", "StateTransitions", "Tab"} <= kinds
    arm_panel = next(v for k, v in config.items() if k.startswith("StateTransitions!"))
    assert [p["value"] for p in arm_panel["paths"]][:2] == [
        "/corraoi/slot.arm", "/corraoi/slot.success"
    ]
