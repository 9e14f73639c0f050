"""corraoi.recorder.style is the one place for colours and names: every view draws a policy alike.

The same policy gets the same colour in a ``record`` recording, a ``compare`` recording,
the sweep recording and the sweep figure; a policy's own colour (``spec.color``) wins; the
oracle never shares a policy's colour or line style.
"""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from rerun.chunk import RrdReader

from corraoi.model.theory import analyse
from corraoi.recorder import style
from corraoi.recorder.rerun.names import run_path
from corraoi.recorder.rerun.output import RrdOutput
from corraoi.recorder.rerun.sink import RerunSink
from corraoi.recorder.sweeplog.layout import regret_path
from corraoi.recorder.sweeplog.recording import SweepRerunSink
from corraoi.viewer.compare import compare

from .rrd_util import read_rrd
from .test_sweep_log import small_sweep


def rgba(rgb: tuple[int, int, int]) -> int:
    r, g, b = rgb
    return (r << 24) | (g << 16) | (b << 8) | 0xFF


def static_styles(path: Path) -> dict[str, dict]:
    out = {}
    for chunk in RrdReader(str(path)).stream():
        if chunk.is_static:
            out[chunk.entity_path] = chunk.to_record_batch().to_pydict()
    return out


def line_color(styles: dict[str, dict], entity: str) -> int:
    return styles[entity]["SeriesLines:colors"][0][0]


def test_policy_colours_names_and_explicit_colours():
    assert style.policy_color("aoi-aware-cts") == style.policy_color("cts") == (214, 39, 40)
    assert style.policy_color("cts", (1, 2, 3)) == (1, 2, 3)  # a policy's own colour wins
    assert style.policy_color("my-plugin") == style.policy_color("my-plugin")  # stable
    assert style.spec_color(SimpleNamespace(name="ucb", color=[9, 8, 7])) == (9, 8, 7)
    assert style.spec_color(SimpleNamespace(name="ucb")) == style.POLICY_COLORS["ucb"]
    assert style.spec_label(SimpleNamespace(name="ucb", label="UCB (c=2)")) == "UCB (c=2)"
    assert style.spec_label(SimpleNamespace(name="ucb", label="")) == "ucb"
    assert style.arm_label(0, "1") == "arm 1" and style.arm_label(2, "good") == "arm 3 (good)"
    assert style.arm_legend(0, "1") == "arm 1" and style.arm_legend(2, "good") == "3 good"
    used = set(style.POLICY_COLORS.values()) | set(style.ARM_COLORS)
    assert style.ORACLE_COLOR not in used
    # the oracle is far from every policy hue, not a shade of one
    for rgb in style.POLICY_COLORS.values():
        assert np.abs(np.subtract(rgb, style.ORACLE_COLOR)).max() >= 100
    a, b, c = style.run_colors([(10, 20, 30), (10, 20, 30), (200, 0, 0)])
    assert a == (10, 20, 30) and b == style.lighter((10, 20, 30), 0.25) and c == (200, 0, 0)


def _record_rrd(path: Path, config, blocks, **kwargs) -> Path:
    with RrdOutput(config, rrd_path=path) as out:
        sink = RerunSink(out.recording, config.label, config, **kwargs)
        for b in blocks:
            sink.write(b)
        sink.close()
    return path


