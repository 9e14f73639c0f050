"""One installed package (issue 41): ``corraoi`` is the distribution's only top-level import
name. The checkout's recorder/ and viewer/ install as ``corraoi.recorder`` and ``corraoi.viewer``
(pyproject.toml's package-dir), in a wheel and in an editable install alike."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
#: the checkout's folders and where the installed package has them
INSTALLED_AS = {"corraoi": "corraoi", "recorder": "corraoi/recorder", "viewer": "corraoi/viewer"}
#: what the wheel is built from, copied so that the build writes nothing into the checkout
SOURCES = ("pyproject.toml", "README.md", *INSTALLED_AS)


def _can_build_wheels() -> bool:
    """setuptools' own bdist_wheel (70.1 and later), or the wheel package's."""
    try:
        import setuptools
    except ImportError:
        return False
    major, minor = (int(p) for p in setuptools.__version__.split(".")[:2])
    if (major, minor) >= (70, 1):
        return True
    try:
        import wheel  # noqa: F401
    except ImportError:
        return False
    return True


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> Path:
    if not _can_build_wheels():
        pytest.skip(
            "building a wheel without the network needs setuptools >= 70.1 or wheel "
            "(pip install -e '.[test]')"
        )
    work = tmp_path_factory.mktemp("wheel")
    src = work / "src"
    src.mkdir()
    skip = shutil.ignore_patterns("__pycache__", "*.egg-info", "build")
    for name in SOURCES:
        if (ROOT / name).is_dir():
            shutil.copytree(ROOT / name, src / name, ignore=skip)
        else:
            shutil.copy2(ROOT / name, src / name)
    out = work / "dist"
    subprocess.run(
        [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation", "--no-index",
         "-q", "-w", str(out), str(src)],
        check=True, capture_output=True, text=True,
    )  # fmt: skip
    (built,) = out.glob("corraoi-*.whl")
    return built


def test_the_wheel_has_one_top_level_name(wheel: Path):
    names = zipfile.ZipFile(wheel).namelist()
    tops = {n.split("/")[0] for n in names}
    dist_info = {t for t in tops if t.endswith(".dist-info")}
    assert len(dist_info) == 1 and dist_info.pop().startswith("corraoi-")
    assert {t for t in tops if not t.endswith(".dist-info")} == {"corraoi"}


def test_the_wheel_holds_every_module_of_the_three_folders(wheel: Path):
    """Every .py file of corraoi/, recorder/ and viewer/ (pyproject.toml lists the packages one
    by one: a new folder must join the list) and the CUDA kernel's source."""
    names = set(zipfile.ZipFile(wheel).namelist())
    expected = {
        f"{INSTALLED_AS[folder]}/{path.relative_to(ROOT / folder).as_posix()}"
        for folder in INSTALLED_AS
        for path in (ROOT / folder).rglob("*.py")
        if "__pycache__" not in path.parts
    }
    assert sorted(expected - names) == []
    assert "corraoi/gpu/kernel.cu" in names
    assert {"corraoi/recorder/slotlog/reader.py", "corraoi/viewer/diffs.py"} <= names
    assert not [n for n in names if n.startswith(("recorder/", "viewer/"))]


#: run outside the checkout: which files the packages come from, and whether the old
#: top-level names import
PROBE = """
import importlib, json, sys
if {drop_editable}:  # the wheel's files alone, not an editable install of this environment
    sys.meta_path[:] = [f for f in sys.meta_path if "__editable__" not in type(f).__module__]
import corraoi.recorder.slotlog.reader, corraoi.viewer.diffs
found = {{"corraoi": corraoi.__file__, "recorder": corraoi.recorder.__file__,
          "reader": corraoi.recorder.slotlog.reader.__file__,
          "viewer": corraoi.viewer.__file__}}
for old in ("recorder", "viewer"):
    try:
        importlib.import_module(old)
        found[old + " (top level)"] = "imported"
    except ModuleNotFoundError:
        pass
print(json.dumps(found))
"""


def _probe(cwd: Path, pythonpath: str | None, drop_editable: bool) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    if pythonpath is not None:
        env["PYTHONPATH"] = pythonpath
    res = subprocess.run(
        [sys.executable, "-c", PROBE.format(drop_editable=drop_editable)],
        cwd=cwd, env=env, capture_output=True, text=True,
    )  # fmt: skip
    assert res.returncode == 0, res.stderr
    return json.loads(res.stdout)


def test_the_installed_wheel_has_no_recorder_or_viewer_package(wheel: Path, tmp_path: Path):
    site = tmp_path / "site"
    subprocess.run(
        [sys.executable, "-m", "pip", "install", "--no-deps", "--no-index", "-q", "--target",
         str(site), str(wheel)],
        check=True, capture_output=True, text=True,
    )  # fmt: skip
    found = _probe(tmp_path, str(site), drop_editable=True)
    assert found == {
        "corraoi": str(site / "corraoi" / "__init__.py"),
        "recorder": str(site / "corraoi" / "recorder" / "__init__.py"),
        "reader": str(site / "corraoi" / "recorder" / "slotlog" / "reader.py"),
        "viewer": str(site / "corraoi" / "viewer" / "__init__.py"),
    }


def test_the_installed_package_outside_the_checkout(tmp_path: Path):
    """The environment's own install (``pip install -e .``), imported from elsewhere: corraoi's
    recorder and viewer come from the checkout's folders, and the old top-level names
    ``recorder`` and ``viewer`` do not import."""
    probe = subprocess.run(
        [sys.executable, "-c", "import importlib.util as u; print(u.find_spec('corraoi') is None)"],
        cwd=tmp_path, env={k: v for k, v in os.environ.items() if k != "PYTHONPATH"},
        capture_output=True, text=True, check=True,
    )  # fmt: skip
    if probe.stdout.strip() == "True":
        pytest.skip("corraoi is not installed in this environment (pip install -e .)")
    found = _probe(tmp_path, None, drop_editable=False)
    assert "recorder (top level)" not in found and "viewer (top level)" not in found, (
        f"{found}: an install made before issue 41; reinstall with pip install --no-deps -e ."
    )
    package = Path(found["corraoi"]).parent
    if (package.parent / "recorder" / "__init__.py").is_file():  # editable: the checkout's folders
        where = {"recorder": package.parent / "recorder", "viewer": package.parent / "viewer"}
    else:
        where = {"recorder": package / "recorder", "viewer": package / "viewer"}
    assert found["recorder"] == str(where["recorder"] / "__init__.py")
    assert found["viewer"] == str(where["viewer"] / "__init__.py")
