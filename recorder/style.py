"""How corraoi draws things: colours, names, line styles and units, for every view.

One place for the look of the Rerun views (``record``, ``replay``, ``compare``, the sweep
recording) and the matplotlib figures (``figure``, ``sweep -o``, ``reproduce``), so that a
policy has the same colour everywhere and a series the same name.

* A policy's colour: its own (``spec.color``, a plug-in's choice) if it has one, else its
  built-in class's (:data:`POLICY_COLORS`); an ``aoi-aware-`` variant shares its base
  policy's colour and is told apart by its line style: dashed in figures, a thinner line
  with cross markers in Rerun (rerun-sdk 0.41 lines cannot be dashed).
* The oracle (the best arm k* played on the same hidden path) is near-black and dotted
  (a point per slot, no line): never the hue nor the line style of a policy.
* Arms have their own colours (:func:`arm_color`) up to :data:`LINES_UP_TO` arms; beyond,
  the arms that matter have theirs (:func:`focus_color`) and the others are grey. An arm's
  true mean is drawn in its own colour, dotted, and named like its empirical mean, so that
  a legend lists each arm once.
* Names come from the instance (``arm 2 (los)``; the number alone where no name was given),
  shortened in legends (:func:`arm_legend`), whole in the run card.
* How many arms a view draws line by line (:data:`LINES_UP_TO`) and which arms matter
  beyond that (:data:`FOCUS_MAX`).
* rerun-sdk 0.41 has no axis titles: units go into view titles and series names
  (:data:`AOI_UNIT`, :data:`REGRET_UNIT`).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from corraoi.policies import AOI_PREFIX, RGB
from corraoi.policies.multi_source import RULES as MULTI_SOURCE_RULES
from corraoi.text import safe_text

#: Units, in brackets after a quantity's name (view titles, series names, axis labels).
AOI_UNIT = "[slots]"
REGRET_UNIT = "[slot-ages]"
SLOT_UNIT = "[slot]"
MEAN_UNIT = "[probability]"
PULLS_UNIT = "[count]"
SHARE_UNIT = "[fraction]"

#: Up to this many arms, the views draw a line (or a row of markers) per arm; beyond it,
#: per-arm values are bars at the time cursor, and lines are kept for the arms that matter.
LINES_UP_TO = 8
#: Beyond LINES_UP_TO arms: the most arms drawn as lines (the best arm, the competitive
#: arms, then the arms that become the most played or make up a small candidate set).
FOCUS_MAX = 8
#: Of those, the arms drawn from the first slot (the best arm and the competitive arms with
#: the highest means); the rest join as the run goes (:func:`arms_that_matter`).
FOCUS_START = 5
#: Characters of a legend entry (longer names end in an ellipsis).
LEGEND_CHARS = 18

def _builtin_colors() -> dict[str, RGB]:
    from corraoi.policies import builtins  # the registry imports without numba

    return {n: cls.color for n, cls in builtins().items() if cls.color is not None}


#: The built-in policies' colours, as each policy class declares its own (one place: the
#: class); an ``aoi-aware-`` variant has its base policy's colour.
POLICY_COLORS: dict[str, RGB] = _builtin_colors()
_EXTRA_COLORS: tuple[RGB, ...] = ((227, 119, 194), (127, 127, 127), (188, 189, 34), (23, 190, 207))
#: Colours of arms 1..8, and of the arms that matter beyond eight arms.
ARM_COLORS: tuple[RGB, ...] = (
    (102, 194, 165),
    (252, 141, 98),
    (141, 160, 203),
    (231, 138, 195),
    (166, 216, 84),
    (230, 171, 2),  # Set2's yellow (255, 217, 47) is too faint on white, a dark gold instead
    (229, 196, 148),
    (166, 118, 29),  # a brown for Set2's grey, which the reference lines and bars use
)
#: The oracle's AoI: near-black, unlike every policy and arm colour.
ORACLE_COLOR: RGB = (40, 40, 40)
SUCCESS_COLOR: RGB = (46, 160, 67)
FAILURE_COLOR: RGB = (214, 39, 40)
OVERRIDE_COLOR: RGB = (255, 187, 0)
STATE_COLOR: RGB = (90, 90, 160)

# Rerun line widths and marker sizes (UI points).
WIDTH_MAIN = 2.0
WIDTH_SECONDARY = 1.0
WIDTH_ARM = 1.5
WIDTH_TRUE_MEAN = 1.0
WIDTH_REFERENCE = 1.0
WIDTH_AOI_AWARE = 1.25
WIDTH_BAND = 0.75
MARKER_SUCCESS = 4.0
MARKER_FAILURE = 5.0
MARKER_OVERRIDE = 5.0
MARKER_ORACLE = 2.0
MARKER_STATE = 3.0
MARKER_CANDIDATE = 3.0
MARKER_TRUE_MEAN = 3.0
MARKER_AOI_AWARE = 2.5
#: a multi-source rule's marker in Rerun (RULE_MARKERS): large enough that a square, a
#: circle and a triangle are told apart on a curve
MARKER_RULE = 4.0
#: matplotlib dash pattern of the AoI-aware variants in figures.
DASH_AOI_AWARE: tuple[int, tuple[float, float]] = (0, (5, 2.5))

#: Series names (the legend entries) of a run's views.
AOI_NAME = f"AoI {AOI_UNIT}"
ORACLE_NAME = f"oracle AoI, best arm k* {AOI_UNIT}"
REGRET_NAME = f"pathwise regret sum(aoi - oracle_aoi) {REGRET_UNIT}"
ESTIMATOR_NAME = f"paper's estimator sum(aoi) - t/mu* {REGRET_UNIT}"
SUCCESS_NAME = "success"
FAILURE_NAME = "failure"
OVERRIDE_NAME = "AoI-aware override"
STATE_NAME = "hidden state x"
#: The "why this arm" view's series.
SCORE_UNIT = "[score]"
CHOSEN_NAME = "arm played: its score"
#: up to LINES_UP_TO arms, where every arm's line is drawn: the arm played is the top line
#: where the score chose it, and its dot marks only the slots it was below the top
CHOSEN_BELOW_NAME = "arm played below the top score"
FORCED_NAME = "forced (not by score)"
THRESHOLD_NAME = f"override threshold 1/max mu_hat {AOI_UNIT}"
FORCED_COLOR: RGB = (120, 120, 120)
MARKER_CHOSEN = 4.0
MARKER_FORCED = 4.0
BEST_ARM_NAME = "best arm k*"


def best_arm_name(k: int) -> str:
    """The legend entry of the best-arm line: ``best arm k* = 13``."""
    return f"{BEST_ARM_NAME} = {k + 1}"
#: Bars of the arms that do not matter (beyond LINES_UP_TO arms): the empirical mean in the
#: candidate set, out of it, and the true mean.
BAR_IN_SET_COLOR: RGB = (140, 140, 140)
BAR_OUT_COLOR: RGB = (195, 195, 195)
BAR_TRUE_COLOR: RGB = (50, 50, 50)
#: The paper's estimator and the best-arm line: a neutral reference colour, never a
#: policy's hue nor a shade of one (two shades of one hue are hard to tell apart).
REFERENCE_COLOR: RGB = (130, 130, 130)


#: The marker of a multi-source rule's curves in a figure (the first rule's: none), beside
#: the base policy's colour and the AoI-aware dash: ``rhorand-ucb`` and ``chairs-ucb`` of a
#: sweep are told apart. The rules are corraoi.policies.multi_source's, in its order.
RULE_MARKERS = dict(zip(MULTI_SOURCE_RULES, ("", "s", "^", "o", "D", "v", "P", "X"),
                        strict=False))  # fmt: skip


def rule_of(name: str) -> str:
    """The multi-source rule a policy's name starts with (``chairs-ucb`` -> ``chairs``), or
    "" (corraoi.policies.multi_source: ``<rule>-<base>``)."""
    head = name.split("-", 1)[0]
    return head if head in RULE_MARKERS and "-" in name else ""


def rule_marker(name: str) -> str:
    """The marker of a policy's curves (:data:`RULE_MARKERS`; "" for none)."""
    return RULE_MARKERS.get(rule_of(name), "")


