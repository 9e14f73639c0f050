"""The optional extras (``pip install "corraoi[NAME]"``): whether one is installed, found
without importing it (pandas alone costs 0.3 s), and the one line that says what to install."""

from __future__ import annotations

import importlib.util

from .errors import MissingExtraError

#: What each extra installs, by the import names corraoi looks for.
EXTRAS = {
    "analysis": ("pandas", "pyarrow"),
    "plot": ("matplotlib",),
    "cluster": ("dask",),
    "foxglove": ("foxglove",),
    "gpu": ("cupy",),
    "notebook": ("rerun_notebook",),
    "gym": ("gymnasium",),
}


def install_hint(extra: str) -> str:
    """``pip install "corraoi[EXTRA]"``."""
    return f'pip install "corraoi[{extra}]"'


def missing(names: tuple[str, ...]) -> str | None:
    """The first of ``names`` that is not installed, or None."""
    for name in names:
        try:
            found = importlib.util.find_spec(name) is not None
        except (ImportError, ValueError):
            found = False
        if not found:
            return name
    return None


def require(extra: str, what: str, names: tuple[str, ...] | None = None) -> None:
    """Raise :class:`~corraoi.errors.MissingExtraError` naming the extra unless ``names``
    (default: all the extra installs) are installed; ``what`` is what needs them."""
    absent = missing(names if names is not None else EXTRAS[extra])
    if absent is not None:
        raise MissingExtraError(
            f"{absent} is not installed: {what} needs the {extra} extra, {install_hint(extra)}"
        )


__all__ = ["EXTRAS", "install_hint", "missing", "require"]
