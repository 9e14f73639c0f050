"""The house's structure (issues 34 and 41), read from the source of the three packages.

Every import is counted, at module level, inside functions and named in a string to be
imported (``import_module``, a lazy ``__getattr__`` table, a ``"module:attr"`` hook, a
worker's script); ``if TYPE_CHECKING:`` blocks are typing only and left out unless said:

* the module graph across ``corraoi``, ``recorder`` and ``viewer`` has no cycle;
* imports go down the floors: corraoi's lower wings < ``recorder`` < ``viewer`` < the top
  floor (``corraoi.face``, ``corraoi.cli``, ``corraoi.testing``, ``corraoi.pytest_plugin``
  and the package's lazy ``__init__``); the file formats reach no module of the
  experiments, typing included, and recording none of the viewer;
* the wings of ``corraoi`` (its folders, and its ground-floor modules) import each other
  without a circle, and stand at most 8 floors high;
* no module re-exports a name it imports (a wing's ``__init__.py`` is its front), no module,
  test or benchmark reaches another's private name, and no string names a module of the
  layers above to be imported later;
* a front names its public API or nothing, and exports no name nobody imports;
* a wing's ``__init__.py`` imports nothing heavy.
"""

from __future__ import annotations

import ast
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
#: The checkout's folders and the packages they install as (pyproject.toml's package-dir;
#: tests/test_packaging.py checks the wheel): recorder/ is corraoi.recorder.
FOLDERS = {"corraoi": "corraoi", "recorder": "corraoi.recorder", "viewer": "corraoi.viewer"}
RECORDER, VIEWER = FOLDERS["recorder"], FOLDERS["viewer"]
#: what composes the layers for a user: the only modules that import recorder or viewer
TOP = ("corraoi.face", "corraoi.cli", "corraoi.testing", "corraoi.pytest_plugin", "corraoi.gym")
HEAVY = ("numba", "rerun", "pandas", "pyarrow", "matplotlib")
#: What is still owed, with why; each is paid in this round and taken off (the tests fail on a
#: debt that is paid but still listed, so that the list stays true).
OWED_CLIMBS: dict[str, str] = {}


def module_name(path: Path) -> str:
    """The module a file of the checkout is once installed: recorder/walk.py is
    corraoi.recorder.walk; tests/test_x.py is tests.test_x."""
    top, *rest = path.relative_to(ROOT).with_suffix("").parts
    parts = [*FOLDERS.get(top, top).split("."), *rest]
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def _modules() -> dict[str, Path]:
    return {module_name(path): path for folder in FOLDERS for path in (ROOT / folder).rglob("*.py")}


MODULES = _modules()


def _runtime_imports(tree: ast.Module, typing: bool = False) -> list[ast.Import | ast.ImportFrom]:
    """The imports of ``tree``, those under ``if TYPE_CHECKING:`` only with ``typing``."""
    found: list[ast.Import | ast.ImportFrom] = []

    def visit(node: ast.AST) -> None:
        for child in ast.iter_child_nodes(node):
            if (not typing and isinstance(child, ast.If)
                    and "TYPE_CHECKING" in ast.unparse(child.test)):  # fmt: skip
                for other in child.orelse:
                    visit(other)
                continue
            if isinstance(child, (ast.Import, ast.ImportFrom)):
                found.append(child)
            visit(child)

    visit(tree)
    return found


def _base(name: str, node: ast.ImportFrom) -> str:
    """The absolute module an ``from ... import`` names."""
    if not node.level:
        return node.module or ""
    package = name if MODULES.get(name, Path()).name == "__init__.py" else name.rpartition(".")[0]
    up = package.split(".")[: len(package.split(".")) - (node.level - 1)]
    return ".".join(up + ([node.module] if node.module else []))


def _known(name: str) -> str | None:
    while name and name not in MODULES:
        name = name.rpartition(".")[0]
    return name or None


