"""Views that read at a glance at any K (issue 35): which views each K gets, where legends
stand, the instance's names and one colour per arm, names that are bad input, K = 1024,
the bars and lines drawn for many arms, compare's shared scales and the sweep recording.

The recordings' data are read back (``rerun.chunk.RrdReader``) and checked value for value;
the blueprints are walked as the Python objects ``rerun.blueprint`` builds. What a person
sees is checked in a browser by tests/test_e2e_web.py.
"""

from __future__ import annotations

import dataclasses
import json
import re
import subprocess
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from .scripts import load_script

rr = pytest.importorskip("rerun")
from rerun.chunk import RrdReader  # noqa: E402

from corraoi.engine.block import RunConfig, SlotBlock  # noqa: E402
from corraoi.engine.simulation import simulate_run  # noqa: E402
from corraoi.model.instance import Instance, load_instance  # noqa: E402
from corraoi.model.theory import analyse  # noqa: E402
from corraoi.policies import make_policy  # noqa: E402
from corraoi.recorder import style  # noqa: E402
from corraoi.recorder.rerun.layout import one_run_blueprint, title_chars  # noqa: E402
from corraoi.recorder.rerun.names import ENTITIES, PRESENTATION, WHY, run_path, snapshot_every  # noqa: E402
from corraoi.recorder.rerun.output import RrdOutput  # noqa: E402
from corraoi.recorder.rerun.sink import RerunSink  # noqa: E402

from .rrd_util import RERUN, read_rrd, strict_rerun  # noqa: E402, F401

NAMED_6 = {
    "name": "mmWave-6",
    "p": [0.25, 0.07, 0.22, 0.2, 0.26],
    "Y": [[0, 1, 0, 1, 1], [0, 1, 0, 0, 0], [1, 1, 0, 1, 0], [1, 1, 0, 0, 0], [1, 0, 1, 0, 0],
          [1, 1, 0, 0, 0]],
    "arms": ["LoS 28GHz", "NLoS A", "NLoS B", "relay UAV", "sub-6", "IRS panel"],
    "states": ["clear", "blocked", "rain", "crowd", "fog"],
}  # fmt: skip


def random_instance(K: int, n: int = 12, seed: int = 0, **extra: Any) -> Instance:
    rng = np.random.default_rng(seed)
    Y = (rng.uniform(size=(K, n)) < rng.uniform(0.1, 0.5, size=(K, 1))).astype(int)
    Y[np.arange(K), rng.integers(n, size=K)] = 1  # every arm succeeds somewhere
    data = {"name": f"R{K}", "p": list(rng.dirichlet(np.ones(n))), "Y": Y.tolist(), **extra}
    return Instance.from_dict(data)


def instance_of(K: int) -> Instance:
    if K == 2:
        return load_instance("GE")
    if K == 4:
        return load_instance("I1")
    if K == 6:
        return Instance.from_dict(NAMED_6)
    return random_instance(K, seed=K)


def run(tmp_path: Path, inst: Instance, policy: str = "cucb", horizon: int = 1500,
        seed: int = 1) -> tuple[Path, RunConfig, SlotBlock, RerunSink]:  # fmt: skip
    config = RunConfig(inst, make_policy(policy), seed, horizon)
    blocks = list(simulate_run(inst, config.policy, seed, horizon))
    path = tmp_path / f"{inst.K}.rrd"
    with RrdOutput(config, rrd_path=path) as out:
        sink = RerunSink(out.recording, config.label, config)
        for b in blocks:
            sink.write(b)
        sink.close()
    return path, config, SlotBlock.concat(blocks), sink


def views(blueprint: Any) -> list[Any]:
    """Every view of a blueprint, depth first."""
    out, todo = [], [blueprint.root_container]
    while todo:
        item = todo.pop(0)
        if hasattr(item, "class_identifier"):
            out.append(item)
        else:
            todo[:0] = list(item.contents)
    return out


def legend(view: Any) -> tuple[bool, int | None]:
    """(shown, corner) of a view's legend."""
    pl = view.properties.get("PlotLegend")
    visible = pl.visible.as_arrow_array().to_pylist()[0] if pl.visible is not None else True
    corner = pl.corner.as_arrow_array().to_pylist()[0] if pl.corner is not None else None
    return bool(visible), corner


def time_end(view: Any) -> int:
    return view.properties["TimeAxis"].view_range.as_arrow_array().to_pylist()[0]["end"]


