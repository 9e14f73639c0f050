"""corraoi: correlated Age-of-Information bandits.

The model (instances, theory), the twelve policies and the engine live here; the recorder
and viewer packages build on them. Heavy pieces are imported lazily by the CLI.
"""

from ._version import __version__
from .errors import ConfigError, CorraoiError, InstanceError, PolicyError, UsageError

__all__ = [
    "__version__",
    "ConfigError",
    "CorraoiError",
    "InstanceError",
    "PolicyError",
    "UsageError",
]