def _string_imports(name: str, tree: ast.Module) -> set[str]:
    """The modules of ours that ``tree`` names in a string to be imported: the first argument
    of ``import_module``, ``__import__`` or ``find_spec``, a ``"module:attr"`` seam (a hook
    named by its module), the values of a lazy ``__getattr__`` table (also relative to the
    package, as ``{"RerunSink": "rerun.sink"}``) and the imports of Python code in a string
    (a worker's ``python -c`` script). A module's name as data (an entry-point group, a
    metadata key, ``-m corraoi.cli`` recognised in ``argv``) is not an import."""
    lazy = any(isinstance(n, ast.FunctionDef) and n.name == "__getattr__" for n in tree.body)
    package = name if MODULES.get(name, Path()).name == "__init__.py" else name.rpartition(".")[0]
    tables = {
        id(v) for n in tree.body if lazy and isinstance(n, (ast.Assign, ast.AnnAssign))
        and isinstance(n.value, ast.Dict) for v in n.value.values
    }  # fmt: skip
    called = {
        id(n.args[0]) for n in ast.walk(tree)
        if isinstance(n, ast.Call) and n.args
        and (_dotted(n.func) or "").rpartition(".")[2] in ("import_module", "__import__",
                                                           "find_spec")
    }  # fmt: skip
    found: set[str] = set()
    for node in ast.walk(tree):
        if not (isinstance(node, ast.Constant) and isinstance(node.value, str)):
            continue
        text, seam, _ = node.value.strip().partition(":")
        if id(node) in tables and f"{package}.{text}" in MODULES:
            found.add(f"{package}.{text}")
        elif text in MODULES and (id(node) in called or id(node) in tables
                                  or (seam and "." in text)):  # fmt: skip
            found.add(text)
        elif "import" in node.value:
            try:
                code = ast.parse(node.value)
            except SyntaxError:
                continue
            for imp in _runtime_imports(code):
                if isinstance(imp, ast.Import):
                    found |= {a.name for a in imp.names}
                elif not imp.level:
                    found |= {imp.module or "", *(f"{imp.module}.{a.name}" for a in imp.names)}
    return found


def _edges(typing: bool = False) -> dict[str, set[str]]:
    """Every module of ours and the modules of ours it imports: at module level, inside
    functions, and named in strings to be imported (:func:`_string_imports`)."""
    edges: dict[str, set[str]] = {}
    for name, path in MODULES.items():
        targets: set[str] = set()
        tree = ast.parse(path.read_text(encoding="utf-8"))
        for node in _runtime_imports(tree, typing):
            if isinstance(node, ast.Import):
                wanted = [a.name for a in node.names]
            else:
                base = _base(name, node)
                subs = [f"{base}.{a.name}" for a in node.names]
                # `from . import x` of submodules depends on them, not on the package itself
                wanted = subs if all(s in MODULES for s in subs) else [base, *subs]
            targets |= {t for w in wanted if (t := _known(w)) is not None and t != name}
        targets |= {t for w in _string_imports(name, tree)
                    if (t := _known(w)) is not None and t != name}  # fmt: skip
        edges[name] = targets
    return edges


def _circles(edges: dict[str, set[str]]) -> set[frozenset[str]]:
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    out: set[frozenset[str]] = set()
    sys.setrecursionlimit(max(sys.getrecursionlimit(), 10_000))

    def strong(v: str) -> None:  # Tarjan
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in edges.get(v, ()):
            if w not in index:
                strong(w)
                low[v] = min(low[v], low[w])
            elif w in stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            part = []
            while True:
                w = stack.pop()
                part.append(w)
                if w == v:
                    break
            if len(part) > 1:
                out.add(frozenset(part))

    for v in list(edges):
        if v not in index:
            strong(v)
    return out


def _is_top(name: str) -> bool:
    return name == "corraoi" or name.startswith(TOP)


def _wing(name: str) -> str:
    """The room of ``corraoi`` a module stands in: its folder, or the module itself."""
    parts = name.split(".")
    if len(parts) > 2 or MODULES[name].name == "__init__.py" and len(parts) == 2:
        return ".".join(parts[:2])
    return name


def test_the_module_graph_has_no_cycle():
    assert _circles(_edges()) == set()


#: The floors of the three folders, lowest first: an import goes to a module of its own floor
#: or of one below.
FLOORS = ("corraoi's lower wings", "recorder", "viewer", "the top floor")


