"""The sweep figure and ``corraoi figure``: drawn from the log alone, in the paper's style,
with clear errors (unknown policies, existing output, bad logs, matplotlib missing)."""

from __future__ import annotations

import struct
import subprocess
import sys
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from click.testing import CliRunner

from corraoi.cli import main
from corraoi.errors import FigureUnavailable, UsageError
from corraoi.recorder.style import POLICY_COLORS
from corraoi.recorder.sweeplog.log import SweepMcapSink
from corraoi.recorder.sweeplog.read import read_sweep
from corraoi.viewer.figure import DPI, FIGSIZE, MISSING_MATPLOTLIB, draw_figure

from .test_sweep_log import POLICIES, small_sweep, write_log

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
MATPLOTLIB_MODULES = (
    "matplotlib",
    "matplotlib.figure",
    "matplotlib.backends.backend_agg",
    "matplotlib.lines",
    "matplotlib.patches",
)


@pytest.fixture(scope="module")
def log_path(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return write_log(tmp_path_factory.mktemp("sweep") / "sweep.mcap", small_sweep())


def run(*args: str):
    return CliRunner().invoke(main, list(args))


def png_size(path: Path) -> tuple[int, int]:
    data = path.read_bytes()
    assert data[:8] == PNG_SIGNATURE and data[12:16] == b"IHDR"
    width, height = struct.unpack(">II", data[16:24])
    return width, height


def has_color(path: Path, rgb: tuple[int, int, int], tol: int = 2) -> bool:
    from matplotlib.image import imread

    img = np.round(imread(path)[..., :3] * 255).astype(int)
    return bool((np.abs(img - np.array(rgb)).max(axis=-1) <= tol).any())


def capture_figures(monkeypatch: pytest.MonkeyPatch) -> list[Any]:
    """Keep every matplotlib Figure saved from now on, to inspect what was drawn."""
    from matplotlib.figure import Figure

    saved: list[Any] = []
    original = Figure.savefig

    def savefig(self: Any, *args: Any, **kwargs: Any) -> Any:
        saved.append(self)
        return original(self, *args, **kwargs)

    monkeypatch.setattr(Figure, "savefig", savefig)
    return saved


# ---------------------------------------------------------------------------- draw_figure


def test_png_of_the_expected_size_with_each_policy_colour(tmp_path: Path, log_path: Path):
    pytest.importorskip("matplotlib")
    out = draw_figure(read_sweep(log_path), tmp_path / "fig.png")
    assert out == tmp_path / "fig.png" and not (tmp_path / "fig.png.partial").exists()
    assert png_size(out) == (round(FIGSIZE[0] * DPI), round(FIGSIZE[1] * DPI))
    for name in ("ucb", "cucb", "cts"):  # the drawn policies' colours (aoi-aware-cucb: green)
        assert has_color(out, POLICY_COLORS[name]), name
    for name in ("ts", "cts-gauss"):  # not in this sweep
        assert not has_color(out, POLICY_COLORS[name]), name


def test_paper_style_lines_bands_dashes_legend_title(tmp_path: Path, log_path: Path, monkeypatch):
    pytest.importorskip("matplotlib")
    saved = capture_figures(monkeypatch)
    sweep = read_sweep(log_path)
    draw_figure(sweep, tmp_path / "fig.png")
    (fig,) = saved
    (ax,) = fig.axes
    lines = {line.get_label(): line for line in ax.get_lines()}
    assert list(lines) == list(POLICIES)
    for name in POLICIES:
        curve = sweep.curves[name]
        x, y = lines[name].get_data()
        assert np.array_equal(x, curve.t) and np.array_equal(y, curve.regret_mean)
    green = tuple(v / 255 for v in POLICY_COLORS["cucb"])
    assert lines["cucb"].get_color() == lines["aoi-aware-cucb"].get_color() == green
    assert lines["cucb"].get_linestyle() == "-"
    assert lines["aoi-aware-cucb"].get_linestyle() == "--"
    assert len(ax.collections) == len(POLICIES)  # one shaded band per policy
    band = ax.collections[1].get_paths()[0].vertices[:, 1]
    c = sweep.curves["cucb"]
    assert band.max() == pytest.approx((c.regret_mean + c.regret_ci95).max())
    legend = [t.get_text() for t in ax.get_legend().get_texts()]
    assert legend[: len(POLICIES)] == list(POLICIES) and "95% confidence band" in legend
    title = ax.get_title()
    assert "I1" in title and "6 runs" in title and "T = 300" in title
    assert ax.get_xscale() == "linear" and ax.get_xlabel() == "slot t"


def test_log_x_and_policy_subset_in_the_order_asked(tmp_path: Path, log_path: Path, monkeypatch):
    pytest.importorskip("matplotlib")
    saved = capture_figures(monkeypatch)
    out = draw_figure(read_sweep(log_path), tmp_path / "f.png", log_x=True, policies=["cts", "ucb"])
    (ax,) = saved[0].axes
    assert [line.get_label() for line in ax.get_lines()] == ["cts", "ucb"]
    assert ax.get_xscale() == "log"
    assert has_color(out, POLICY_COLORS["cts"]) and not has_color(out, POLICY_COLORS["cucb"])


def test_same_log_same_bytes_and_other_formats(tmp_path: Path, log_path: Path):
    pytest.importorskip("matplotlib")
    sweep = read_sweep(log_path)
    a = draw_figure(sweep, tmp_path / "a.png")
    b = draw_figure(sweep, tmp_path / "b.png")
    assert a.read_bytes() == b.read_bytes()
    svg = draw_figure(sweep, tmp_path / "f.svg")
    assert svg.read_text().lstrip().startswith("<?xml") and "cucb" in svg.read_text()


def test_missing_matplotlib_is_one_clear_line(tmp_path: Path, log_path: Path, monkeypatch):
    for name in MATPLOTLIB_MODULES:
        monkeypatch.setitem(sys.modules, name, None)  # import raises ImportError
    with pytest.raises(FigureUnavailable) as exc:
        draw_figure(read_sweep(log_path), tmp_path / "fig.png")
    assert (
        str(exc.value)
        == MISSING_MATPLOTLIB
        == "figures need matplotlib: pip install 'corraoi[plot]'"
    )
    res = run("figure", str(log_path), "-o", str(tmp_path / "fig.png"))
    assert res.exit_code == 1
    assert res.output.strip() == f"corraoi: error: {MISSING_MATPLOTLIB}"
    assert list(tmp_path.iterdir()) == []


def test_unknown_policy_and_empty_log(tmp_path: Path, log_path: Path):
    sweep = read_sweep(log_path)
    from corraoi.errors import UsageError

    with pytest.raises(UsageError, match="no curve for ts, nope in this sweep log"):
        draw_figure(sweep, tmp_path / "x.png", policies=["cucb", "ts", "nope"])
    config, _ = small_sweep(("ts",), runs=2, horizon=10)
    with SweepMcapSink(tmp_path / "empty.mcap", config, fsync=False):
        pass
    pytest.importorskip("matplotlib")
    with pytest.raises(UsageError, match="holds no points"):
        draw_figure(read_sweep(tmp_path / "empty.mcap"), tmp_path / "x.png")
    assert not (tmp_path / "x.png").exists()


# ---------------------------------------------------------------------------- CLI


def test_cli_figure_writes_and_refuses_to_overwrite(tmp_path: Path, log_path: Path):
    pytest.importorskip("matplotlib")
    out = tmp_path / "fig.png"
    res = run(
        "figure", str(log_path), "-o", str(out), "--log-x", "--policies", "cucb,aoi-aware-cucb"
    )
    assert res.exit_code == 0, res.output
    assert f"wrote {out}: 2 policies, instance I1, 6 runs, horizon 300" in res.output
    assert png_size(out) == (1500, 900)
    assert has_color(out, POLICY_COLORS["cucb"]) and not has_color(out, POLICY_COLORS["ucb"])
    before = out.read_bytes()
    res = run("figure", str(log_path), "-o", str(out))
    assert res.exit_code == 2
    assert (
        res.output.strip() == f"corraoi: error: {out}: already exists (use --force to overwrite it)"
    )
    assert out.read_bytes() == before
    res = run("figure", str(log_path), "-o", str(out), "--force", "--policies", "ucb")
    assert res.exit_code == 0, res.output
    assert out.read_bytes() != before and has_color(out, POLICY_COLORS["ucb"])


@pytest.mark.parametrize(
    "case, expected",
    [
        ("unknown", "no curve for ts in this sweep log (it has: ucb, cucb, aoi-aware-cucb, cts)"),
        ("missing", "no such sweep log"),
        ("directory", "is a directory, not a sweep log"),
        ("not-mcap", "not an MCAP file"),
        ("out-dir", "is a directory; give a file name for the figure"),
    ],
)
def test_cli_figure_errors(tmp_path: Path, log_path: Path, case: str, expected: str):
    out = tmp_path / "fig.png"
    args = [str(log_path), "-o", str(out)]
    if case == "unknown":
        args += ["--policies", "cucb", "--policies", "ts"]
    elif case == "missing":
        args[0] = str(tmp_path / "none.mcap")
    elif case == "directory":
        args[0] = str(tmp_path)
    elif case == "not-mcap":
        (tmp_path / "x.mcap").write_text("not mcap")
        args[0] = str(tmp_path / "x.mcap")
    elif case == "out-dir":
        args[2] = str(tmp_path)
    res = run("figure", *args)
    assert res.exit_code == 2, res.output
    assert expected in res.output
    assert res.output.startswith("corraoi: error: ") and res.output.count("\n") == 1
    assert "Traceback" not in res.output and not out.exists()


def test_cli_figure_of_an_interrupted_sweep_warns(tmp_path: Path):
    pytest.importorskip("matplotlib")
    config, points = small_sweep(("ucb", "cts"), runs=3, horizon=100)
    with pytest.raises(KeyboardInterrupt), SweepMcapSink(tmp_path / "s.mcap", config) as sink:
        for p in points[:12]:
            sink.write(p)
        raise KeyboardInterrupt
    res = run("figure", str(tmp_path / "s.mcap.partial"), "-o", str(tmp_path / "f.png"))
    assert res.exit_code == 0, res.output
    assert "the sweep did not finish (interrupted); drawing the 12 checkpoint(s)" in res.output
    assert png_size(tmp_path / "f.png") == (1500, 900)


def test_cli_figure_never_simulates(tmp_path: Path, log_path: Path):
    pytest.importorskip("matplotlib")
    code = (
        "import sys\n"
        "from corraoi.cli import main\n"
        "try:\n"
        f"    main(['figure', {str(log_path)!r}, '-o', {str(tmp_path / 'f.png')!r}])\n"
        "except SystemExit as e:\n"
        "    assert not e.code, e.code\n"
        "heavy = [m for m in ('corraoi.engine.simulation', 'corraoi.engine._kernel', 'numba',"
        " 'rerun')"
        " if m in sys.modules]\n"
        "assert not heavy, heavy\n"
    )
    res = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert res.returncode == 0, res.stdout + res.stderr
    assert png_size(tmp_path / "f.png") == (1500, 900)


# ---------------------------------------------------------------------------- options (issue 10)

BASES = ("ucb", "ts", "ts-gauss", "cucb", "cts", "cts-gauss")
ALL12 = BASES + tuple(f"aoi-aware-{b}" for b in BASES)


@pytest.fixture(scope="module")
def log12(tmp_path_factory: pytest.TempPathFactory) -> Path:
    path = tmp_path_factory.mktemp("sweep12") / "sweep.mcap"
    return write_log(path, small_sweep(ALL12, runs=3, horizon=300))


def _boxes_overlap(a: Any, b: Any) -> bool:
    return bool(a.x0 < b.x1 and b.x0 < a.x1 and a.y0 < b.y1 and b.y0 < a.y1)


@pytest.mark.parametrize("split", [False, True])
def test_twelve_policies_never_overlap_the_legend(tmp_path, log12, monkeypatch, split):
    pytest.importorskip("matplotlib")
    saved = capture_figures(monkeypatch)
    out = draw_figure(read_sweep(log12), tmp_path / "f.png", split=split)
    (fig,) = saved
    renderer = fig.canvas.get_renderer()
    axes = fig.axes
    assert len(axes) == (2 if split else 1)
    (legend,) = [ax.get_legend() for ax in axes if ax.get_legend() is not None]
    box = legend.get_window_extent(renderer)
    assert [t.get_text() for t in legend.get_texts()][:12] == list(ALL12)
    for ax in axes:
        assert not _boxes_overlap(box, ax.get_window_extent(renderer))
    assert box.x1 <= fig.bbox.x1 + 1 and box.y0 >= fig.bbox.y0 - 1  # inside the figure
    if split:  # small multiples: base policies left, their AoI-aware forms right, one y scale
        left, right = ([line.get_label() for line in ax.get_lines()] for ax in axes)
        assert left == list(ALL12[:6]) and right == list(ALL12[6:])
        assert axes[0].get_ylim() == axes[1].get_ylim()
        assert all(line.get_linestyle() == "--" for line in axes[1].get_lines())
    for name in ("ts-gauss", "cts-gauss"):
        assert has_color(out, POLICY_COLORS[name]), name


def test_log_y_and_dpi(tmp_path, log_path, monkeypatch):
    pytest.importorskip("matplotlib")
    saved = capture_figures(monkeypatch)
    out = draw_figure(read_sweep(log_path), tmp_path / "f.png", log_y=True, dpi=60)
    (ax,) = saved[0].axes
    assert ax.get_yscale() == "symlog" and "symmetric log" in ax.get_ylabel()
    assert "[slot-ages]" in ax.get_ylabel()
    assert png_size(out) == (round(FIGSIZE[0] * 60), round(FIGSIZE[1] * 60))
    res = run("figure", str(log_path), "-o", str(tmp_path / "g.png"), "--dpi", "40", "--log-y")
    assert res.exit_code == 0, res.output
    assert png_size(tmp_path / "g.png") == (400, 240)


MAGIC = {
    "png": b"\x89PNG",
    "svg": b"<?xml",
    "pdf": b"%PDF",
    "jpg": b"\xff\xd8\xff",
    "jpeg": b"\xff\xd8\xff",
    "webp": b"RIFF",
    "tif": b"II*\x00",
    "tiff": b"II*\x00",
}


@pytest.mark.parametrize("ext", sorted(MAGIC))
def test_the_extension_picks_the_format(tmp_path, log_path, ext):
    pytest.importorskip("matplotlib")
    out = tmp_path / f"fig.{ext.upper() if ext == 'png' else ext}"
    res = run("figure", str(log_path), "-o", str(out))
    assert res.exit_code == 0, res.output
    assert out.read_bytes().startswith(MAGIC[ext])
    if ext == "webp":
        assert out.read_bytes()[8:12] == b"WEBP"


@pytest.mark.parametrize(
    "name, args, expected",
    [
        ("fig.bmp", [], "fig.bmp: cannot tell the figure format (extension '.bmp'); expected a "
         "file name ending in .png, .svg, .pdf, .jpg, .webp or .tif"),
        ("fig", [], "fig: cannot tell the figure format (no extension)"),
        ("fig.png", ["--dpi", "5"], "--dpi 5: out of range, expected 20..1200 dots per inch"),
        ("fig.png", ["--dpi", "5000"], "--dpi 5000: out of range"),
    ],
)  # fmt: skip
def test_bad_extension_or_dpi_is_one_line_and_no_file(tmp_path, log_path, name, args, expected):
    out = tmp_path / name
    res = run("figure", str(log_path), "-o", str(out), *args)
    assert res.exit_code == 2, res.output
    assert res.output.startswith("corraoi: error: ") and res.output.count("\n") == 1
    assert expected in res.output
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(UsageError, match="cannot tell the figure format"):
        draw_figure(read_sweep(log_path), tmp_path / "x.gif")


def test_the_rules_of_several_sources_are_told_apart_by_marker(tmp_path: Path, monkeypatch):
    # rhorand-ucb and chairs-ucb share UCB's colour (and its shades by M): a marker per rule
    # tells their curves apart, the AoI-aware dash still marks the AoI-aware form
    pytest.importorskip("matplotlib")
    import corraoi
    from corraoi.recorder.style import is_aoi_aware, rule_marker

    names = ["rhorand-ucb", "chairs-ucb", "mctopm-aoi-aware-ucb", "centralized-ucb"]
    corraoi.sweep("I1", names, runs=3, horizon=300, sources=2, out=tmp_path / "s")
    saved = capture_figures(monkeypatch)
    draw_figure(read_sweep(tmp_path / "s" / "sweep.mcap"), tmp_path / "fig.png")
    (fig,) = saved
    lines = {line.get_label(): line for line in fig.axes[0].get_lines()}
    label = {n: f"{n}(M=2)" if f"{n}(M=2)" in lines else n for n in names}
    assert sorted(lines) == sorted(label.values())
    assert [lines[label[n]].get_marker() for n in names] == ["None", "o", "s", "^"]
    assert len({lines[label[n]].get_color() for n in names}) == 1  # UCB's, for every rule
    assert lines[label["mctopm-aoi-aware-ucb"]].get_linestyle() == "--"
    assert lines[label["chairs-ucb"]].get_linestyle() == "-"
    legend = fig.axes[0].get_legend()
    assert [h.get_marker() for h in legend.legend_handles[:4]] == ["None", "o", "s", "^"]
    assert is_aoi_aware("mctopm-aoi-aware-ucb") and not is_aoi_aware("chairs-ucb")
    assert rule_marker("ucb") == "" and rule_marker("sw-ucb") == ""


def test_a_legend_of_dozens_of_curves_goes_into_columns_and_leaves_the_axes_whole(
        tmp_path: Path, monkeypatch):  # fmt: skip
    # reproduce decentralized draws 48 curves: in one column at the usual type the legend
    # was taller than the figure and constrained layout squeezed the axes to a strip
    pytest.importorskip("matplotlib")
    import corraoi

    names = [f"{rule}-{base}" for rule in ("rhorand", "mctopm", "centralized", "chairs")
             for base in ("ucb", "cucb")]  # fmt: skip
    corraoi.sweep("I1", names, runs=2, horizon=200, sources=[1, 2, 3, 4], out=tmp_path / "s")
    saved = capture_figures(monkeypatch)
    draw_figure(read_sweep(tmp_path / "s" / "sweep.mcap"), tmp_path / "fig.png")
    (fig,) = saved
    ax = fig.axes[0]
    assert len(ax.get_lines()) == 32
    legend = ax.get_legend()
    renderer = fig.canvas.get_renderer()
    columns = {round(t.get_window_extent(renderer).x0) for t in legend.get_texts()}
    assert len(columns) == 2
    assert ax.get_position().height > 0.6 and ax.get_position().width > 0.4
