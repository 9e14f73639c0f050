"""Scripts of the checkout (tests/golden/regenerate.py, docs/examples/*.py) loaded as modules,
so that a test calls their functions rather than running them in a subprocess."""

from __future__ import annotations

import importlib.util
from pathlib import Path
from types import ModuleType

ROOT = Path(__file__).resolve().parent.parent


def load_script(path: str | Path) -> ModuleType:
    """The script at ``path`` (relative to the checkout's root) as a fresh module."""
    full = ROOT / path
    spec = importlib.util.spec_from_file_location(full.stem, full)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module
