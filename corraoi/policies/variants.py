"""Correlated and AoI-aware forms of a compiled policy, made as subclasses (one object each)."""

from __future__ import annotations

from .api import RGB, CompiledPolicy

AOI_PREFIX = "aoi-aware-"
AOI_AWARE_REF = "Fatale et al. (2020): play argmax mu_hat when the age exceeds 1 / max mu_hat"


def variant(
    base: type[CompiledPolicy],
    name: str,
    *,
    correlated: bool,
    aware: bool,
    color: RGB | None = None,
    theorem: str | None = None,
    reference: str = "",
) -> type[CompiledPolicy]:
    """A subclass of ``base`` with the candidate set and/or the AoI-aware override on."""
    parts = []
    if correlated:
        parts.append("on the correlated candidate set")
    if aware:
        parts.append("AoI-aware (argmax mu_hat when age > 1/max mu_hat)")
    attrs = {
        "name": name,
        "correlated": correlated,
        "aoi_aware": aware,
        "color": color if color is not None else base.color,
        "theorem": theorem,
        "summary": f"{base.name.upper()} " + ", ".join(parts) + ".",
        "reference": "; ".join(r for r in (base.reference, reference) if r),
        "__module__": base.__module__,
        "__doc__": base.__doc__,
    }
    cls_name = "".join(w.capitalize() for w in name.replace("-", " ").split())
    return type(cls_name, (base,), attrs)


def family(
    base: type[CompiledPolicy],
    *,
    correlated_name: str | None,
    correlated_color: RGB | None = None,
    correlated_theorem: str | None = None,
    correlated_reference: str = "",
) -> list[type[CompiledPolicy]]:
    """[base, its correlated form, the AoI-aware base, the AoI-aware correlated form]
    (without the correlated ones when ``correlated_name`` is None)."""
    out = [base]
    corr = None
    if correlated_name is not None:
        corr = variant(base, correlated_name, correlated=True, aware=False,
                       color=correlated_color, theorem=correlated_theorem,
                       reference=correlated_reference)  # fmt: skip
        out.append(corr)
    out.append(variant(base, AOI_PREFIX + base.name, correlated=False, aware=True,
                       reference=AOI_AWARE_REF))  # fmt: skip
    if corr is not None:
        out.append(variant(base, AOI_PREFIX + correlated_name, correlated=True, aware=True,  # type: ignore[operator]
                           color=correlated_color, reference=f"{correlated_reference}; "
                           f"{AOI_AWARE_REF}"))  # fmt: skip
    return out