def y_range(view: Any) -> list[float] | None:
    axis = view.properties.get("ScalarAxis")
    return None if axis is None else axis.range.as_arrow_array().to_pylist()[0]


def statics(path: Path) -> dict[str, dict[str, Any]]:
    out: dict[str, dict[str, Any]] = {}
    for chunk in RrdReader(path).stream():
        if chunk.is_static:
            out.setdefault(chunk.entity_path, {}).update(chunk.to_record_batch().to_pydict())
    return out


def color_of(entry: dict[str, Any]) -> int:
    for key in ("SeriesLines:colors", "SeriesPoints:colors", "BarChart:color"):
        if key in entry:
            return entry[key][0][0]
    raise KeyError(entry)


def rgba(rgb: tuple[int, int, int]) -> int:
    return (rgb[0] << 24) | (rgb[1] << 16) | (rgb[2] << 8) | 0xFF


def bars(path: Path) -> dict[str, tuple[list[int], list[list[float]]]]:
    """entity -> (slots, bar values) of every time-indexed bar chart."""
    out: dict[str, tuple[list[int], list[list[float]]]] = {}
    for chunk in RrdReader(path).stream():
        b = chunk.to_record_batch()
        if chunk.is_static or "BarChart:values" not in b.schema.names:
            continue
        slots, values = out.setdefault(chunk.entity_path, ([], []))
        slots.extend(b.column("slot").to_pylist())
        for cell in b.column("BarChart:values").to_pylist():
            (tensor,) = cell
            values.append(list(tensor["buffer"]))
    return out


# ------------------------------------------------------------------ views chosen by K


@pytest.mark.parametrize("K", [2, 4, 6, 16, 64, 256])
def test_views_are_chosen_by_K_and_legends_stand_right_of_the_data(K):
    inst = instance_of(K)
    config = RunConfig(inst, make_policy("cucb"), 0, 5000, score=True)  # the why view too
    all_views = views(one_run_blueprint(config.label, config))
    kinds = [v.class_identifier for v in all_views]
    contents = {c for v in all_views for c in v.contents}
    # why this arm: the scores (the run is one that logs them), forced slots, lines
    assert {"$origin/why/chosen", "$origin/why/forced"} <= contents
    if K <= style.LINES_UP_TO:  # a line per arm, its true mean dotted in its colour
        assert "BarChart" not in kinds
        assert {"$origin/mu_hat", "$origin/true_means/**", "$origin/pulls",
                "$origin/why/score"} <= contents  # fmt: skip
    else:  # bars at the cursor, strips, the arms that matter as lines
        assert kinds.count("BarChart") == 3  # means, pulls, scores
        assert {"$origin/why/bars/**", "$origin/why/focus/**"} <= contents
        assert {"$origin/bars/mean", "$origin/bars/mean_true", "$origin/bars/mean_arm/**",
                "$origin/bars/pulls", "$origin/bars/pulls_arm/**",
                "$origin/focus/**"} <= contents  # fmt: skip
        assert "$origin/mu_hat" not in contents and "$origin/pulls" not in contents
    assert kinds.count("TextDocument") == 1  # the run card
    for v in all_views:
        title = str(v.name.as_arrow_array().to_pylist()[0] if hasattr(v.name, "as_arrow_array")
                    else v.name)  # fmt: skip
        assert not title.endswith("\u2026"), title  # every title fits its panel at 1600 px
        if v.class_identifier != "TimeSeries":
            continue
        shown, corner = legend(v)
        if shown:  # in the room right of the data: past the cursor or the horizon
            assert corner == 2  # RightTop
            end = time_end(v)
            assert end > 5000 * 1.1 or 0 < end < 1000, (title, end)
        if "arm played" in title or "candidate" in title:
            assert y_range(v) == [0.5, K + 0.5]


def test_titles_fit_and_legend_room_grows_with_the_names():
    from corraoi.recorder.rerun.layout import first_fit, legend_room, names_in_title

    assert first_fit(400, "a" * 200, "short") == "short"
    assert len(first_fit(200, "b" * 200)) == title_chars(200)
    assert legend_room(["arm 1"], 500) < legend_room(["18 characters long"], 500)
    assert legend_room([], 500) == 0
    assert names_in_title("arm played", ["1 los", "2 nlos"], 900, "x") == \
        "arm played: 1 los · 2 nlos"  # fmt: skip
    assert names_in_title("arm played", ["1 " + "y" * 40] * 20, 300, "fallback") == "fallback"


