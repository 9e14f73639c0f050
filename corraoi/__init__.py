"""corraoi: correlated Age-of-Information bandits.

The model (instances, theory), the twelve policies and the engine live here; the recorder
and viewer packages build on them. Heavy pieces are imported lazily by the CLI, and
``corraoi.load`` (logs and sweeps as pandas tables) is imported on first use.
"""

from typing import TYPE_CHECKING, Any

from corraoi import _signals

if _signals.is_cli():  # the command line: Ctrl-C at start-up is one line, exit 130
    _signals.install()

from ._version import __version__  # noqa: E402
from .errors import ConfigError, CorraoiError, InstanceError, PolicyError, UsageError  # noqa: E402

if TYPE_CHECKING:
    from corraoi.face.tables import load


def __getattr__(name: str) -> Any:
    # corraoi.load imports pandas/pyarrow and the recorder only when it is first used
    if name == "load":
        from corraoi.face.tables import load

        return load
    raise AttributeError(f"module 'corraoi' has no attribute {name!r}")


__all__ = [
    "__version__",
    "ConfigError",
    "CorraoiError",
    "InstanceError",
    "PolicyError",
    "UsageError",
    "load",
]
