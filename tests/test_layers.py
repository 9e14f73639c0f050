"""The house's structure (issue 34), read from the source of the three packages.

Every import is counted, at module level and inside functions (``if TYPE_CHECKING:`` blocks
are typing only and left out):

* the module graph across ``corraoi``, ``recorder`` and ``viewer`` has no cycle;
* only the top floor (``corraoi.face``, ``corraoi.cli``, ``corraoi.testing``,
  ``corraoi.pytest_plugin`` and the package's lazy ``__init__``) imports ``recorder`` or
  ``viewer``; the recorder never imports the viewer, nor the core's top floor;
* the wings of ``corraoi`` (its folders, and its ground-floor modules) import each other
  without a circle, and stand at most 8 floors high;
* no module re-exports a name it imports (a wing's ``__init__.py`` is its public surface),
  no module imports another's private name, and no string names a module of the layers
  above to be imported later;
* a wing's ``__init__.py`` imports nothing heavy.
"""

from __future__ import annotations

import ast
import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = ("corraoi", "recorder", "viewer")
#: what composes the layers for a user: the only modules that import recorder or viewer
TOP = ("corraoi.face", "corraoi.cli", "corraoi.testing", "corraoi.pytest_plugin")
HEAVY = ("numba", "rerun", "pandas", "pyarrow", "matplotlib")
#: What is still owed, with why; each is paid in this round and taken off (the tests fail on a
#: debt that is paid but still listed, so that the list stays true).
OWED_CLIMBS: dict[str, str] = {}


def _modules() -> dict[str, Path]:
    out = {}
    for pkg in PACKAGES:
        for path in (ROOT / pkg).rglob("*.py"):
            parts = path.relative_to(ROOT).with_suffix("").parts
            out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


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
    package = name if MODULES[name].name == "__init__.py" else name.rpartition(".")[0]
    up = package.split(".")[: len(package.split(".")) - (node.level - 1)]
    return ".".join(up + ([node.module] if node.module else []))


def _known(name: str) -> str | None:
    while name and name not in MODULES:
        name = name.rpartition(".")[0]
    return name or None


def _edges(typing: bool = False) -> dict[str, set[str]]:
    edges: dict[str, set[str]] = {}
    for name, path in MODULES.items():
        targets: set[str] = set()
        for node in _runtime_imports(ast.parse(path.read_text(encoding="utf-8")), typing):
            if isinstance(node, ast.Import):
                wanted = [a.name for a in node.names]
            else:
                base = _base(name, node)
                subs = [f"{base}.{a.name}" for a in node.names]
                # `from . import x` of submodules depends on them, not on the package itself
                wanted = subs if all(s in MODULES for s in subs) else [base, *subs]
            targets |= {t for w in wanted if (t := _known(w)) is not None and t != name}
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


def test_only_the_top_floor_imports_the_recorder_or_the_viewer():
    wrong = {}
    for src, targets in _edges().items():
        pkg = src.split(".")[0]
        bad = sorted(
            t for t in targets
            if (pkg == "corraoi" and not _is_top(src) and t.split(".")[0] != "corraoi")
            or (pkg == "recorder" and (t.startswith("viewer") or _is_top(t)))
            or (pkg == "viewer" and _is_top(t))
        )  # fmt: skip
        if bad:
            wrong[src] = bad
    assert set(wrong) - set(OWED_CLIMBS) == set(), wrong
    assert set(OWED_CLIMBS) <= set(wrong), "paid: take it off OWED_CLIMBS"


def _rooms(edges: dict[str, set[str]]) -> dict[str, set[str]]:
    """The wings of ``corraoi`` and the wings each imports."""
    rooms: dict[str, set[str]] = {}
    for src, targets in edges.items():
        if not src.startswith("corraoi.") or src == "corraoi.__main__":
            continue
        room = rooms.setdefault(_wing(src), set())
        room |= {_wing(t) for t in targets if t.startswith("corraoi.") and _wing(t) != _wing(src)}
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
    assert "recorder.slotlog.sink" in edges["corraoi.face.recording"]
    assert "corraoi.engine.block" in edges["recorder.slotlog.reader"]
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
            if base.split(".")[0] not in PACKAGES:
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


def _private_reaches(name: str, tree: ast.Module) -> list[str]:
    """Where module ``name`` (its ``tree``) uses another module's private name: imported
    (``from x import _y``), or read through a module (``x._y``, ``a.b.x._y``), also in the
    Python code of a string (a worker's ``python -c`` script)."""
    found = []
    modules: dict[str, str] = {}  # a local name or dotted path -> the module it is
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            base = _base(name, node)
            if base.split(".")[0] not in PACKAGES:
                continue
            for a in node.names:
                if f"{base}.{a.name}" in MODULES:
                    modules[a.asname or a.name] = f"{base}.{a.name}"
                elif _private(a.name) and base != name:
                    found.append(f"{name}: from {base} import {a.name}")
        elif isinstance(node, ast.Import):
            for a in node.names:
                if a.name in MODULES:
                    modules[a.asname or a.name] = a.name
    for node in ast.walk(tree):
        if isinstance(node, ast.Attribute) and _private(node.attr):
            base = _dotted(node.value)
            if base in modules and modules[base] != name:
                found.append(f"{name}: {modules[base]}.{node.attr}")
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


def test_the_private_check_sees_each_way_in():
    """The check itself: an import, a module's attribute, a dotted path and a worker's
    script each reach a private name; a module's own privates and dunders do not."""
    code = (
        "from corraoi.engine.kernels import _x, __version__\n"
        "from corraoi.engine import kernels\n"
        "import corraoi.engine.kernel_cache\n"
        "kernels._y(); kernels.__doc__\n"
        "corraoi.engine.kernel_cache._z\n"
        "WORKER = 'from corraoi.engine import kernels\\nkernels._w()'\n"
    )
    found = _private_reaches("corraoi.gpu.device", ast.parse(code))
    assert sorted(found) == [
        "corraoi.gpu.device: corraoi.engine.kernel_cache._z",
        "corraoi.gpu.device: corraoi.engine.kernels._w (in a string)",
        "corraoi.gpu.device: corraoi.engine.kernels._y",
        "corraoi.gpu.device: from corraoi.engine.kernels import _x",
    ]
    assert _private_reaches("corraoi.engine.kernels", ast.parse(code))[1:] == []


def test_no_string_names_a_module_of_recorder_or_viewer_below_the_top_floor():
    """No string seam: below the top floor, no string names a module of the recorder or the
    viewer (``"recorder.x:f"``) to be imported later; what the layers below need from above
    is handed down (a trace channel's readers, a sweep folder's outputs)."""
    pattern = r"[\"']((?:recorder|viewer)(?:\.\w+)+(?::\w+)?)[\"']"
    for mod, path in MODULES.items():
        if not mod.startswith("corraoi") or _is_top(mod):
            continue
        found = re.findall(pattern, path.read_text(encoding="utf-8"))
        assert not found, (mod, found)


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