def _floor(name: str) -> int:
    if _is_top(name) or name == "corraoi.__main__":
        return 3
    return 2 if name.startswith(VIEWER) else 1 if name.startswith(RECORDER) else 0


def _climbs(edges: dict[str, set[str]]) -> dict[str, list[str]]:
    """Each module's imports of a module on a higher floor."""
    wrong = {src: sorted(t for t in targets if _floor(t) > _floor(src))
             for src, targets in edges.items()}  # fmt: skip
    return {src: bad for src, bad in wrong.items() if bad}


def test_imports_go_down_the_floors_of_the_three_folders():
    """corraoi's lower wings < recorder < viewer < the top floor (``corraoi.face``,
    ``corraoi.cli``, ``corraoi.testing``, ``corraoi.pytest_plugin``, the package's lazy
    ``__init__``): no import climbs, inside functions and strings included."""
    wrong = _climbs(_edges())
    assert set(wrong) - set(OWED_CLIMBS) == set(), wrong
    assert set(OWED_CLIMBS) <= set(wrong), "paid: take it off OWED_CLIMBS"


def _reach(edges: dict[str, set[str]], start: str) -> set[str]:
    seen, todo = set(), [start]
    while todo:
        m = todo.pop()
        if m not in seen:
            seen.add(m)
            todo += edges.get(m, ())
    return seen


def test_the_formats_import_no_experiment_module_even_for_types():
    """The file formats store plain values (a sweep's points are ``corraoi.stats``'s, its
    provenance is handed in): no module of the recorder reaches ``corraoi.experiments``,
    typing imports and the imports of what it imports counted."""
    edges = _edges(typing=True)
    wrong = {m: sorted(t for t in _reach(edges, m) if t.startswith("corraoi.experiments"))
             for m in edges if m.startswith(RECORDER)}  # fmt: skip
    assert {m: ts for m, ts in wrong.items() if ts} == {}


def test_recording_imports_no_viewer_module():
    """The writer does not lean on the reader: what a run is recorded with (the face's
    ``recording``, the recorder, what they import at module level) imports no module of
    the viewer."""
    edges = _edges()
    assert not [t for t in edges["corraoi.face.recording"] if t.startswith(VIEWER)]
    module_level: dict[str, set[str]] = {}
    for name, path in MODULES.items():
        tree = ast.parse(path.read_text(encoding="utf-8"))
        module_level[name] = {
            t for node in tree.body if isinstance(node, (ast.Import, ast.ImportFrom))
            for w in ([a.name for a in node.names] if isinstance(node, ast.Import)
                      else [_base(name, node), *(f"{_base(name, node)}.{a.name}"
                                                 for a in node.names)])
            if (t := _known(w)) is not None and t != name
        }  # fmt: skip
    assert not [t for t in _reach(module_level, "corraoi.face.recording") if t.startswith(VIEWER)]


def test_a_plain_record_loads_no_viewer_module(tmp_path: Path):
    """At run time too: ``corraoi.record`` (its summary measured as the blocks go by) loads
    no module of the viewer, nor of the experiments."""
    code = ("import sys, corraoi\n"
            "run = corraoi.record('ucb', 'I1', seed=0, horizon=50, path='a.mcap', rrd=False)\n"
            "assert run.summary.slots == 50\n"
            "print(sorted(m for m in sys.modules if m.startswith('corraoi.viewer')\n"
            "             or m.startswith('corraoi.experiments')))")  # fmt: skip
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=tmp_path, env=env)  # fmt: skip
    assert out.stdout.strip() == "[]"


