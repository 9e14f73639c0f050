"""Hidden-state processes: the trace channel replays a recorded path; bad traces get one line.

(Markov channels: tests/test_markov.py.)
"""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

from corraoi.cli import main
from corraoi.engine.simulation import simulate
from corraoi.errors import ConfigError
from corraoi.face.resolve import channel as resolve_channel
from corraoi.model.channels import Channel, parse_channel, trace_channel
from corraoi.model.instance import load_instance
from corraoi.policies import make_policy
from corraoi.recorder.slotlog.reader import open_log

I1 = load_instance("I1")


def run(*args: object):  # type: ignore[no-untyped-def]
    return CliRunner().invoke(main, [str(a) for a in args])


def test_a_trace_channel_reproduces_a_recorded_hidden_path(tmp_path: Path):
    src = tmp_path / "ucb.mcap"
    assert run("record", "-p", "ucb", "-T", "2500", "-s", "9", "--no-rrd", "-o", src).exit_code == 0
    out = tmp_path / "cts.mcap"
    res = run("record", "-p", "cts", "-T", "2500", "-s", "1", "--no-rrd", "-o", out,
              "--channel", f"trace:{src}")  # fmt: skip
    assert res.exit_code == 0, res.output
    a, b = open_log(src), open_log(out)
    assert np.array_equal(a.read_all().x, b.read_all().x)  # the seed-9 path, replayed on seed 1
    assert b.format_version == 2
    assert b.config.channel is not None and b.config.channel.kind == "trace"
    assert json.loads(b.metadata["config"])["channel"]["length"] == 2500
    # every run of a batch replays the same path
    chan = resolve_channel(f"trace:{src}", I1)
    blk = next(simulate(I1, make_policy("ts"), [0, 1, 2], 2500, block=2500, channel=chan))
    assert all(np.array_equal(blk.x[i], a.read_all().x) for i in range(3))


def test_the_core_reads_text_traces_and_the_readers_it_is_handed(tmp_path: Path):
    """The core names no reader of the layers above: a slot log's states are read by the
    reader the top floor hands it (``readers``); without one, one line says what is read."""
    src = tmp_path / "ucb.mcap"
    assert run("record", "-p", "ucb", "-T", "300", "--no-rrd", "-o", src).exit_code == 0
    with pytest.raises(ConfigError, match="not a text file of 1-based states"):
        parse_channel(f"trace:{src}", I1)
    seen = []

    def reader(path: Path, instance: object, where: str) -> np.ndarray:
        seen.append((path, where))
        return np.array([3, 2, 1, 0])

    chan = parse_channel(f"trace:{src}", I1, readers={".mcap": reader})
    assert chan.trace.tolist() == [3, 2, 1, 0] and seen == [(src, f"channel trace:{src}")]


def test_a_text_trace(tmp_path: Path):
    trace = tmp_path / "states.txt"
    trace.write_text("# a hand-written path\n1 2 3 4\n4 3 2 1  # comment\n")
    chan = parse_channel(f"trace:{trace}", I1)
    blk = next(simulate(I1, make_policy("ucb"), [0], 8, block=8, channel=chan))
    assert blk.x[0].tolist() == [0, 1, 2, 3, 3, 2, 1, 0]


def test_a_trace_channel_from_an_array_of_states():
    chan = trace_channel(np.array([0, 3, 1, 2]), "by hand", I1)
    assert chan.kind == "trace" and chan.source == "by hand" and chan.trace.dtype == np.int64
    assert chan == trace_channel([0, 3, 1, 2], "by hand", I1)  # same path, same digest
    blk = next(simulate(I1, make_policy("ucb"), [0, 1], 4, block=4, channel=chan))
    assert blk.x[1].tolist() == [0, 3, 1, 2]
    for bad, needle in [([], "holds no state"), ([[0, 1]], "1-D array of integer states"),
                        ([0.5, 1.0], "1-D array of integer states"),
                        ([0, 4], "state 5, but instance I1 has states 1..4")]:  # fmt: skip
        with pytest.raises(ConfigError, match=needle):
            trace_channel(np.asarray(bad), "by hand", I1)


@pytest.mark.parametrize(
    ("content", "horizon", "needle"),
    [
        ("1 2 3", 5, "3 slots, shorter than the horizon 5"),
        ("1 2 9", 3, "slot 3 has state 9, but instance I1 has states 1..4"),
        ("1 x 2", 3, ":1: state 'x' is not an integer"),
        ("# nothing\n", 3, "the trace holds no state"),
    ],
)
def test_bad_traces_get_one_line(tmp_path: Path, content: str, horizon: int, needle: str):
    trace = tmp_path / "t.txt"
    trace.write_text(content)
    res = run("record", "-p", "ucb", "-T", horizon, "--no-rrd", "-o", tmp_path / "x.mcap",
              "--channel", f"trace:{trace}")  # fmt: skip
    assert res.exit_code == 2, res.output
    assert needle in res.output and "Traceback" not in res.output
    assert len(res.output.strip().splitlines()) == 1
    assert not list(tmp_path.glob("x.mcap*"))


def test_channel_option_errors(tmp_path: Path):
    for spec, needle in (
        ("wobbly", "expected iid, markov or trace:PATH"),
        (f"trace:{tmp_path / 'none.txt'}", "no such file"),
        (f"trace:{tmp_path}", "not a regular file"),
        ("markov", "instance I1 has no transition matrix"),
    ):
        with pytest.raises(ConfigError, match=needle):
            parse_channel(spec, I1)


def test_iid_channel_is_the_default_and_round_trips():
    assert parse_channel(None, I1) == Channel("iid")
    assert Channel.from_dict(Channel("iid").to_dict()) == Channel("iid")
