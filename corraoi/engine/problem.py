"""A problem: one policy on one instance, channel and horizon, checked once and laid out as
the arrays every engine takes (issue 23, "resolve once, pass down").

The CPU engine (:class:`corraoi.engine.simulation.Simulation`) and the GPU runner
(``corraoi/gpu/runner.py``) both start from a :class:`Problem`; the seeds are the only
thing they add. Every check of a run's facts happens in :meth:`Problem.of`: the horizon, an
instance that can be simulated (mu* > 0), the channel against the instance and horizon, and
the policy resolved to its class.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from corraoi.errors import ConfigError, CorraoiError, PolicyError
from corraoi.limits import check_horizon
from corraoi.model.candidates import pseudo_reward_classes
from corraoi.model.channels import Channel, default_channel
from corraoi.model.instance import Instance
from corraoi.model.theory import InstanceTheory, analyse
from corraoi.policies.api import CompiledPolicy
from corraoi.policies.spec import PolicySpec


def check_instance(instance: Instance) -> InstanceTheory:
    """The instance's theory, or a ConfigError when it cannot be simulated (mu* = 0)."""
    theory = analyse(instance)
    if theory.mu_star <= 0:
        raise ConfigError(
            f"instance {instance.name}: every arm has mean 0, the AoI grows without bound "
            "and regret is not defined"
        )
    return theory


def _c(a: Any, dtype: Any) -> np.ndarray:
    # writable C arrays: the types the cached kernels were compiled for (kernels.warm_args)
    return np.require(a, dtype, ["C", "W"])


@dataclass(frozen=True, eq=False)
class Problem:
    """One policy on one instance, channel and horizon, checked, with its kernel arrays."""

    instance: Instance
    policy: PolicySpec
    horizon: int
    channel: Channel
    theory: InstanceTheory
    #: the policy's class (a CompiledPolicy or a plain-Python Policy)
    cls: Any
    #: (1 or n + 1, n) float64: the law of X_1, then the transition rows
    cdf_rows: np.ndarray
    #: the channel's kernel code (corraoi.engine._kernel.CHANNEL_CDF / CHANNEL_TRACE)
    kind: int
    #: (T,) int64: a trace channel's path (else a placeholder)
    trace: np.ndarray
    #: (K, n) int8 rewards
    Y: np.ndarray
    #: (K, K) int8: phi_{k,l} is 0, l's failure rate, l's success rate or 1
    pclass: np.ndarray
    #: (P,) float64: the parameters in the class's declared order (compiled policies)
    params: np.ndarray
    #: float64 state entries per run of a compiled policy (0 for a Python one)
    state_size: int

    @classmethod
    def of(cls, instance: Instance, policy: PolicySpec, horizon: int,
           channel: Channel | None = None) -> Problem:  # fmt: skip
        """Check the facts of a run once and lay them out (ConfigError/PolicyError when bad)."""
        check_horizon(horizon)
        theory = check_instance(instance)
        chan = channel if channel is not None else default_channel(instance)
        chan.check(instance, int(horizon))
        klass: Any = policy.resolve()
        cdf_rows, kind, trace = chan.kernel_arrays(instance)
        compiled = isinstance(klass, type) and issubclass(klass, CompiledPolicy)
        params = policy.param_vector(klass) if compiled else np.zeros(0)
        size = _state_size(klass, instance.K, policy) if compiled else 0
        return cls(instance=instance, policy=policy, horizon=int(horizon), channel=chan,
                   theory=theory, cls=klass, cdf_rows=_c(cdf_rows, np.float64), kind=int(kind),
                   trace=_c(trace, np.int64), Y=_c(instance.Y, np.int8),
                   pclass=_c(pseudo_reward_classes(instance), np.int8),
                   params=_c(params, np.float64), state_size=size)  # fmt: skip

    @property
    def compiled(self) -> bool:
        return issubclass(self.cls, CompiledPolicy)

    @property
    def K(self) -> int:
        return int(self.instance.K)


#: The most float64 state entries a compiled policy may keep per run (8 MiB a run).
MAX_STATE_SIZE = 1 << 20


def _state_size(klass: Any, K: int, policy: PolicySpec) -> int:
    """A compiled policy's ``state_size``, checked: whatever the hook raises or returns that
    is not a whole number in 0..MAX_STATE_SIZE is one PolicyError line."""
    try:
        size = klass.state_size(K, dict(policy.params))
    except (CorraoiError, KeyboardInterrupt):
        raise
    except Exception as exc:  # noqa: BLE001 - a plug-in's hook, whatever it raises
        detail = " ".join(str(exc).split())[:200]
        raise PolicyError(f"policy {policy.name}: its state_size raised {type(exc).__name__}"
                          + (f": {detail}" if detail else "")) from None  # fmt: skip
    if isinstance(size, bool) or not isinstance(size, (int, np.integer)) or not (
        0 <= size <= MAX_STATE_SIZE
    ):
        raise PolicyError(f"policy {policy.name}: its state_size returned {size!r}; expected a "
                          f"whole number of float64 entries per run, 0..{MAX_STATE_SIZE}")
    return int(size)