def test_the_floor_check_sees_strings_and_lazy_tables():
    """The check itself: a module named to ``import_module``, a lazy ``__getattr__`` table's
    relative names and a worker's script are imports; a word that is only a folder's name
    (a git pathspec) is not."""
    code = (
        "import importlib\n"
        "_LAZY = {'RerunSink': 'rerun.sink'}\n"
        "def __getattr__(name):\n"
        "    return importlib.import_module('corraoi.viewer.diffs')\n"
        "WORKER = 'from corraoi.engine import kernels'\n"
        "PATHS = ['corraoi', 'recorder', 'viewer', 'corraoi.cli']\n"
        "SEAM = 'corraoi.face.load:load'\n"
    )
    found = _string_imports("corraoi.recorder", ast.parse(code))
    assert found >= {"corraoi.recorder.rerun.sink", "corraoi.viewer.diffs",
                     "corraoi.engine.kernels", "corraoi.face.load"}  # fmt: skip
    assert not found & {"corraoi", "recorder", "viewer", "corraoi.cli"}
    assert "corraoi.face.recording" in _edges()["corraoi"]  # the package's lazy table
    assert _climbs({"corraoi.recorder.x": {"corraoi.viewer.diffs", "corraoi.engine.block"},
                    "corraoi.viewer.y": {"corraoi.recorder.x", "corraoi.face.load"}}) == {
        "corraoi.recorder.x": ["corraoi.viewer.diffs"],
        "corraoi.viewer.y": ["corraoi.face.load"]}  # fmt: skip


def _in_corraoi_folder(name: str) -> bool:
    """A module of the corraoi/ folder (not of recorder/ or viewer/, installed under it)."""
    return name.startswith("corraoi.") and not name.startswith((RECORDER, VIEWER))


def _rooms(edges: dict[str, set[str]]) -> dict[str, set[str]]:
    """The wings of the corraoi/ folder and the wings each imports."""
    rooms: dict[str, set[str]] = {}
    for src, targets in edges.items():
        if not _in_corraoi_folder(src) or src == "corraoi.__main__":
            continue
        room = rooms.setdefault(_wing(src), set())
        room |= {_wing(t) for t in targets if _in_corraoi_folder(t) and _wing(t) != _wing(src)}
    return rooms


def test_corraois_wings_have_no_circle_and_stand_at_most_8_floors():
    edges = _edges()
    rooms = _rooms(edges)
    assert _circles(rooms) == set()
    floors: dict[str, int] = {}

    def floor(room: str) -> int:
        if room not in floors:
            floors[room] = 1 + max((floor(t) for t in rooms.get(room, ())), default=0)
        return floors[room]

    assert max(floor(r) for r in rooms) <= 8, floors
    # and inside each wing, at most 8 floors as well
    for wing in {r for r in rooms if (ROOT / r.replace(".", "/")).is_dir()}:
        inner = {m: {t for t in edges[m] if t.startswith(wing + ".")} for m in edges
                 if m.startswith(wing + ".")}  # fmt: skip
        depth: dict[str, int] = {}

        def down(m: str, inner: dict[str, set[str]] = inner, depth: dict[str, int] = depth) -> int:
            if m not in depth:
                depth[m] = 1 + max((down(t) for t in inner[m]), default=0)
            return depth[m]

        assert max(map(down, inner), default=0) <= 8, (wing, depth)


def test_the_gpu_backend_knows_nothing_of_the_experiments_even_for_types():
    """The GPU backend runs one policy's runs from plain data; which runs of a grid, in
    which order, is the experiments' (``experiments.backends``): no module of
    ``corraoi.gpu`` names ``corraoi.experiments``, typing imports counted too."""
    edges = _edges(typing=True)
    assert "corraoi.experiments.grid" in edges["corraoi.experiments.backends"]  # they are seen
    gpu = {t for m, ts in edges.items() if m.startswith("corraoi.gpu") for t in ts}
    assert "corraoi.engine.problem" in gpu
    assert {t for t in gpu if t.startswith("corraoi.experiments")} == set()


def test_the_checks_see_a_circle_and_a_climb():
    """The check itself: a made-up circle is found, and the top floor's climbs are seen."""
    assert _circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == {frozenset("abc")}
    edges = _edges()
    assert "corraoi.recorder.slotlog.sink" in edges["corraoi.face.recording"]
    assert "corraoi.engine.block" in edges["corraoi.recorder.slotlog.reader"]
    assert _wing("corraoi.engine.kernels") == "corraoi.engine"
    assert _wing("corraoi.rng") == "corraoi.rng"