@pytest.mark.parametrize("policy", ["cts", "aoi-aware-ucb"])
def test_one_policy_one_colour_in_record_compare_sweep_and_figure(
    tmp_path, make_config, engine, record_mcap, policy
):
    want = style.policy_color(policy)
    # record / replay
    config = make_config(policy, horizon=600)
    styles = static_styles(_record_rrd(tmp_path / "r.rrd", config, engine(config)))
    base = "/" + run_path(config.label)
    assert line_color(styles, f"{base}/aoi") == line_color(styles, f"{base}/regret") == rgba(want)
    oracle = styles[f"{base}/oracle_aoi"]
    assert oracle["SeriesPoints:colors"][0][0] == rgba(style.ORACLE_COLOR) != rgba(want)
    # compare: the first run of the policy in its colour, a second one (another seed) in a
    # lighter shade, both sent through the same sink as record
    a, _, _ = record_mcap(policy, seed=1, horizon=600, name="a.mcap")
    b, _, _ = record_mcap(policy, seed=2, horizon=600, name="b.mcap")
    result = compare([a, b], rrd_path=tmp_path / "c.rrd")
    styles = static_styles(tmp_path / "c.rrd")
    first, second = (f"/{run_path(r.label)}" for r in result.runs)
    assert line_color(styles, f"{first}/aoi") == rgba(want)
    assert line_color(styles, f"{second}/aoi") == rgba(style.lighter(want, 0.25))
    assert line_color(styles, f"{second}/regret") == rgba(style.lighter(want, 0.25))
    # sweep recording
    config_s, points = small_sweep((policy, "ucb"), runs=2, horizon=300)
    with SweepRerunSink.to_file(tmp_path / "s.rrd", config_s) as sink:
        for p in points:
            sink.write(p)
    styles = static_styles(tmp_path / "s.rrd")
    assert line_color(styles, "/" + regret_path(policy)) == rgba(want)
    # figure
    pytest.importorskip("matplotlib")
    from matplotlib.image import imread

    from corraoi.recorder.sweeplog.log import SweepMcapSink
    from corraoi.recorder.sweeplog.read import read_sweep
    from corraoi.viewer.figure import draw_figure

    with SweepMcapSink(tmp_path / "s.mcap", config_s, fsync=False) as log:
        for p in points:
            log.write(p)
    png = draw_figure(read_sweep(tmp_path / "s.mcap"), tmp_path / "f.png", policies=[policy])
    img = np.round(imread(png)[..., :3] * 255).astype(int)
    assert ((np.abs(img - np.array(want)).max(axis=-1) <= 2).sum()) > 100


def test_a_policy_with_its_own_colour_is_drawn_in_it(tmp_path, make_config, engine):
    config = make_config("ucb", horizon=300)
    # the plug-in API gives PolicySpec a ``color``; until then set it on this instance
    object.__setattr__(config.policy, "color", (12, 34, 56))
    styles = static_styles(_record_rrd(tmp_path / "own.rrd", config, engine(config)))
    assert line_color(styles, f"/{run_path(config.label)}/aoi") == rgba((12, 34, 56))


def test_true_means_are_constant_reference_lines(tmp_path, make_config, engine):
    config = make_config("cucb", horizon=2500)
    path = _record_rrd(tmp_path / "m.rrd", config, engine(config, block=700), batch=1000)
    slots, values = read_rrd(path)[f"/{run_path(config.label)}/mu_true"]
    mu = analyse(config.instance).mu
    assert np.allclose(np.array(values), np.tile(mu, (len(values), 1)))
    assert slots[0] == 1 and slots[-1] == 2500 and len(slots) < 2500 / 100


def test_a_sweep_policy_with_its_own_colour_keeps_it_in_the_recording_and_figure(tmp_path):
    pytest.importorskip("matplotlib")
    from matplotlib.image import imread

    from corraoi.recorder.sweeplog.log import SweepMcapSink
    from corraoi.recorder.sweeplog.read import read_sweep
    from corraoi.viewer.figure import draw_figure

    config, points = small_sweep(("cucb", "ucb"), runs=2, horizon=300)
    assert [p["name"] for p in config["policies"]] == ["cucb", "ucb"]
    config["policies"][0]["color"] = [150, 30, 200]  # as the plug-in API writes it
    assert style.config_colors(config) == {"cucb": (150, 30, 200), "ucb": (31, 119, 180)}
    with SweepRerunSink.to_file(tmp_path / "s.rrd", config) as sink:
        for p in points:
            sink.write(p)
    styles = static_styles(tmp_path / "s.rrd")
    assert line_color(styles, "/" + regret_path("cucb")) == rgba((150, 30, 200))
    with SweepMcapSink(tmp_path / "s.mcap", config, fsync=False) as log:
        for p in points:
            log.write(p)
    png = draw_figure(read_sweep(tmp_path / "s.mcap"), tmp_path / "f.png")
    img = np.round(imread(png)[..., :3] * 255).astype(int)
    assert ((np.abs(img - np.array((150, 30, 200))).max(axis=-1) <= 2).sum()) > 100
    green = style.POLICY_COLORS["cucb"]
    assert ((np.abs(img - np.array(green)).max(axis=-1) <= 2).sum()) == 0
