"""docs/architecture.md stays true: every module it names exists, and every module of the
three packages is named there (a new module gets its line, a removed one loses it)."""

from __future__ import annotations

import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DOC = ROOT / "docs" / "architecture.md"
PACKAGES = ("corraoi", "recorder", "viewer")


def _named() -> set[str]:
    """Paths the page names: `pkg/.../x.py` in full, or `x.py` under its section's folder."""
    text = DOC.read_text()
    found: set[str] = set()
    folder = None
    for para in re.split(r"\n\s*\n", text):
        head = re.match(r"\*\*`([a-z_/]+/)`", para)
        folder = head.group(1) if head else None
        for name in re.findall(r"`([A-Za-z0-9_./]+\.(?:py|cu))`", para):
            if "/" in name:
                found.add(name)
            elif folder is not None:
                found.add(folder + name)
        for sub in re.findall(r"`([a-z_]+/)` \(([^)]*)\)", para):  # `gpu/` (`runner.py`, ...)
            for name in re.findall(r"([A-Za-z0-9_]+\.(?:py|cu))", sub[1]):
                found.add((folder or "") + sub[0] + name)
    return found


def test_every_module_the_page_names_exists():
    text = DOC.read_text()
    full = set(re.findall(r"`((?:corraoi|recorder|viewer)/[A-Za-z0-9_./]+\.(?:py|cu))`", text))
    assert full, "the page names no module by path"
    missing = sorted(p for p in full if not (ROOT / p).is_file())
    assert not missing, f"docs/architecture.md names modules that do not exist: {missing}"


def test_every_module_is_on_the_page():
    named = _named()
    modules = [
        str(p.relative_to(ROOT))
        for pkg in PACKAGES
        for p in sorted((ROOT / pkg).rglob("*"))
        if p.suffix in (".py", ".cu") and "__pycache__" not in p.parts
        and p.name not in ("__init__.py", "__main__.py", "_version.py")
    ]  # fmt: skip
    absent = [m for m in modules if m not in named]
    assert not absent, f"docs/architecture.md does not place these modules: {absent}"