@pytest.mark.parametrize("K", [2, 4, 6, 16, 64])
def test_one_colour_per_arm_and_the_instances_names(tmp_path, K):
    inst = instance_of(K)
    path, config, ref, sink = run(tmp_path, inst)
    st = statics(path)
    base = "/" + run_path(config.label)
    legends = [style.arm_legend(k, n) for k, n in enumerate(inst.arm_names)]
    if K <= style.LINES_UP_TO:
        line = st[f"{base}/mu_hat"]
        assert line["SeriesLines:names"] == [legends]
        colours = line["SeriesLines:colors"][0]
        assert len(set(colours)) == K  # one colour per arm
        for k in range(K):  # the true mean dotted in the arm's colour, under the arm's name
            dots = st[f"{base}/true_means/{k + 1}"]
            assert dots["SeriesPoints:colors"] == [[colours[k]]]
            assert dots["SeriesPoints:names"] == [[legends[k]]]
            assert color_of(st[f"{base}/candidates/{k + 1}"]) == colours[k]
    else:
        th = analyse(inst)
        shown = list(sink.focus)
        assert shown[: len(style.arms_that_matter(th.mu, th.best_arm, th.competitive))] == \
            style.arms_that_matter(th.mu, th.best_arm, th.competitive)  # fmt: skip
        assert len(shown) <= style.FOCUS_MAX
        colours = [color_of(st[f"{base}/focus/{k + 1}"]) for k in shown]
        assert len(set(colours)) == len(shown)  # each arm that matters its own colour
        for k, c in zip(shown, colours, strict=True):  # the same in every view of it
            for part in ("true_means", "bars/mean_arm", "bars/pulls_arm", "candidates"):
                assert color_of(st[f"{base}/{part}/{k + 1}"]) == c, part
            assert st[f"{base}/focus/{k + 1}"]["SeriesLines:names"] == [[legends[k]]]
        grey = rgba(style.BAR_IN_SET_COLOR)
        others = [k for k in range(K) if k not in shown]
        assert all(color_of(st[f"{base}/candidates/{k + 1}"]) == grey for k in others)
    card = st[f"{base}/about"]["TextDocument:text"][0][0]
    for k, name in enumerate(inst.arm_names):
        if name != str(k + 1) and (K <= style.LINES_UP_TO or k in sink.focus):
            assert name in card


def test_a_named_instance_names_its_arms_and_states_in_the_views(tmp_path):
    inst = Instance.from_dict(NAMED_6)
    config = RunConfig(inst, make_policy("cts"), 0, 3000)
    titles = [str(v.name) for v in views(one_run_blueprint(config.label, config))]
    played = next(t for t in titles if t.startswith("arm played"))
    assert played == "arm played: " + " · ".join(
        f"{k + 1} {n}" for k, n in enumerate(NAMED_6["arms"])
    )
    assert any(t.startswith("hidden state x") for t in titles)


# ------------------------------------------------------------------ bad input


BAD_ARMS = ["a" * 40, "x/y [1] z", "Ünïcødé → 電波", "x/y [1] z", "  spaced  out  ",
            "b" * 39 + "é"]  # fmt: skip


def test_bad_names_are_escaped_in_paths_shortened_in_legends_whole_in_the_card(tmp_path):
    data = {**NAMED_6, "name": "bad/name [x] ü", "arms": BAD_ARMS,
            "states": ["s/1", "s [2]", "ß", "s 4", "s5"]}  # fmt: skip
    inst = Instance.from_dict(data)
    path, config, ref, _ = run(tmp_path, inst, horizon=800)
    assert "/" in config.label
    base = "/" + run_path(config.label)
    assert base == "/runs/" + rr.escape_entity_path_part(config.label)  # one part, escaped
    assert "\\/" in base and "\\[" in base
    entities = {c.entity_path for c in RrdReader(path).stream()}
    assert f"{base}/aoi" in entities
    assert all(e.startswith(base) or e.startswith("/__") for e in entities)
    assert np.array_equal([v[0] for v in read_rrd(path)[f"{base}/aoi"][1]], ref.aoi)
    st = statics(path)
    names = st[f"{base}/mu_hat"]["SeriesLines:names"][0]
    assert len(set(names)) == 6  # duplicates told apart by their numbers
    assert all(len(n) <= style.LEGEND_CHARS for n in names)
    assert names[0] == "1 " + "a" * 15 + "\u2026" and names[4] == "5 spaced out"
    card = st[f"{base}/about"]["TextDocument:text"][0][0]
    unescaped = re.sub(r"\\(.)", r"\1", card)
    for name in BAD_ARMS:
        assert " ".join(name.split()) in unescaped  # whole (white space made one space)
    assert "x/y \\[1\\] z" in card  # markdown's brackets escaped, not taken as a link