def _defined(tree: ast.Module) -> set[str]:
    out = set()
    for node in tree.body:
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            out.add(node.name)
        elif isinstance(node, (ast.Assign, ast.AnnAssign)):
            for t in node.targets if isinstance(node, ast.Assign) else [node.target]:
                out |= {n.id for n in ast.walk(t) if isinstance(n, ast.Name)}
    return out


def test_no_module_re_exports_what_it_imports():
    """A name imported from another module of ours is used where it is imported; it is not
    handed on (listed in ``__all__`` or left unused). A package's ``__init__.py`` is its
    public surface and hands names on by design."""
    shims = {}
    for name, path in MODULES.items():
        if path.name == "__init__.py":
            continue
        tree = ast.parse(path.read_text(encoding="utf-8"))
        used = {n.id for n in ast.walk(tree) if isinstance(n, ast.Name)}
        text = path.read_text(encoding="utf-8")
        exported: set[str] = set()
        for node in tree.body:
            if isinstance(node, ast.Assign) and any(
                isinstance(t, ast.Name) and t.id == "__all__" for t in node.targets
            ):
                exported = {e.value for e in ast.walk(node.value) if isinstance(e, ast.Constant)}
        for node in tree.body:
            if not isinstance(node, ast.ImportFrom):
                continue
            base = _base(name, node)
            if base.split(".")[0] != "corraoi":
                continue
            for a in node.names:
                bind = a.asname or a.name
                if f"{base}.{a.name}" in MODULES:
                    continue  # a module, imported to be used
                quoted = re.search(rf"[\"']{re.escape(bind)}\b", text) is not None
                if bind in exported or (bind not in used and not quoted):
                    shims.setdefault(name, []).append(bind)
    assert shims == {}


def _dotted(node: ast.AST) -> str | None:
    """``a.b.c`` for a chain of names and attributes, else None."""
    if isinstance(node, ast.Name):
        return node.id
    if isinstance(node, ast.Attribute):
        base = _dotted(node.value)
        return None if base is None else f"{base}.{node.attr}"
    return None


def _private(name: str) -> bool:
    return name.startswith("_") and not name.startswith("__")


#: the calls that reach an attribute by its name (``monkeypatch.setattr(x, "_y", ...)``)
_BY_NAME = ("getattr", "setattr", "delattr", "hasattr")


def _private_reaches(name: str, tree: ast.Module) -> list[str]:
    """Where module ``name`` (its ``tree``) uses another module's private name: imported
    (``from x import _y``), or read through a module (``x._y``, ``a.b.x._y``, a
    ``monkeypatch.setattr(x, "_y", ...)``), also in the Python code of a string (a worker's
    ``python -c`` script)."""
    found = []
    modules: dict[str, str] = {}  # a local name or dotted path -> the module it is
    classes: dict[str, str] = {}  # a name imported from another module -> where it is
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            base = _base(name, node)
            if base.split(".")[0] != "corraoi":
                continue
            for a in node.names:
                if f"{base}.{a.name}" in MODULES:
                    modules[a.asname or a.name] = f"{base}.{a.name}"
                elif _private(a.name) and base != name:
                    found.append(f"{name}: from {base} import {a.name}")
                elif base != name:
                    classes[a.asname or a.name] = f"{base}.{a.name}"
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name in MODULES:
                    modules[a.asname or a.name] = a.name
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and _private(node.attr):
            base = _dotted(node.value)
            if base in modules and modules[base] != name:
                found.append(f"{name}: {modules[base]}.{node.attr}")
            made = node.value.func if isinstance(node.value, ast.Call) else node.value
            if isinstance(made, ast.Name) and made.id in classes:  # Class._x, Class()._x
                found.append(f"{name}: {classes[made.id]}.{node.attr}")
        elif (isinstance(node, ast.Call) and len(node.args) >= 2
              and (_dotted(node.func) or "").rpartition(".")[2] in _BY_NAME
              and isinstance(node.args[1], ast.Constant) and isinstance(node.args[1].value, str)
              and _private(node.args[1].value)):  # fmt: skip
            base = _dotted(node.args[0])
            if base in modules and modules[base] != name:
                found.append(f"{name}: {modules[base]}.{node.args[1].value}")
            elif base in classes:
                found.append(f"{name}: {classes[base]}.{node.args[1].value}")
        elif isinstance(node, ast.Constant) and isinstance(node.value, str) \
                and "import" in node.value:  # fmt: skip
            try:
                code = ast.parse(node.value)
            except SyntaxError:
                continue
            found += [f"{f} (in a string)" for f in _private_reaches(name, code)]
    return found