def _without_rule(name: str) -> str:
    """The single-source policy a multi-source form is made of (``mctopm-aoi-aware-cts``
    -> ``aoi-aware-cts``); any other name unchanged."""
    rule = rule_of(name)
    return name.removeprefix(f"{rule}-") if rule else name


def base_policy(name: str) -> str:
    """``aoi-aware-cts`` -> ``cts``, ``mctopm-aoi-aware-cts`` -> ``cts``; any other name
    unchanged."""
    return _without_rule(name).removeprefix(AOI_PREFIX)


def is_aoi_aware(name: str) -> bool:
    """``aoi-aware-cts`` and its multi-source forms (``rhorand-aoi-aware-cts``)."""
    return _without_rule(name).startswith(AOI_PREFIX)


def policy_color(name: str, color: Sequence[int] | None = None) -> RGB:
    """The colour of a policy: ``color`` when given (a policy's own ``spec.color``), else
    its base policy's; unknown bases get a stable extra colour."""
    if color is not None:
        r, g, b = (int(c) for c in color)
        return (r, g, b)
    base = base_policy(name)
    if base in POLICY_COLORS:
        return POLICY_COLORS[base]
    return _EXTRA_COLORS[sum(base.encode()) % len(_EXTRA_COLORS)]


def variant_colors(rgb: Sequence[int], n: int) -> list[RGB]:
    """``n`` shades of one policy's colour, darker to lighter, for the parameter values a
    sweep runs it with (one curve each, told apart; a single value keeps the colour)."""
    base = tuple(int(c) for c in rgb)
    if n <= 1:
        return [(base[0], base[1], base[2])]
    out: list[RGB] = []
    for i in range(n):
        f = -0.45 + 0.9 * i / (n - 1)  # -0.45: 45% toward black .. +0.45: toward white
        r, g, b = (round(c + f * (255 - c)) if f > 0 else round(c * (1 + f)) for c in base)
        out.append((r, g, b))
    return out