def test_1024_arms_record_and_draw(tmp_path):
    inst = random_instance(1024, n=16, seed=3)
    path, config, ref, sink = run(tmp_path, inst, horizon=1200)
    verify = subprocess.run([RERUN, "rrd", "verify", str(path)], capture_output=True, text=True)
    assert verify.returncode == 0, verify.stderr
    assert len(sink.focus) <= style.FOCUS_MAX
    base = "/" + run_path(config.label)
    got = bars(path)
    slots, values = got[f"{base}/bars/pulls"]
    assert slots[-1] == 1200 and len(values[-1]) == 1024
    shown = np.isin(np.arange(1024), list(sink.focus))
    assert np.array_equal(np.array(values[-1])[~shown], ref.pulls[-1][~shown])
    assert not config.scored  # beyond 64 arms the score is off by default: no why-this-arm views
    assert len(views(one_run_blueprint(config.label, config))) == 9


# ------------------------------------------------------------------ what is drawn


def test_bars_hold_the_values_of_their_slots_and_lines_the_arms_that_matter(tmp_path):
    inst = random_instance(16, seed=16)
    path, config, ref, sink = run(tmp_path, inst, horizon=2500)
    base = "/" + run_path(config.label)
    every = snapshot_every(2500)
    want = [t for t in range(1, 2501) if t == 1 or t % every == 0 or t == 2500]
    got = bars(path)
    slots, mean = got[f"{base}/bars/mean"]
    assert slots == want
    _, other = got[f"{base}/bars/mean_other"]
    _, pulls = got[f"{base}/bars/pulls"]
    rows = np.array(want) - 1
    together = np.array(mean) + np.array(other)
    focus_pulls = np.zeros_like(ref.pulls[rows], dtype=float)
    for k, first in sink.focus.items():
        s, v = got[f"{base}/bars/mean_arm/{k + 1}"]
        assert s == [t for t in want if t >= first]
        together[np.array(want) >= first, k] += np.array(v)[:, 0]
        s, v = got[f"{base}/bars/pulls_arm/{k + 1}"]
        focus_pulls[np.array(want) >= first, k] = np.array(v)[:, 0]
    assert np.array_equal(together, ref.mu_hat[rows])  # each arm's mean, in one bar
    assert np.array_equal(np.array(pulls) + focus_pulls, ref.pulls[rows])
    # the candidates' bars are the means of the members not drawn in their own colour
    cand = ref.candidates[rows]
    assert np.all((np.array(mean) > 0) <= cand)
    data = read_rrd(path)
    for k, first in sink.focus.items():  # each line from the slot its arm came to matter
        s, v = data[f"{base}/focus/{k + 1}"]
        assert s[0] == first and s[-1] == 2500
        assert np.array_equal([x[0] for x in v], ref.mu_hat[first - 1:, k])
        if first > 1:  # it joined at a snapshot slot, as the most played or a member
            assert first in want
            i = first - 1
            top = np.sort(ref.pulls[i])[-2:]
            most = int(np.argmax(ref.pulls[i])) == k and top[1] > top[0]
            small = ref.candidates[i, k] and ref.candidates[i].sum() <= style.FOCUS_MAX
            assert most or small