def test_no_module_imports_another_modules_private_names():
    found = []
    for name, path in MODULES.items():
        found += _private_reaches(name, ast.parse(path.read_text(encoding="utf-8")))
    assert found == []


def test_no_test_or_benchmark_imports_a_private_name():
    """Tests and benchmarks use public names only, as any caller does: what a test needs
    has a public name (``partial.fdopen``, the seam faults are injected at), or is tested
    through the public API. (This file is left out: its checks' samples are private.)"""
    found = []
    for folder in ("tests", "benchmarks"):
        for path in sorted((ROOT / folder).rglob("*.py")):
            if path == Path(__file__).resolve():
                continue
            name = ".".join(path.relative_to(ROOT).with_suffix("").parts)
            found += _private_reaches(name, ast.parse(path.read_text(encoding="utf-8")))
    assert found == []


def test_the_private_check_sees_each_way_in():
    """The check itself: an import, a module's attribute, a dotted path, a monkeypatched
    name, a class imported from another module (or its instance) and a worker's script
    each reach a private name; a module's own privates and dunders do not."""
    code = (
        "from corraoi.engine.kernels import _x, __version__\n"
        "from corraoi.engine import kernels\n"
        "import corraoi.engine.kernel_cache\n"
        "kernels._y(); kernels.__doc__\n"
        "corraoi.engine.kernel_cache._z\n"
        "WORKER = 'from corraoi.engine import kernels\\nkernels._w()'\n"
        "monkeypatch.setattr(kernel_cache, '_LOADED', {}); getattr(kernels, '__name__')\n"
        "import corraoi.engine.kernel_cache as kernel_cache\n"
        "from corraoi.gpu.device import EmulatedDevice\n"
        "EmulatedDevice()._b(3); setattr(EmulatedDevice, '_c', None); EmulatedDevice.build\n"
    )
    found = _private_reaches("corraoi.gpu.device", ast.parse(code))
    assert sorted(found) == [
        "corraoi.gpu.device: corraoi.engine.kernel_cache._LOADED",
        "corraoi.gpu.device: corraoi.engine.kernel_cache._z",
        "corraoi.gpu.device: corraoi.engine.kernels._w (in a string)",
        "corraoi.gpu.device: corraoi.engine.kernels._y",
        "corraoi.gpu.device: from corraoi.engine.kernels import _x",
    ]
    assert sorted(_private_reaches("corraoi.engine.kernels", ast.parse(code))) == [
        "corraoi.engine.kernels: corraoi.engine.kernel_cache._LOADED",
        "corraoi.engine.kernels: corraoi.engine.kernel_cache._z",
        "corraoi.engine.kernels: corraoi.gpu.device.EmulatedDevice._b",
        "corraoi.engine.kernels: corraoi.gpu.device.EmulatedDevice._c",
    ]


def test_no_string_names_a_module_of_recorder_or_viewer_below_the_top_floor():
    """No string seam: below the top floor, no string names a module of the recorder or the
    viewer (``"corraoi.recorder.x:f"``) to be imported later; what the layers below need
    from above is handed down (a trace channel's readers, a sweep folder's outputs)."""
    pattern = r"[\"']((?:corraoi\.recorder|corraoi\.viewer)(?:\.\w+)+(?::\w+)?)[\"']"
    for mod, path in MODULES.items():
        if not mod.startswith("corraoi") or _is_top(mod):
            continue
        found = re.findall(pattern, path.read_text(encoding="utf-8"))
        assert not found, (mod, found)


#: A package's ``__init__.py`` is its front. ``corraoi.cli``'s is the command group itself
#: (the console script's ``main``), not a front.
FRONTS = sorted(m for m, p in MODULES.items() if p.name == "__init__.py" and m != "corraoi.cli")
CALLERS = ("corraoi", "recorder", "viewer", "tests", "benchmarks")


