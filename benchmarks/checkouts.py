"""The code a benchmark times: one checkout's packages, whatever its layout.

A checkout keeps ``recorder/`` and ``viewer/`` beside ``corraoi/``; an install makes them
``corraoi.recorder`` and ``corraoi.viewer``. The checkout's folder on PYTHONPATH is not
enough to run its code: ``corraoi`` comes from there, but nothing there maps the two
subpackages, so the installed corraoi's import hook (an editable install maps them onto
*its* checkout) gives a child another checkout's recorder and viewer beside this one's
engine, and a comparison times a mix of the two without a word. A checkout from before
the one-package layout (224f28d, 2347ea6) imports them as top-level ``recorder`` and
``viewer``, while today's benchmark scripts ask for ``corraoi.recorder``.

:func:`pythonpath` gives the PYTHONPATH that runs one checkout's code: a folder with a
``sitecustomize.py`` that puts a finder first in ``sys.meta_path``, mapping ``corraoi``,
``corraoi.recorder`` and ``corraoi.viewer`` onto the checkout's folders (in the older layout,
``corraoi.recorder`` and ``corraoi.viewer`` onto its top-level packages), then the checkout
itself.
"""

from __future__ import annotations

import hashlib
import os
import tempfile
from pathlib import Path

#: The subpackages an install maps from the checkout's top-level folders.
MAPPED = ("recorder", "viewer")

_SHIM = '''\
# written by benchmarks/checkouts.py: run the code of the checkout {root!r}, not the
# installed corraoi's (the benchmark's child processes start with this folder on PYTHONPATH)
import importlib
import importlib.abc
import importlib.util
import sys

ROOT = {root!r}
MAPPED = {mapped!r}
OLD_LAYOUT = {old!r}  # its recorder and viewer are top-level packages


class _Alias(importlib.abc.Loader):
    """corraoi.recorder.x of an older checkout: its module recorder.x itself."""

    def __init__(self, old):
        self.old = old

    def create_module(self, spec):
        return importlib.import_module(self.old)

    def exec_module(self, module):
        pass


class _Checkout(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        sub = name.split(".")
        if name == "corraoi":
            folder = ROOT + "/corraoi"
        elif sub[0] != "corraoi" or sub[1] not in MAPPED:
            return None  # another package, or corraoi's own subpackages (its __path__)
        else:
            if OLD_LAYOUT:
                old = ".".join(sub[1:])
                spec = importlib.util.find_spec(old)
                if spec is None:
                    return None
                return importlib.util.spec_from_loader(
                    name, _Alias(old), is_package=spec.submodule_search_locations is not None)
            if len(sub) > 2:
                return None  # found by the usual finders in the package's own __path__
            folder = ROOT + "/" + sub[1]
        return importlib.util.spec_from_file_location(
            name, folder + "/__init__.py", submodule_search_locations=[folder])


sys.meta_path.insert(0, _Checkout())
'''


def old_layout(root: Path) -> bool:
    """Whether the checkout's code imports ``recorder`` and ``viewer`` as top-level packages
    (before the one-package layout): none of its modules names ``corraoi.recorder``."""
    for path in (root / "corraoi").rglob("*.py"):
        text = path.read_text(encoding="utf-8", errors="replace")
        if "corraoi.recorder" in text or "corraoi.viewer" in text:
            return False
    return True


def pythonpath(root: Path) -> str:
    """The PYTHONPATH of a process that runs the code of the checkout ``root`` (module
    docstring); its shim folder is made once per checkout, in the temp folder."""
    root = root.resolve()
    if not (root / "corraoi" / "__init__.py").is_file():
        raise SystemExit(f"{root}: no corraoi/ package there (expected a checkout of corraoi)")
    mapped = tuple(m for m in MAPPED if (root / m / "__init__.py").is_file())
    shim = _SHIM.format(root=str(root), mapped=mapped, old=old_layout(root))
    key = hashlib.sha256(shim.encode()).hexdigest()[:16]
    folder = Path(tempfile.gettempdir()) / f"corraoi-bench-checkout-{key}"
    if not (folder / "sitecustomize.py").is_file():
        folder.mkdir(parents=True, exist_ok=True)
        tmp = folder / f".sitecustomize.{key}.tmp"
        tmp.write_text(shim, encoding="utf-8")
        tmp.replace(folder / "sitecustomize.py")
    return os.pathsep.join([str(folder), str(root)])


__all__ = ["MAPPED", "old_layout", "pythonpath"]