@pytest.mark.parametrize("K", [4, 16])
def test_the_chosen_dots_mark_what_the_score_lines_do_not_show(tmp_path, K):
    """Up to LINES_UP_TO arms every arm's score is a line, and where the score chose the arm
    the arm played is the top one: why/chosen holds only the slots where the arm played was
    below the top score (a plug-in that does not maximise its scores; here arms moved by
    hand). Beyond, only the arms that matter are lines: why/chosen holds the played arm's
    score wherever it has one."""
    inst = instance_of(K)
    config = RunConfig(inst, make_policy("ucb"), 1, 3000)
    ref = SlotBlock.concat(list(simulate_run(inst, config.policy, 1, 3000)))
    score = ref.score.astype(np.float64)
    rows = np.arange(len(ref))
    below = np.isfinite(score).all(axis=1) & (rows % 97 == 5)  # play the lowest score there
    arm = np.where(below, np.argmin(np.where(np.isfinite(score), score, np.inf), axis=1),
                   ref.arm)  # fmt: skip
    block = dataclasses.replace(ref, arm=arm)
    with RrdOutput(config, rrd_path=tmp_path / "a.rrd") as out:
        with RerunSink(out.recording, config.label, config) as sink:
            sink.write(block)
    slots, values = read_rrd(tmp_path / "a.rrd")[f"/{run_path(config.label)}/why/chosen"]
    chosen = score[rows, arm]
    want = below if K <= style.LINES_UP_TO else np.isfinite(chosen)
    assert 20 < want.sum() < len(ref)
    assert np.array_equal(slots, ref.t[want])
    assert np.array_equal([v[0] for v in values], chosen[want])


@pytest.mark.parametrize("policy", ["cucb", "ucb"])
def test_the_scores_are_one_entity_of_K_series(tmp_path, policy):
    """Up to LINES_UP_TO arms why/score holds every arm's score, a row a slot scored; an arm
    without a finite score there (outside CUCB's candidate set) is -inf, no point (NaN
    would make two equal recordings differ under `rerun rrd compare`)."""
    path, config, ref, _ = run(tmp_path, instance_of(4), policy, horizon=2000)
    slots, values = read_rrd(path)[f"/{run_path(config.label)}/why/score"]
    score = ref.score.astype(np.float64)
    fin = np.isfinite(score)
    rows = fin.any(axis=1)
    assert rows.sum() > 1000 and np.array_equal(slots, ref.t[rows])
    assert np.array_equal(np.array(values), np.where(fin, score, -np.inf)[rows])
    assert (policy == "cucb") == bool((~fin[rows]).any())  # CUCB leaves arms out


def test_true_means_are_dots_that_alternate_where_means_are_equal(tmp_path):
    inst = load_instance("I1")  # mu_1 = mu_4 = 0.2
    path, config, ref, _ = run(tmp_path, inst, horizon=2000)
    data = read_rrd(path)
    base = "/" + run_path(config.label)
    mu = analyse(inst).mu
    first = {}
    for k in range(4):
        slots, values = data[f"{base}/true_means/{k + 1}"]
        assert np.allclose([v[0] for v in values], mu[k])
        assert 8 <= len(slots) <= 30  # dotted: a few dozen, evenly spaced
        assert len(set(np.diff(slots))) == 1
        first[k] = slots[0]
    assert first[0] != first[3]  # arms 1 and 4 (equal means) take turns
    slots, values = data[f"{base}/arm/best"]
    assert {v[0] for v in values} == {2.0} and slots[0] == 1 and slots[-1] == 2000


# ------------------------------------------------------------------ content unchanged

GOLDEN = Path(__file__).parent / "golden"


def golden_module() -> Any:
    return load_script("tests/golden/regenerate.py")


def entities_by_value(path: Path, base: str) -> tuple[dict[str, tuple[list[int], list[Any]]],
                                                      set[str]]:  # fmt: skip
    """The time-indexed Scalars of every entity under ``base`` (slots sorted) and the set of
    every entity under ``base``."""
    rows: dict[str, tuple[list[int], list[Any]]] = {}
    every = set()
    for chunk in RrdReader(path).stream():
        if not chunk.entity_path.startswith(base + "/"):
            continue
        every.add(chunk.entity_path)
        b = chunk.to_record_batch()
        if chunk.is_static or "Scalars:scalars" not in b.schema.names:
            continue
        s, v = rows.setdefault(chunk.entity_path[len(base) + 1 :], ([], []))
        s.extend(b.column("slot").to_pylist())
        v.extend(b.column("Scalars:scalars").to_pylist())
    for e, (s, v) in rows.items():
        o = np.argsort(s, kind="stable")
        rows[e] = ([s[i] for i in o], [v[i] for i in o])
    return rows, every