def _exported(path: Path) -> list[str] | None:
    """A front's ``__all__`` (None without one)."""
    for node in ast.parse(path.read_text(encoding="utf-8")).body:
        if isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id == "__all__" for t in node.targets
        ):
            return [e.value for e in ast.walk(node.value) if isinstance(e, ast.Constant)]
    return None


def _through_fronts() -> dict[str, set[str]]:
    """Each front and the names its callers take through it: ``from front import x``,
    ``front.x`` (also through an alias), in the code of the three folders, the tests and the
    benchmarks (the front itself left out), and in the docs' and README's examples."""
    exported = {f: set(_exported(MODULES[f]) or ()) for f in FRONTS}
    used: dict[str, set[str]] = {f: set() for f in FRONTS}
    for folder in CALLERS:
        for path in (ROOT / folder).rglob("*.py"):
            name = module_name(path)
            tree = ast.parse(path.read_text(encoding="utf-8"))
            alias: dict[str, str] = {}
            for node in ast.walk(tree):
                if isinstance(node, ast.ImportFrom):
                    base = _base(name, node) if name in MODULES or not node.level else ""
                    for a in node.names:
                        sub = f"{base}.{a.name}"
                        if base in used and base != name and (
                            a.name in exported[base] or sub not in MODULES
                        ):
                            used[base].add(a.name)
                        elif sub in used:
                            alias[a.asname or a.name] = sub
                elif isinstance(node, ast.Import):
                    for a in node.names:  # `import x.y` binds x, and x.y.z is read as is
                        if a.asname and a.name in used:
                            alias[a.asname] = a.name
            for node in ast.walk(tree):
                if isinstance(node, ast.Attribute):
                    base = _dotted(node.value)
                    base = alias.get(base or "", base) if base not in used else base
                    if base in used and base != name:
                        used[base].add(node.attr)
    docs = "\n".join(p.read_text(encoding="utf-8")
                     for p in [ROOT / "README.md", *(ROOT / "docs").glob("*.md")]
                     if p.name != "changelog.md")  # history, not examples  # fmt: skip
    for front in FRONTS:
        for names in re.findall(rf"from {re.escape(front)} import ([\w, ]+)", docs):
            used[front] |= {n.strip() for n in names.split(",")}
        used[front] |= set(re.findall(rf"\b(?<![\w.]){re.escape(front)}\.(\w+)", docs))
    return used


def test_a_wings_front_names_its_public_api_or_is_empty():
    """A front either names its public API (``__all__``, what its callers import from it)
    or holds its docstring only, its callers importing its modules (docs/architecture.md
    says which)."""
    wrong = []
    for front in FRONTS:
        body = ast.parse(MODULES[front].read_text(encoding="utf-8")).body
        rest = [n for n in body[1:] if not (isinstance(n, ast.ImportFrom)
                                            and n.module == "__future__")]  # fmt: skip
        if rest and _exported(MODULES[front]) is None:
            wrong.append(front)
    assert wrong == []


def test_no_front_exports_a_name_nobody_imports():
    used = _through_fronts()
    unused = {f: sorted(set(_exported(MODULES[f]) or ()) - used[f]) for f in FRONTS}
    assert {f: names for f, names in unused.items() if names} == {}


def test_the_front_check_sees_each_way_through():
    used = _through_fronts()
    assert "make_policy" in used["corraoi.policies"]  # from corraoi.policies import make_policy
    assert "record" in used["corraoi"]  # corraoi.record(...)
    assert "get_device" in used["corraoi.gpu"]


@pytest.mark.parametrize(
    "wing",
    sorted(m for m, p in MODULES.items() if p.name == "__init__.py" and m.count(".") == 1),
)
def test_a_wings_init_imports_nothing_heavy(wing: str):
    code = (f"import sys, json; import {wing}; "
            f"print(json.dumps(sorted(m for m in {HEAVY!r} if m in sys.modules)))")  # fmt: skip
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         check=True, cwd=ROOT)  # fmt: skip
    assert json.loads(out.stdout) == []