def spec_color(spec: Any) -> RGB:
    """The colour of a policy spec (``.name`` and, where it has one, ``.color``)."""
    return policy_color(spec.name, getattr(spec, "color", None))


def spec_label(spec: Any) -> str:
    """The legend label of a policy spec: its ``.label`` where it has one, else its name."""
    return str(getattr(spec, "label", "") or spec.name)


def config_colors(config: dict[str, Any]) -> dict[str, RGB]:
    """The colour of every policy of a sweep configuration (``config["policies"]``, as
    written into sweep logs), each policy's own ``color`` where its entry carries one."""
    out: dict[str, RGB] = {}
    for p in config.get("policies") or []:
        if isinstance(p, dict) and isinstance(p.get("name"), str):
            own = p.get("color")
            ok = isinstance(own, (list, tuple)) and len(own) == 3
            out[p["name"]] = policy_color(p["name"], own if ok else None)
    return out


def lighter(rgb: Sequence[int], amount: float = 0.5) -> RGB:
    """``rgb`` mixed with white (``amount`` = 0: unchanged, 1: white)."""
    r, g, b = (round(c + (255 - c) * amount) for c in rgb)
    return (r, g, b)


def arm_color(k: int) -> RGB:
    """Colour of the arm with 0-based index ``k`` in views of up to :data:`LINES_UP_TO`
    arms, where every arm has its own (:data:`ARM_COLORS`; beyond, they repeat)."""
    return ARM_COLORS[k % len(ARM_COLORS)]


def focus_color(i: int) -> RGB:
    """Colour of the ``i``-th arm that matters (0-based, in the order they came to matter)
    in a view of more than :data:`LINES_UP_TO` arms: each of the at most
    :data:`FOCUS_MAX` has its own, the other arms are grey (:data:`BAR_IN_SET_COLOR`)."""
    return ARM_COLORS[i % len(ARM_COLORS)]


def source_color(m: int) -> RGB:
    """Colour of source ``m`` (from 1) of a run of several sources: each of up to eight
    sources its own (the arms' palette, :data:`ARM_COLORS`; no red, which marks the
    collisions)."""
    return ARM_COLORS[(m - 1) % len(ARM_COLORS)]


def source_name(m: int) -> str:
    """Source ``m``'s name in legends and titles."""
    return f"source {m}"


#: The most arms whose means a run of several sources draws as bars, each source's beside
#: the others' (beyond: a heatmap of sources x arms).
SOURCE_BARS_UP_TO = 16