def old_entities_of(block: SlotBlock) -> dict[str, tuple[list[int], list[Any]]]:
    """What the entities that existed before the views' work (``ENTITIES``) hold for a run,
    from its log's columns: one value per slot, or the slots where the arm succeeded,
    failed, was chosen by the override, or was a candidate (numbered from 1)."""
    t = [int(v) for v in block.t]
    arm = [float(a + 1) for a in block.arm]

    def where(mask: np.ndarray, values: list[float]) -> tuple[list[int], list[Any]]:
        keep = np.flatnonzero(mask)
        return [t[i] for i in keep], [[values[i]] for i in keep]

    out = {name: (t, [[float(v)] for v in getattr(block, name)])
           for name in ("aoi", "oracle_aoi", "regret", "estimator")}  # fmt: skip
    out["x"] = (t, [[float(v + 1)] for v in block.x])
    out["arm/success"] = where(block.success.astype(bool), arm)
    out["arm/failure"] = where(~block.success.astype(bool), arm)
    out["override"] = where(block.override.astype(bool), arm)
    out["mu_hat"] = (t, [[float(v) for v in row] for row in block.mu_hat])
    out["pulls"] = (t, [[float(v) for v in row] for row in block.pulls])
    for k in range(block.mu_hat.shape[1]):
        out[f"candidates/{k + 1}"] = where(block.candidates[:, k].astype(bool),
                                           [float(k + 1)] * len(t))  # fmt: skip
    return {e: v for e, v in out.items() if v[0]}


@pytest.mark.parametrize("key", golden_module().LOG_CASES, ids=lambda k: "-".join(map(str, k)))
def test_logs_and_the_old_entities_are_unchanged_only_presentation_entities_are_new(
    tmp_path, key
):
    """The golden logs (tests/golden/logs.json) as the views record them: the log value for
    value (integers equal, floats within 1e-12 relative: the same on any machine, where a
    digest of the file's bytes was not), and the old entities hold the log's values."""
    golden = golden_module()
    config = golden.write_log(key, tmp_path / "a.mcap")
    stored = json.loads((GOLDEN / "logs.json").read_text())[golden.case_name(key)]
    assert golden.differences(stored, golden.log_values(tmp_path / "a.mcap")) == []
    from corraoi.recorder.slotlog.reader import open_log

    block = open_log(tmp_path / "a.mcap").read_all()
    with RrdOutput(config, rrd_path=tmp_path / "a.rrd") as out:
        with RerunSink(out.recording, config.label, config) as rsink:
            rsink.write(block)
    base = "/" + run_path(config.label)
    got, every = entities_by_value(tmp_path / "a.rrd", base)
    want = old_entities_of(block)
    assert golden.differences(want, {e: got[e] for e in want if e in got}) == []
    slots, values = got["mu_true"]  # the true means, at the ends of the run
    assert slots[0] == 1 and slots[-1] == config.horizon
    assert golden.differences([stored["metadata"]["mu"]] * len(values), values) == []
    K = config.instance.K
    old = {f"{base}/{e}" for e in ENTITIES if e != "candidates"} | {
        f"{base}/candidates/{k + 1}" for k in range(K)
    }
    why = {e for e in every - old if e.startswith(f"{base}/why/")}  # the scores' view
    assert why and all(any(e[len(base) + 1:].startswith(p) for p in WHY) for e in why)
    new = every - old - why
    assert new == {f"{base}/arm/best"} | {f"{base}/true_means/{k + 1}" for k in range(K)}
    assert all(any(e[len(base) + 1:].startswith(p) for p in PRESENTATION) for e in new)


# ------------------------------------------------------------------ compare and sweep


def test_compare_shares_its_scales_and_uses_the_same_views(tmp_path, record_mcap):
    from corraoi.viewer.compare import compare, compare_blueprint

    a, _, ref_a = record_mcap("ucb", seed=4, horizon=1500, name="a.mcap")
    b, _, ref_b = record_mcap("cucb", seed=4, horizon=1500, name="b.mcap")
    result = compare([a, b], rrd_path=tmp_path / "c.rrd")
    top = max(ref_a.aoi.max(), ref_b.aoi.max(), ref_a.oracle_aoi.max())
    ranges = []
    for chunk in RrdReader(tmp_path / "c.rrd").stream(store=RrdReader(tmp_path / "c.rrd")
                                                      .blueprints()[0]):  # fmt: skip
        batch = chunk.to_record_batch()
        if "ScalarAxis:range" in batch.schema.names:
            ranges += [tuple(r[0]) for r in batch.column("ScalarAxis:range").to_pylist()]
    assert ranges.count((0.5, float(top) + 0.5)) == 2  # one AoI scale for both columns
    assert ranges.count((0.5, 4.5)) == 4  # arm played and candidate set, each column
    props = [c.to_record_batch().to_pydict() for c in RrdReader(tmp_path / "c.rrd").stream()
             if c.entity_path == "/__properties"]  # fmt: skip
    assert any(p.get("RecordingInfo:name") == [["compare ucb, cucb"]] for p in props)
    # many arms: the same views as record's, bars and the arms that matter
    big = random_instance(16, seed=5)
    runs = result.runs
    object.__setattr__(runs[0].log.config, "instance", big)
    kinds = [v.class_identifier for v in views(compare_blueprint(runs, aoi_max=9))]
    assert "BarChart" in kinds


