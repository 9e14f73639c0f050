"""The face's public surface is pinned (as httpx's tests/test_exported_members.py): what
``corraoi`` exports, that each name resolves, and that every callable says what it takes,
returns and raises."""

from __future__ import annotations

import inspect

import corraoi

EXPECTED = [
    "Choice", "CompiledPolicy", "ConfigError", "CorraoiError", "CorraoiWarning", "Instance",
    "InstanceError", "LogError", "Logger", "OutputError", "Param", "Policy", "PolicyError", "Run",
    "Sweep", "UsageError", "__version__", "compare", "diff", "errors", "export", "info", "load",
    "record", "recover", "register", "replay", "show", "sweep",
]  # fmt: skip


def test_all_is_pinned():
    assert sorted(corraoi.__all__) == sorted(EXPECTED)
    assert sorted(dir(corraoi)) == sorted(EXPECTED)


def test_every_name_resolves():
    for name in corraoi.__all__:
        assert getattr(corraoi, name) is not None, name


def test_every_error_is_in_corraoi_errors_under_corraoi_error():
    classes = [v for v in vars(corraoi.errors).values()
               if inspect.isclass(v) and v.__module__ == "corraoi.errors"]  # fmt: skip
    assert len(classes) >= 20
    for cls in classes:
        assert issubclass(cls, (corraoi.CorraoiError, corraoi.CorraoiWarning)), cls
        assert cls.__doc__, cls


def test_every_function_of_the_face_documents_parameters_return_and_errors():
    for name in ("record", "sweep", "load", "compare", "diff", "show", "info", "recover",
                 "replay", "export"):  # fmt: skip
        func = getattr(corraoi, name)
        doc = inspect.getdoc(func) or ""
        assert doc, name
        for param in inspect.signature(func).parameters:
            if param in ("kwargs",):
                continue
            assert f"``{param}``" in doc or param in doc, (name, param)
        assert "Raises" in doc or "raises" in doc, name
        assert "return" in doc.lower(), name
    for cls in (corraoi.Run, corraoi.Sweep):
        assert inspect.getdoc(cls)
        for attr in ("_repr_html_", "show"):
            assert callable(getattr(cls, attr)), (cls, attr)


def test_every_packages_all_resolves():
    """Each package's ``__all__`` (a wing's public names, some imported lazily) names only
    what its package gives: a module moved under a lazy import is caught here."""
    import importlib
    import pkgutil

    for top in ("corraoi", "corraoi.recorder", "corraoi.viewer"):
        root = importlib.import_module(top)
        packages = [root] + [importlib.import_module(m.name)
                             for m in pkgutil.walk_packages(root.__path__, f"{top}.")
                             if m.ispkg]  # fmt: skip
        for pkg in packages:
            for name in getattr(pkg, "__all__", ()):
                assert getattr(pkg, name, None) is not None, f"{pkg.__name__}.{name}"
