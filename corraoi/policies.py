"""The twelve scheduling policies: settings, registry and name parsing.

A policy is a frozen :class:`PolicySpec`; its behaviour lives in the compiled engine kernel
(:mod:`corraoi._kernel`), which reads the integer codes below.
"""

from __future__ import annotations

import difflib
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

from .errors import PolicyError

BASE_UCB, BASE_TS_BETA, BASE_TS_GAUSS = 0, 1, 2

#: name -> (base code, correlated)
_BASES: dict[str, tuple[int, bool]] = {
    "ucb": (BASE_UCB, False),
    "ts": (BASE_TS_BETA, False),
    "ts-gauss": (BASE_TS_GAUSS, False),
    "cucb": (BASE_UCB, True),
    "cts": (BASE_TS_BETA, True),
    "cts-gauss": (BASE_TS_GAUSS, True),
}
AOI_PREFIX = "aoi-aware-"

#: Every registered policy name, in the order tables list them.
POLICY_NAMES: tuple[str, ...] = tuple(_BASES) + tuple(AOI_PREFIX + b for b in _BASES)

#: parameter -> (default, which bases use it, help)
PARAMETERS: dict[str, tuple[float, tuple[int, ...], str]] = {
    "c": (2.0, (BASE_UCB,), "UCB exploration constant: index mu_hat + sqrt(c ln t / n)"),
    "beta": (1.0, (BASE_TS_GAUSS,), "Gaussian TS variance scale: N(mu_hat, beta / (n + 1))"),
}


@dataclass(frozen=True)
class PolicySpec:
    """A policy with its parameters, validated on construction."""

    name: str
    params: dict[str, float] = field(init=False, default_factory=dict, compare=False, hash=False)
    c: float = 2.0
    beta: float = 1.0

    def __post_init__(self) -> None:
        if self.name not in POLICY_NAMES:
            raise PolicyError(unknown_policy_message(self.name))
        for pname in ("c", "beta"):
            value = getattr(self, pname)
            if not (0 < value < float("inf")):
                raise PolicyError(
                    f"policy {self.name}: parameter {pname} must be finite and > 0, got {value!r}"
                )
        object.__setattr__(self, "params", self.used_params())

    @property
    def base_name(self) -> str:
        return self.name.removeprefix(AOI_PREFIX)

    @property
    def base(self) -> int:
        return _BASES[self.base_name][0]

    @property
    def correlated(self) -> bool:
        return _BASES[self.base_name][1]

    @property
    def aoi_aware(self) -> bool:
        return self.name.startswith(AOI_PREFIX)

    def used_params(self) -> dict[str, float]:
        """The parameters this policy reads, with their values."""
        return {
            p: float(getattr(self, p))
            for p, (_, bases, _) in PARAMETERS.items()
            if self.base in bases
        }

    def to_dict(self) -> dict[str, Any]:
        return {"name": self.name, "params": dict(self.params)}

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> PolicySpec:
        return make_policy(str(data["name"]), **dict(data.get("params", {})))


def unknown_policy_message(name: str) -> str:
    close = difflib.get_close_matches(name.lower(), POLICY_NAMES, n=1, cutoff=0.6)
    hint = f"; did you mean {close[0]}?" if close else ""
    return f"unknown policy {name!r}{hint} (known: {', '.join(POLICY_NAMES)}, or all)"


def make_policy(name: str, **params: float | None) -> PolicySpec:
    """Build a policy, rejecting unknown parameter names. ``None`` values take defaults."""
    key = name.strip().lower()
    if key not in POLICY_NAMES:
        raise PolicyError(unknown_policy_message(name))
    unknown = sorted(set(params) - set(PARAMETERS))
    if unknown:
        raise PolicyError(
            f"unknown policy parameter {unknown[0]!r} (known: {', '.join(PARAMETERS)})"
        )
    values = {k: float(v) for k, v in params.items() if v is not None}
    return PolicySpec(name=key, **values)


def parse_policy_names(values: Iterable[str]) -> list[str]:
    """Names from ``--policy`` given as a name, a comma list, repeated, or ``all``.

    Keeps first-seen order and drops repeats; raises with a suggestion on a typo.
    """
    names: list[str] = []
    for value in values:
        for part in value.split(","):
            token = part.strip().lower()
            if not token:
                continue
            expanded = list(POLICY_NAMES) if token == "all" else [token]
            for n in expanded:
                if n not in POLICY_NAMES:
                    raise PolicyError(unknown_policy_message(part.strip()))
                if n not in names:
                    names.append(n)
    if not names:
        raise PolicyError("no policy given (expected a name, a comma list or all)")
    return names


def make_policies(
    values: Iterable[str], *, c: float | None = None, beta: float | None = None
) -> list[PolicySpec]:
    """Policies for ``--policy`` values, with shared parameters applied where they are used.

    A parameter that none of the chosen policies reads is an error, so that a typo such as
    ``--beta 2 --policy ucb`` is not silently ignored.
    """
    names = parse_policy_names(values)
    given = {"c": c, "beta": beta}
    reads = {n: make_policy(n).params for n in names}
    for pname, value in given.items():
        if value is not None and not any(pname in reads[n] for n in names):
            users = [n for n in POLICY_NAMES if pname in make_policy(n).params]
            raise PolicyError(
                f"parameter {pname} does not apply to {', '.join(names)} "
                f"(it is read by {', '.join(users)})"
            )
    # each policy gets only the parameters it reads
    return [make_policy(n, **{k: v for k, v in given.items() if k in reads[n]}) for n in names]
