"""corraoi: correlated Age-of-Information bandits.

The Python face, as complete as the command line::

    import corraoi

    run = corraoi.record("cucb", "I1", seed=0, horizon=10_000)   # a Run: run.summary, run.slots
    sw = corraoi.sweep("I1", ["ucb", "cucb"], runs=200, out="sweeps/I1")   # a Sweep
    worst = sw.record("worst", policy="cucb")   # that run, slot by slot
    corraoi.diff(run, worst).identical
    corraoi.show(worst)   # in Jupyter the Rerun viewer inline, elsewhere served on 127.0.0.1

Every name here is imported on first use, so ``import corraoi`` stays as fast as Python's
own start (numba, Rerun and pandas load only when a call needs them). Errors are
:class:`CorraoiError` subclasses, all in :mod:`corraoi.errors`.
"""

from typing import TYPE_CHECKING, Any

from . import _signals

if _signals.is_cli():  # the command line: Ctrl-C at start-up is one line, exit 130
    _signals.install()

from . import errors  # noqa: E402
from ._version import __version__  # noqa: E402
from .errors import (  # noqa: E402
    ConfigError,
    CorraoiError,
    CorraoiWarning,
    InstanceError,
    LogError,
    OutputError,
    PolicyError,
    UsageError,
)

if TYPE_CHECKING:
    from .face.load import export, load
    from .face.logger import Logger
    from .face.recording import record
    from .face.runs import Run
    from .face.show import show
    from .face.sweeps import Sweep, sweep
    from .face.views import compare, diff, info, recover, replay
    from .model.instance import Instance
    from .policies import Choice, CompiledPolicy, Param, Policy, register

#: The face's names, by the module that defines each (imported on first use).
_LAZY = {
    "record": "corraoi.face.recording",
    "sweep": "corraoi.face.sweeps",
    "load": "corraoi.face.load",
    "export": "corraoi.face.load",
    "info": "corraoi.face.views",
    "recover": "corraoi.face.views",
    "replay": "corraoi.face.views",
    "Logger": "corraoi.face.logger",
    "compare": "corraoi.face.views",
    "diff": "corraoi.face.views",
    "Run": "corraoi.face.runs",
    "Sweep": "corraoi.face.sweeps",
    "show": "corraoi.face.show",
    "Instance": "corraoi.model.instance",
    "Policy": "corraoi.policies",
    "Choice": "corraoi.policies",
    "CompiledPolicy": "corraoi.policies",
    "Param": "corraoi.policies",
    "register": "corraoi.policies",
}


def __getattr__(name: str) -> Any:
    module = _LAZY.get(name)
    if module is None:
        raise AttributeError(f"module 'corraoi' has no attribute {name!r}")
    import importlib

    value = getattr(importlib.import_module(module), name)
    globals()[name] = value  # the next access is a plain attribute
    return value


def __dir__() -> list[str]:
    return sorted(__all__)


__all__ = [
    "Choice",
    "CompiledPolicy",
    "ConfigError",
    "CorraoiError",
    "CorraoiWarning",
    "Instance",
    "InstanceError",
    "LogError",
    "Logger",
    "OutputError",
    "Param",
    "Policy",
    "PolicyError",
    "Run",
    "Sweep",
    "UsageError",
    "__version__",
    "compare",
    "diff",
    "errors",
    "export",
    "info",
    "load",
    "record",
    "recover",
    "register",
    "replay",
    "show",
    "sweep",
]
