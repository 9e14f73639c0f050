"""The optional extras (``pip install "corraoi[NAME]"``): whether one is installed, found
without importing it (pandas alone costs 0.3 s), and the one line that says what to install;
and, for a package corraoi itself needs (:data:`CORE`) or an extra's that an import did not
find, that line made from the ``ModuleNotFoundError`` (:func:`missing_package`)."""

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


#: The packages every installation has (pyproject's dependencies), by the names they are
#: imported as: the distribution that installs each. A machine can still lack one (an
#: install with ``--no-deps``, a package removed since).
CORE = {
    "numpy": "numpy",
    "numba": "numba",
    "click": "click",
    "orjson": "orjson",
    "mcap": "mcap",
    "zstandard": "zstandard",
    "rerun": "rerun-sdk",
    "rerun_bindings": "rerun-sdk",
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


def require_package(name: str, what: str) -> None:
    """Raise the one-line :class:`~corraoi.errors.MissingExtraError` unless the package
    imported as ``name`` (one of :data:`CORE` or of an extra's) is installed, found without
    importing it: ``what`` needs it (say so before a long job, not after)."""
    if missing((name,)) is not None:
        raise not_installed(name, what)


def missing_package(exc: BaseException, what: str = "corraoi") -> MissingExtraError | None:
    """The one-line error for ``exc``, an import that failed because a package corraoi
    needs (:data:`CORE`) or an extra's (:data:`EXTRAS`) is not installed: what to install
    and the pip command. None for any other error (a module of corraoi itself missing is a
    fault to show as it is). ``what`` is what needed it (``corraoi sweep``)."""
    if not isinstance(exc, ModuleNotFoundError) or not exc.name:
        return None
    name = exc.name.partition(".")[0]
    if name not in CORE and not any(name in names for names in EXTRAS.values()):
        return None
    return not_installed(name, what)


def not_installed(name: str, what: str) -> MissingExtraError:
    """The error for the package imported as ``name`` not installed: the distribution (and
    the versions corraoi asks for) of one of :data:`CORE`, the extra of any other."""
    if name in CORE:
        dist = CORE[name]
        return MissingExtraError(f"{dist} is not installed (no module {name}): {what} needs "
                                 f'it, pip install "{requirement(dist)}"')  # fmt: skip
    extra = next((e for e, names in EXTRAS.items() if name in names), None)
    if extra is None:
        return MissingExtraError(f"{name} is not installed: {what} needs it")
    return MissingExtraError(f"{name} is not installed: {what} needs the {extra} extra, "
                             f"{install_hint(extra)}")  # fmt: skip


def requirement(dist: str) -> str:
    """``dist`` with the versions corraoi asks for (``rerun-sdk==0.41.*``), from the installed
    corraoi's metadata; the bare name where that cannot be read (a source checkout)."""
    import re
    from importlib.metadata import PackageNotFoundError, requires

    try:
        wanted = requires("corraoi") or []
    except PackageNotFoundError:
        return dist
    for req in wanted:
        head = re.match(r"\s*([A-Za-z0-9_.\-]+)(\[[^\]]*\])?\s*([^;]*)", req)
        if head is None or ";" in req:  # an extra's requirement, not a dependency
            continue
        if head.group(1).lower().replace("_", "-") == dist:
            return f"{dist}{head.group(3).strip()}"
    return dist


__all__ = [
    "CORE",
    "EXTRAS",
    "install_hint",
    "missing",
    "missing_package",
    "not_installed",
    "require",
    "require_package",
    "requirement",
]
