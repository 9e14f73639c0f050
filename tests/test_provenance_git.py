"""The git commit a log records (issue 41, "start-up given back"): read from ``.git`` with no
process on the way, "+dirty" as ``git status`` says of the packages, and git asked again only
when something that can change its answer changed."""

from __future__ import annotations

import os
import subprocess
import time
from pathlib import Path

import pytest

from corraoi.provenance import git_commit

GIT = ["git", "-c", "user.name=t", "-c", "user.email=t@example.org", "-c", "init.defaultBranch=x"]


def _git(root: Path, *args: str) -> str:
    res = subprocess.run([*GIT, "-C", str(root), *args], capture_output=True, text=True)
    assert res.returncode == 0, res.stderr
    return res.stdout.strip()


def _age(root: Path) -> None:
    """Every file of the checkout changed a minute ago: none is young enough to be racy."""
    old = time.time() - 60
    for path in root.rglob("*"):
        if ".git" not in path.parts:
            os.utime(path, (old, old))


@pytest.fixture
def checkout(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    monkeypatch.setenv("CORRAOI_CACHE_DIR", str(tmp_path / "cache"))
    root = tmp_path / "co"
    for rel in ("corraoi/a.py", "corraoi/sub/b.py", "recorder/c.py", "viewer/d.py", "README.md"):
        (root / rel).parent.mkdir(parents=True, exist_ok=True)
        (root / rel).write_text(f"# {rel}\n")
    (root / ".gitignore").write_text("__pycache__/\n*.py[cod]\n")
    _git(root, "init", "-q")
    _git(root, "add", ".")
    _git(root, "commit", "-qm", "one")
    _age(root)
    return root


@pytest.fixture
def gits(monkeypatch: pytest.MonkeyPatch) -> list[list[str]]:
    """Every process started (git's arguments), recorded."""
    started: list[list[str]] = []
    run = subprocess.run

    def counted(args, *a, **k):  # type: ignore[no-untyped-def]
        started.append(list(args))
        return run(args, *a, **k)

    monkeypatch.setattr(subprocess, "run", counted)
    return started


def test_the_commit_is_read_without_git_and_gits_dirty_answer_is_kept(checkout, gits):
    head = _git(checkout, "rev-parse", "HEAD")
    gits.clear()
    assert git_commit(checkout) == head
    assert [a[3:4] for a in gits] == [["status"]]  # the first time: git status, once
    gits.clear()
    assert git_commit(checkout) == head and git_commit(checkout) == head
    assert gits == []  # then no process at all

    (checkout / "README.md").write_text("outside the packages\n")
    assert git_commit(checkout) == head and gits == []

    (checkout / "corraoi" / "sub" / "b.py").write_text("# edited\n")
    assert git_commit(checkout) == head + "+dirty"
    assert len(gits) == 1
    _git(checkout, "add", "corraoi")
    assert git_commit(checkout) == head + "+dirty"  # staged, not committed
    _git(checkout, "commit", "-qm", "two")
    two = _git(checkout, "rev-parse", "HEAD")
    assert two != head and git_commit(checkout) == two

    (checkout / "viewer" / "new.py").write_text("# untracked\n")
    assert git_commit(checkout) == two + "+dirty"
    (checkout / "viewer" / "new.py").unlink()
    (checkout / "recorder" / "c.py").unlink()
    assert git_commit(checkout) == two + "+dirty"  # deleted
    _git(checkout, "checkout", "-q", "--", "recorder")
    pycache = checkout / "viewer" / "__pycache__"
    pycache.mkdir()
    (pycache / "d.cpython-311.pyc").write_bytes(b"\0" * 16)  # bytecode is not code
    assert git_commit(checkout) == two


def test_a_same_size_edit_right_after_is_seen_and_young_files_are_not_kept(checkout, gits):
    head = _git(checkout, "rev-parse", "HEAD")
    path = checkout / "corraoi" / "a.py"
    assert git_commit(checkout) == head
    path.write_text("# corraoi/b.py\n")  # as long as before, within the same second
    assert git_commit(checkout) == head + "+dirty"
    path.write_text("# corraoi/a.py\n")
    gits.clear()
    assert git_commit(checkout) == head  # young files: git asked, its answer not kept
    assert git_commit(checkout) == head and [a[3:4] for a in gits] == [["status"]] * 2
    _age(checkout)
    assert git_commit(checkout) == head and git_commit(checkout) == head
    assert len(gits) == 3  # aged: asked once more, then kept


def test_a_worktree_packed_refs_and_a_detached_head(checkout, gits, tmp_path: Path):
    head = _git(checkout, "rev-parse", "HEAD")
    _git(checkout, "pack-refs", "--all")
    assert not (checkout / ".git" / "refs" / "heads" / "x").exists()
    gits.clear()
    assert git_commit(checkout) == head
    assert all(a[3] != "rev-parse" for a in gits)  # packed-refs read from the file

    wt = tmp_path / "wt"
    _git(checkout, "worktree", "add", "-q", "-b", "side", str(wt))
    assert (wt / ".git").is_file()
    _age(wt)
    assert git_commit(wt) == head
    (wt / "corraoi" / "a.py").write_text("# changed in the worktree\n")
    assert git_commit(wt) == head + "+dirty" and git_commit(checkout) == head

    _git(checkout, "checkout", "-q", "--detach", "HEAD")
    gits.clear()
    assert git_commit(checkout) == head
    assert all(a[3] != "rev-parse" for a in gits)


def test_no_checkout_no_commit(tmp_path: Path):
    (tmp_path / "corraoi").mkdir()
    assert git_commit(tmp_path) is None
    (tmp_path / ".git").write_text("gitdir: nowhere\n")
    assert git_commit(tmp_path) is None