def test_the_sweep_recording_is_named_and_tells_pull_shares_apart(tmp_path):
    from corraoi.recorder.sweeplog.recording import SweepRerunSink, share_widths

    from .test_sweep_log import small_sweep

    config, points = small_sweep(("ucb", "cucb"), runs=2, horizon=300)
    folder = tmp_path / "my-sweep"
    with SweepRerunSink.to_file(folder / "sweep.rrd", config) as sink:
        for p in points:
            sink.write(p)
    props = [c.to_record_batch().to_pydict() for c in RrdReader(folder / "sweep.rrd").stream()
             if c.entity_path == "/__properties"]  # fmt: skip
    names = [p["RecordingInfo:name"][0][0] for p in props if "RecordingInfo:name" in p]
    assert names == ["my-sweep: I1 sweep, 2 runs, T = 300"]
    st = statics(folder / "sweep.rrd")
    widths = [st[f"/sweep/pulls/ucb/{k}"]["SeriesLines:widths"][0][0] for k in range(1, 5)]
    assert widths == share_widths(4) and widths == sorted(widths, reverse=True)
    assert widths[0] - widths[-1] >= 3  # a thin line inside a wide one where shares meet


def test_the_sweep_overlay_leaves_out_every_notable_run_of_several_sources():
    # a cell of several sources marks its run of most collisions too: one storm of 2,300
    # flattened the means in the overlay, drawn there as the worst run was before
    from corraoi.recorder.sweeplog.layout import regret_path, sweep_blueprint
    from corraoi.stats import CELL_RUNS

    names = ["rhorand-ucb(M=2)", "chairs-ucb(M=2)"]
    config = {"instance": {"Y": [[1, 0], [0, 1], [1, 1]], "p": [0.5, 0.5]},
              "policies": [{"name": n} for n in names], "runs": 5, "horizon": 100,
              "sources": [2], "notable": {"cells": {n: {} for n in names}}}  # fmt: skip
    found = views(sweep_blueprint(config))
    overlay = next(v for v in found if str(v.name).startswith("AoI regret"))
    for n in names:
        for kind in CELL_RUNS:
            assert f"- {regret_path(n)}/{kind}" in overlay.contents, (n, kind)
    watch = [str(v.name) for v in found if str(v.name).endswith("most collisions")]
    assert watch == [f"{n}: mean, worst, median, best run, most collisions" for n in names]


def test_a_sweep_of_many_arms_draws_bars_and_the_arms_that_matter(tmp_path):
    from corraoi.recorder.sweeplog.layout import shown_arms, sweep_blueprint
    from corraoi.recorder.sweeplog.recording import SweepRerunSink
    from corraoi.stats import SweepPoint

    inst = random_instance(64, seed=7)
    config = {"instance": inst.to_dict(), "policies": [{"name": "cucb"}], "runs": 3,
              "horizon": 200}  # fmt: skip
    rng = np.random.default_rng(0)
    shares = rng.dirichlet(np.ones(64), size=4)
    points = [SweepPoint(policy="cucb", t=t, regret_mean=1.0 * t, regret_ci95=0.5,
                         estimator_mean=1.0, estimator_ci95=None, pull_share=shares[i])
              for i, t in enumerate((50, 100, 150, 200))]  # fmt: skip
    with SweepRerunSink.to_file(tmp_path / "s.rrd", config) as sink:
        for p in points:
            sink.write(p)
    slots, values = bars(tmp_path / "s.rrd")["/sweep/share/cucb"]
    assert slots == [50, 100, 150, 200] and np.allclose(values, shares)
    shown = shown_arms(config)
    assert 1 <= len(shown) <= style.FOCUS_START
    lines = [v for v in views(sweep_blueprint(config)) if "arms that matter" in str(v.name)]
    assert lines[0].contents == [f"$origin/{k + 1}" for k in shown]
