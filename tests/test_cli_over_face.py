"""The command line stands over the face (issue 41, item 3): every module of ``corraoi/cli``
imports only the face (``corraoi.face.*`` and the top-level ``corraoi`` names), click, the
command line's own helpers and the ground floor's ``errors``, ``_version``, ``_signals``,
``text``, ``progress``, ``limits`` and ``extras``. Every import is read from the source,
at module level and inside functions (typing-only imports too: a type is a name as well).
"""

from __future__ import annotations

import ast
from pathlib import Path

import corraoi

ROOT = Path(__file__).resolve().parent.parent
CLI = ROOT / "corraoi" / "cli"
#: the ground floor a command may name
GROUND = ("errors", "_version", "_signals", "text", "progress", "limits", "extras")


def _imports(path: Path) -> list[tuple[int, str]]:
    """Every module ``path`` imports, with its line: ``import a.b`` -> ``a.b``; ``from a
    import b`` -> ``a.b`` (a module or a name in it); relative imports made absolute."""
    package = "corraoi.cli"
    found = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                up = package.split(".")[: len(package.split(".")) - (node.level - 1)]
                base = ".".join(up + ([node.module] if node.module else []))
            else:
                base = node.module or ""
            found += [(node.lineno, f"{base}.{a.name}") for a in node.names]
        elif isinstance(node, ast.Call) and getattr(node.func, "id", None) == "__import__":
            found += [(node.lineno, a.value) for a in node.args[:1]
                      if isinstance(a, ast.Constant) and isinstance(a.value, str)]  # fmt: skip
    return found


def _allowed(module: str) -> bool:
    parts = module.split(".")
    if parts[0] != "corraoi" or len(parts) == 1:
        return True  # the standard library, click and other third parties
    if parts[1] in ("face", "cli") or parts[1] in GROUND:
        return True
    # `from corraoi import X`: a top-level name of the face
    return len(parts) == 2 and parts[1] in corraoi.__all__


def _climbs() -> dict[str, list[str]]:
    wrong: dict[str, list[str]] = {}
    for path in sorted(CLI.rglob("*.py")):
        bad = [f"{line}: {m}" for line, m in _imports(path) if not _allowed(m)]
        if bad:
            wrong[path.name] = bad
    return wrong


def test_the_command_line_imports_only_the_face_and_the_ground_floor():
    assert _climbs() == {}


def test_the_check_sees_every_way_in(tmp_path):
    """The check itself: a module-level import, one inside a function, a relative one and an
    ``__import__`` string are each seen; the face and the ground floor pass."""
    code = (
        "import json\nimport click\nfrom corraoi.errors import UsageError\n"
        "from corraoi import limits, errors\nfrom . import common\nfrom .common import say\n"
        "from corraoi.face.views import info\nimport corraoi.face.runs\n"
        "def f():\n    from corraoi.recorder.export import export\n    import corraoi.viewer.info\n"
        "    from corraoi.engine import kernels\n    from corraoi import gpu\n"
        "X = __import__('corraoi.model.theory')\n"
    )
    path = tmp_path / "x.py"
    path.write_text(code, encoding="utf-8")
    bad = [m for _, m in _imports(path) if not _allowed(m)]
    assert bad == ["corraoi.recorder.export.export", "corraoi.viewer.info",
                   "corraoi.engine.kernels", "corraoi.gpu", "corraoi.model.theory"]  # fmt: skip


def test_what_the_log_commands_do_is_the_faces(tmp_path):
    """``info``, ``recover``, ``replay`` and ``export`` are face functions first: from Python
    they give what the commands print."""
    import json

    from click.testing import CliRunner

    from corraoi.cli import main

    run = corraoi.record("cucb", "I1", seed=2, horizon=300, path=tmp_path / "r.mcap", rrd=False)
    found = corraoi.info(run)
    assert found.to_dict()["slots"] == 300 and found.to_dict()["status"] == "complete"
    printed = CliRunner().invoke(main, ["info", str(run.path), "--json"])
    assert printed.exit_code == 0 and json.loads(printed.output) == found.to_dict()
    table = CliRunner().invoke(main, ["info", str(run.path)])
    assert table.exit_code == 0 and table.output.rstrip("\n") == found.text().rstrip("\n")
    done = corraoi.replay(run, tmp_path / "r.rrd")
    assert (done.slots, done.horizon, done.path) == (300, 300, tmp_path / "r.rrd")
    assert done.path.stat().st_size > 0
    fixed = corraoi.recover(run, tmp_path / "fixed.mcap")
    assert (fixed.slots, fixed.source_status, fixed.status) == (300, "complete", "complete")
    assert corraoi.load(fixed.path).summary.regret == run.summary.regret
    table = corraoi.export(run, tmp_path / "t.csv")
    assert table.rows == 300 and (tmp_path / "t.csv").read_text().count("\n") == 301


def _counting_face_calls(monkeypatch) -> list[str]:
    """Every function of every face module wrapped: a call made from a command's module of
    ``corraoi/cli`` is listed (not the group's set-up in ``corraoi/cli/__init__.py``, the
    same for every command, nor the calls the face makes into itself)."""
    import functools
    import importlib
    import inspect
    import pkgutil
    import sys

    import corraoi.face

    calls: list[str] = []

    def counted(func, name):
        @functools.wraps(func)
        def wrapper(*args, **kwargs):
            caller = sys._getframe(1).f_globals.get("__name__", "")
            if caller.startswith("corraoi.cli."):
                calls.append(name)
            return func(*args, **kwargs)

        return wrapper

    for info in pkgutil.iter_modules(corraoi.face.__path__):
        module = importlib.import_module(f"corraoi.face.{info.name}")
        for name, value in list(vars(module).items()):
            if inspect.isfunction(value) and value.__module__ == module.__name__:
                monkeypatch.setattr(module, name, counted(value, f"{info.name}.{name}"))
    return calls


def test_record_sweep_and_reproduce_call_the_face_once(tmp_path, monkeypatch):
    """``record`` (given runs, runs up to date, runs ``--from`` a sweep), ``sweep`` (a
    table, a folder) and ``reproduce`` each parse, make one call into the face, and
    print."""
    from click.testing import CliRunner

    from corraoi.cli import main

    calls = _counting_face_calls(monkeypatch)
    sweep = str(tmp_path / "sw")
    log = str(tmp_path / "r.mcap")
    commands = [
        ["record", "-p", "ucb", "-T", "40", "--no-rrd", "-o", log],
        ["record", "-p", "ucb", "-T", "40", "--no-rrd", "-o", log, "--json"],
        ["sweep", "-p", "ucb,cucb", "-n", "3", "-T", "40", "--json"],
        ["sweep", "-p", "ucb", "-n", "3", "-T", "40", "-o", sweep],
        ["record", "--from", sweep, "--run", "worst", "--no-rrd", "-o",
         str(tmp_path / "{from}.mcap")],
        # (reproduce decentralized takes the same face call: its sweep's kernels of many
        # sources cost minutes to compile here, once)
        ["reproduce", "-n", "2", "-T", "40", "-o", str(tmp_path / "paper")],
    ]  # fmt: skip
    made = {}
    for args in commands:
        calls.clear()
        done = CliRunner().invoke(main, args)
        assert done.exit_code == 0, (args, done.output)
        made[" ".join(a for a in args if str(tmp_path) not in a)] = list(calls)
    assert {k: len(v) for k, v in made.items()} == dict.fromkeys(made, 1), made