def darker(rgb: Sequence[int], amount: float = 0.5) -> RGB:
    """``rgb`` mixed with black (``amount`` = 0: unchanged, 1: black)."""
    r, g, b = (round(c * (1 - amount)) for c in rgb)
    return (r, g, b)


def arm_label(k: int, name: str | None = None) -> str:
    """``arm 2`` or ``arm 2 (name)`` for the arm with 0-based index ``k`` (the whole name,
    control characters escaped)."""
    if name in (None, str(k + 1)):
        return f"arm {k + 1}"
    return f"arm {k + 1} ({safe_text(name)})"


def shorten(text: str, limit: int = LEGEND_CHARS) -> str:
    """``text`` with control characters escaped and runs of white space made one space,
    cut to ``limit`` characters, ending in an ellipsis when it was longer."""
    s = " ".join(safe_text(text).split())
    return s if len(s) <= limit else s[: max(limit - 1, 1)].rstrip() + "\u2026"


def arm_legend(k: int, name: str | None = None) -> str:
    """An arm in a legend: ``arm 2``, or ``2 los`` with the instance's name, shortened to
    :data:`LEGEND_CHARS` in all (:func:`shorten`); the number keeps two arms of one name
    apart."""
    if name in (None, str(k + 1)):
        return f"arm {k + 1}"
    number = str(k + 1)
    return f"{number} {shorten(name, max(LEGEND_CHARS - len(number) - 1, 4))}"


def numbered(i: int, name: str | None, default: str, limit: int = 12) -> str:
    """An arm or state in a title: ``2 rain`` (0-based ``i``, the name shortened to
    ``limit``); the number alone where the name is the default one (``default``)."""
    if name in (None, default):
        return str(i + 1)
    return f"{i + 1} {shorten(name, limit)}"


def arms_that_matter(mu: Any, best: int, competitive: Sequence[int]) -> list[int]:
    """The arms (0-based) a view of many arms draws as lines from the first slot (``mu``:
    the means, a sequence or array): the best
    arm, then the competitive arms (those a correlated policy keeps in its candidate set)
    with the highest means, at most :data:`FOCUS_START`. The views add, up to
    :data:`FOCUS_MAX`, each arm that becomes the most played and the members of a candidate
    set once it has at most FOCUS_MAX arms."""
    rest = sorted((k for k in competitive if k != best), key=lambda k: (-float(mu[k]), k))
    return [best, *rest][:FOCUS_START]


def lines_for(K: int) -> bool:
    """Whether a view of K arms draws a line per arm (else bars, strips and the arms that
    matter)."""
    return K <= LINES_UP_TO


def run_colors(colors: Sequence[RGB]) -> list[RGB]:
    """Colours for runs drawn together: each its policy's, in lighter shades for runs
    that would share one (two seeds of one policy, a policy and its AoI-aware form)."""
    seen: dict[RGB, int] = {}
    out = []
    for base in colors:
        i = seen.get(base, 0)
        seen[base] = i + 1
        out.append(base if i == 0 else lighter(base, min(0.25 * i, 0.7)))
    return out


def mpl(rgb: Sequence[int]) -> tuple[float, float, float]:
    """An RGB colour as matplotlib takes it (0..1 floats)."""
    r, g, b = (c / 255 for c in rgb)
    return (r, g, b)


__all__ = [
    "AOI_UNIT",
    "ARM_COLORS",
    "FOCUS_MAX",
    "FOCUS_START",
    "LEGEND_CHARS",
    "LINES_UP_TO",
    "REFERENCE_COLOR",
    "ORACLE_COLOR",
    "POLICY_COLORS",
    "REGRET_UNIT",
    "SOURCE_BARS_UP_TO",
    "arm_color",
    "arm_label",
    "arm_legend",
    "arms_that_matter",
    "focus_color",
    "base_policy",
    "config_colors",
    "darker",
    "is_aoi_aware",
    "rule_marker",
    "rule_of",
    "lighter",
    "lines_for",
    "mpl",
    "policy_color",
    "run_colors",
    "spec_color",
    "shorten",
    "source_color",
    "source_name",
    "spec_label",
    "numbered",
]
