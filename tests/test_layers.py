"""The house's imports (issue 23): corraoi's core < recorder < viewer, and no import circles.

Every import of the three packages is read from the source (module level and inside
functions; ``if TYPE_CHECKING:`` blocks are typing only and left out). An import that climbs
a layer is allowed only from the command line (``corraoi/cli/``), ``corraoi/testing.py`` and
``corraoi/face/tables.py`` (the lazy ``corraoi.load``). What is still owed is listed below with
why: the test fails on a new climb or circle, and on a listed one that has been paid (so
that the list stays true)."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
LAYERS = {"corraoi": 0, "recorder": 1, "viewer": 2}
#: the issue's exceptions: they compose the layers for a user
MAY_CLIMB = ("corraoi.cli", "corraoi.testing", "corraoi.face.tables")
#: owed climbs (issue 23): none left
OWED_CLIMBS: set[str] = set()
#: owed circles: none left
OWED_CIRCLES: set[frozenset[str]] = set()


def _modules() -> dict[str, Path]:
    out = {}
    for pkg in LAYERS:
        for path in (ROOT / pkg).rglob("*.py"):
            parts = path.relative_to(ROOT).with_suffix("").parts
            out[".".join(parts[:-1] if parts[-1] == "__init__" else parts)] = path
    return out


def _runtime_imports(tree: ast.Module) -> list[ast.Import | ast.ImportFrom]:
    found: list[ast.Import | ast.ImportFrom] = []

    def visit(node: ast.AST) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, ast.If) and "TYPE_CHECKING" in ast.unparse(child.test):
                for other in child.orelse:
                    visit(other)
                continue
            if isinstance(child, (ast.Import, ast.ImportFrom)):
                found.append(child)
            visit(child)

    visit(tree)
    return found


def _edges() -> dict[str, set[str]]:
    mods = _modules()

    def known(name: str) -> str | None:
        while name and name not in mods:
            name = name.rpartition(".")[0]
        return name or None

    edges: dict[str, set[str]] = {}
    for name, path in mods.items():
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        targets: set[str] = set()
        for node in _runtime_imports(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                wanted = [a.name for a in node.names]
            else:
                base = node.module or ""
                if node.level:
                    up = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                    base = ".".join(up + ([node.module] if node.module else []))
                subs = [f"{base}.{a.name}" for a in node.names]
                # `from . import x` of submodules depends on them, not on the package itself
                wanted = subs if all(s in mods for s in subs) else [base, *subs]
            targets |= {t for w in wanted if (t := known(w)) is not None and t != name}
        edges[name] = targets
    return edges


def _circles(edges: dict[str, set[str]]) -> set[frozenset[str]]:
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    out: set[frozenset[str]] = set()

    def strong(v: str) -> None:  # Tarjan
        index[v] = low[v] = len(index)
        stack.append(v)
        for w in edges[v]:
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

    for v in edges:
        if v not in index:
            strong(v)
    return out


def test_imports_only_go_down_outside_the_named_exceptions():
    climbs = {
        src: sorted(t for t in targets if LAYERS[t.split(".")[0]] > LAYERS[src.split(".")[0]])
        for src, targets in _edges().items()
    }
    climbing = {src for src, up in climbs.items() if up}
    new = {s: climbs[s] for s in climbing
           if not s.startswith(MAY_CLIMB) and s not in OWED_CLIMBS}  # fmt: skip
    assert not new, f"imports that climb a layer: {new}"
    assert OWED_CLIMBS <= climbing, f"paid, take off OWED_CLIMBS: {OWED_CLIMBS - climbing}"


def test_no_import_circle_beyond_those_owed():
    circles = _circles(_edges())
    assert circles - OWED_CIRCLES == set(), "new import circles"
    assert OWED_CIRCLES - circles == set(), "circles paid (or changed): update OWED_CIRCLES"


def test_the_walker_sees_a_circle_and_a_climb():
    """The check itself: a made-up circle is found, and corraoi.cli's climbs are seen."""
    assert _circles({"a": {"b"}, "b": {"c"}, "c": {"a"}, "d": {"a"}}) == {frozenset("abc")}
    edges = _edges()
    assert "recorder.slotlog.reader" in edges["corraoi.cli.record_plan"]
    assert "corraoi.engine.block" in edges["recorder.slotlog.reader"]


def test_the_seams_the_core_names_by_string_resolve_upward_only_there():
    """The declared seams: the core names a reader or writer of the layers above by string,
    imported only when it is used (as fsspec names file systems), instead of importing it:
    a trace channel's slot-log reader (recorder) and a sweep folder's default outputs
    (viewer, which writes the recorder's formats and the figure). Each name must resolve,
    to the layer it claims; no other string names a module of recorder or viewer."""
    import importlib
    import re

    from corraoi.experiments.sweeps import DEFAULT_OUTPUTS
    from corraoi.model.channels import TRACE_READERS

    seams = {**{f"trace {k}": v for k, v in TRACE_READERS.items()}, "outputs": DEFAULT_OUTPUTS}
    for what, name in seams.items():
        module, _, attr = name.partition(":")
        assert module.split(".")[0] in ("recorder", "viewer"), (what, name)
        assert callable(getattr(importlib.import_module(module), attr)), (what, name)
    named = set(seams.values())
    for mod, path in _modules().items():
        if LAYERS[mod.split(".")[0]] or mod.startswith(MAY_CLIMB):
            continue
        for text in re.findall(r"[\"']((?:recorder|viewer)\.[\w.]+:\w+)[\"']", path.read_text()):
            assert text in named, (mod, text)


def test_no_module_is_over_400_lines():
    """One job per module (issue 23): none of the three packages' modules is over 400 lines."""
    long = {str(p.relative_to(ROOT)): n for p in _modules().values()
            if (n := len(p.read_text(encoding="utf-8").splitlines())) > 400}  # fmt: skip
    assert long == {}
