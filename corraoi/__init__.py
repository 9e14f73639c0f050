"""corraoi: correlated Age-of-Information bandits.

The model (instances, theory), the twelve policies and the engine live here; the recorder
and viewer packages build on them. Heavy pieces are imported lazily by the CLI.
"""

from . import _signals

if _signals.is_cli():  # the command line: Ctrl-C at start-up is one line, exit 130
    _signals.install()

from ._version import __version__  # noqa: E402
from .errors import (  # noqa: E402
    ConfigError,
    CorraoiError,
    InstanceError,
    PolicyError,
    UsageError,
)

__all__ = [
    "__version__",
    "ConfigError",
    "CorraoiError",
    "InstanceError",
    "PolicyError",
    "UsageError",
]
