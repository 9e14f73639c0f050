"""The slot record, declared once: every per-slot field a run yields, logs and shows.

One :class:`SlotField` per field: its name, the dtype and shape of its column in a
:class:`~corraoi.engine.block.SlotBlock`, its unit and meaning, whether a run may lack it,
how the slot log writes it, how ``corraoi diff`` compares it, and where the views show it
(the Rerun entity and view, the Foxglove path). Everything that spells out the slot record
reads :data:`SLOT_RECORD`: the engine's and the plain-Python tier's output buffers, the
GPU's capture row (checked by a test), the slot log's JSON Schema, encoder and decoder,
the tables' columns, the Rerun sink, the diff, ``corraoi.testing``, ``corraoi diff
--fields``'s help, the Foxglove layout and the field table of ``docs/log-format.md``
(:func:`markdown_table`, checked by a test).

Arms and states are 0-based in a block and numbered from 1 in files and for people
(``one_based``). A field that ``may_be_absent`` is left out of the messages of a run that
does not give it (a plain-Python plug-in that returns no scores; a log written before the
field existed; a loop logged by ``corraoi.Logger`` without the hidden state): in a block it
is ``None``, or, for a column every block carries (``corraoi.engine.block.FIELDS``), a fill
named in ``SlotBlock.absent``; ``SlotBlock.fields()`` names what a block holds, and every
writer, reader and view follows it. A run always holds the :data:`REQUIRED` fields.
"""

from __future__ import annotations

from dataclasses import dataclass

#: How the slot log writes a field's values (``SlotField.json``).
JSON_KINDS = ("integer", "boolean", "number", "float32", "arm set", "candidate scores")
#: How ``corraoi diff`` compares a field: ``exact``, or ``float`` (within ``--atol``; NaN
#: equals NaN).
DIFF_KINDS = ("exact", "float")


@dataclass(frozen=True)
class SlotField:
    """One per-slot field of the slot record."""

    name: str
    #: numpy dtype of its column in a SlotBlock
    dtype: str
    #: one value per arm (a (B, K) column) rather than one per slot ((B,))
    per_arm: bool
    #: unit of its values ("" for none)
    unit: str
    #: what it means, one sentence (the JSON Schema's and the docs' description)
    meaning: str
    #: how the slot log writes it (:data:`JSON_KINDS`): "float32", a number written with
    #: float32's shortest text, +-infinity as +-FLOAT32_MAX (JSON has no infinity);
    #: "candidate scores", a list of such numbers, one per arm of ``candidates`` in its
    #: order (NaN, the value of every other arm, needs no text), [] for a slot not scored
    json: str
    #: a run may lack it (no key in its messages; not in its blocks' ``fields()``)
    may_be_absent: bool = False
    #: arms or states: 0-based in a block, numbered from 1 in files and for people
    one_based: bool = False
    #: the least value ("" for none), and the largest ("K": the arms, "n": the states)
    minimum: str = ""
    maximum: str = ""
    #: how ``corraoi diff`` compares it (:data:`DIFF_KINDS`)
    diff: str = "exact"
    #: its Rerun entity under ``runs/<label>/`` and the view that shows it ("" for none)
    entity: str = ""
    view: str = ""
    #: its path in Foxglove (the layout's plots read it)
    foxglove: str = ""
    #: each source of a run of several sources has its own (``t`` and ``x`` are the slot's,
    #: shared by every source)
    per_source: bool = True
    #: only a run of several sources has it (``collided``): a single source's record, its
    #: log's schema included, is as it was before sources were added
    sources_only: bool = False

    def __post_init__(self) -> None:
        assert self.json in JSON_KINDS, self
        assert self.diff in DIFF_KINDS, self

    @property
    def shape(self) -> str:
        """ "(B,)" or "(B, K)": its column's shape in a block of B slots."""
        return "(B, K)" if self.per_arm else "(B,)"

    def table_columns(self, K: int) -> list[tuple[str, str]]:
        """(name, dtype) of its columns in a table (``Run.slots``, exports): one, or one per
        arm numbered from 1 (``mu_hat_1 .. mu_hat_K``; ``cand_k`` for the candidate set)."""
        if not self.per_arm:
            return [(self.name, self.dtype)]
        stem = "cand" if self.name == "candidates" else self.name
        return [(f"{stem}_{k}", self.dtype) for k in range(1, K + 1)]


def _f(name: str, dtype: str, per_arm: bool, unit: str, meaning: str, json: str,
       **kw: object) -> SlotField:  # fmt: skip
    return SlotField(name, dtype, per_arm, unit, meaning, json, **kw)  # type: ignore[arg-type]


#: Every per-slot field, in the order of a slot message's keys.
SLOT_RECORD: tuple[SlotField, ...] = (
    _f(
        "t",
        "int64",
        False,
        "slot",
        "slot number, 1..horizon",
        "integer",
        minimum="1",
        per_source=False,
        view="the timeline `slot`",
    ),
    _f(
        "x",
        "int64",
        False,
        "",
        "hidden state X_t, numbered 1..n",
        "integer",
        may_be_absent=True,
        one_based=True,
        minimum="1",
        maximum="n",
        entity="x",
        view="hidden state",
        foxglove="/corraoi/slot.x",
        per_source=False,
    ),
    _f(
        "arm",
        "int64",
        False,
        "",
        "channel (arm) played at slot t, numbered 1..K",
        "integer",
        one_based=True,
        minimum="1",
        maximum="K",
        entity="arm/success, arm/failure",
        view="arm played",
        foxglove="/corraoi/slot.arm",
    ),
    _f(
        "success",
        "bool",
        False,
        "",
        "r_t = Y[arm, x] = 1",
        "boolean",
        entity="arm/success, arm/failure",
        view="arm played",
        foxglove="/corraoi/slot.success",
    ),
    _f(
        "collided",
        "bool",
        False,
        "",
        "another source played the same channel at slot t (a run of several sources only); "
        "then nobody on it delivers and success is false",
        "boolean",
        may_be_absent=True,
        sources_only=True,
        foxglove="/corraoi/slot.collided",
    ),
    _f(
        "aoi",
        "int64",
        False,
        "slots",
        "age of information after slot t, in slots (aoi_0 = 1)",
        "integer",
        minimum="1",
        entity="aoi",
        view="AoI",
        foxglove="/corraoi/slot.aoi",
    ),
    _f(
        "oracle_aoi",
        "int64",
        False,
        "slots",
        "age of the oracle that plays the best arm on the same X path",
        "integer",
        may_be_absent=True,
        minimum="1",
        entity="oracle_aoi",
        view="AoI",
        foxglove="/corraoi/slot.oracle_aoi",
    ),
    _f(
        "regret",
        "int64",
        False,
        "slots",
        "pathwise AoI regret sum_{s<=t} (aoi_s - oracle_aoi_s), in slots",
        "integer",
        may_be_absent=True,
        entity="regret",
        view="regret",
        foxglove="/corraoi/slot.regret",
    ),
    _f(
        "estimator",
        "float64",
        False,
        "slots",
        "the paper's estimator sum_{s<=t} aoi_s - t / mu*, in slots",
        "number",
        may_be_absent=True,
        diff="float",
        entity="estimator",
        view="regret",
        foxglove="/corraoi/slot.estimator",
    ),
    _f(
        "override",
        "bool",
        False,
        "",
        "the AoI-aware rule chose the arm (argmax mu_hat); false otherwise",
        "boolean",
        may_be_absent=True,
        entity="override",
        view="arm played",
        foxglove="/corraoi/slot.override",
    ),
    _f(
        "mu_hat",
        "float64",
        True,
        "",
        "empirical mean reward of arms 1..K after the slot's update (0 if never pulled)",
        "number",
        may_be_absent=True,
        minimum="0",
        maximum="1",
        diff="float",
        entity="mu_hat",
        view="empirical means",
        foxglove="/corraoi/slot.mu_hat[:]",
    ),
    _f(
        "pulls",
        "int64",
        True,
        "pulls",
        "pulls of arms 1..K after the slot's update",
        "integer",
        may_be_absent=True,
        minimum="0",
        entity="pulls",
        view="pulls",
        foxglove="/corraoi/slot.pulls[:]",
    ),
    _f(
        "candidates",
        "bool",
        True,
        "",
        "arms (1..K, ascending) the arm was chosen from: A_t + {k_emp} for the correlated "
        "policies, every arm otherwise",
        "arm set",
        may_be_absent=True,
        entity="candidates/<k>",
        view="candidate set",
        foxglove="/corraoi/slot.candidates",
    ),
    _f(
        "forced",
        "bool",
        False,
        "",
        "the arm was not chosen by the score (a first pull of every arm, forced "
        "exploration); false otherwise",
        "boolean",
        may_be_absent=True,
        entity="why/forced",
        view="why this arm",
        foxglove="/corraoi/slot.forced",
    ),
    _f(
        "override_threshold",
        "float32",
        False,
        "slots",
        "the AoI-aware rule's threshold 1 / max_k mu_hat_k before the slot (infinite while "
        "every mean is 0): it acts when the age exceeds it",
        "float32",
        may_be_absent=True,
        diff="float",
        entity="why/threshold",
        view="why this arm",
        foxglove="/corraoi/slot.override_threshold",
    ),
    _f(
        "score",
        "float32",
        True,
        "",
        "what the policy maximised: the index of an index policy, the sample of a sampling "
        "policy; NaN for an arm outside the candidate set and at a slot not scored (forced "
        "or overridden)",
        "candidate scores",
        may_be_absent=True,
        diff="float",
        entity="why/score",
        view="why this arm",
        foxglove="/corraoi/slot.score[:]",
    ),
)

#: The fields by name.
BY_NAME: dict[str, SlotField] = {f.name: f for f in SLOT_RECORD}
#: Names of the fields every slot message holds (a log lacking one is refused).
REQUIRED: tuple[str, ...] = tuple(f.name for f in SLOT_RECORD if not f.may_be_absent)
#: Names of the fields a run may lack.
OPTIONAL: tuple[str, ...] = tuple(f.name for f in SLOT_RECORD if f.may_be_absent)
#: Every field's name, in message order.
NAMES: tuple[str, ...] = tuple(f.name for f in SLOT_RECORD)
#: Per-slot fields (not ``t``) and per-arm fields.
SCALAR: tuple[str, ...] = tuple(f.name for f in SLOT_RECORD if not f.per_arm and f.name != "t")
PER_ARM: tuple[str, ...] = tuple(f.name for f in SLOT_RECORD if f.per_arm)
#: Fields each source of a run of several sources has its own, and those shared by all.
PER_SOURCE: tuple[str, ...] = tuple(f.name for f in SLOT_RECORD if f.per_source)
SHARED: tuple[str, ...] = tuple(f.name for f in SLOT_RECORD if not f.per_source)
#: Fields ``corraoi diff`` compares within a tolerance.
FLOAT_FIELDS: tuple[str, ...] = tuple(f.name for f in SLOT_RECORD if f.diff == "float")
#: The largest float32: a "float32" field's +-infinity as the slot log writes it (JSON has
#: no infinity).
FLOAT32_MAX = 3.4028234663852886e38

#: The GPU kernel's capture row (``corraoi/gpu/kernel.cu``, ``row[i] = ...``): what each of
#: its int64 values holds, from which ``corraoi.gpu.runner.capture_run`` builds the fields
#: (``aoisum`` gives the estimator, ``candidates`` is a bitset; pulls and mu_hat follow from
#: the arms played; ``override_threshold`` and ``score`` are float32 bits in the low word).
#: The fields from ``forced`` on are captured by the capture module only (CAI_CAPTURE=1,
#: ``record --from``), never by a sweep's.
GPU_CAPTURE_ROW = ("x", "arm", "success", "aoi", "oracle_aoi", "regret", "aoisum",
                   "override", "candidates", "forced", "override_threshold",
                   "score")  # fmt: skip
#: The fields of the capture row that take K values (one per arm, ``row[i + k]``).
GPU_CAPTURE_PER_ARM = ("score",)


def record_for(sources: int) -> tuple[SlotField, ...]:
    """The fields a run of ``sources`` sources may hold: a single source's record has no
    field that only a run of several sources has (``collided``)."""
    if sources > 1:
        return SLOT_RECORD
    return tuple(f for f in SLOT_RECORD if not f.sources_only)


def markdown_table() -> str:
    """The field table of ``docs/log-format.md``, generated from :data:`SLOT_RECORD`."""
    lines = [
        "| field | JSON | per arm | unit | may be absent | diff | meaning |",
        "|---|---|---|---|---|---|---|",
    ]
    for f in SLOT_RECORD:
        lines.append(
            f"| `{f.name}` | {f.json} | {'yes' if f.per_arm else ''} | {f.unit} | "
            f"{'yes' if f.may_be_absent else ''} | {f.diff} | {f.meaning} |"
        )
    return "\n".join(lines) + "\n"


__all__ = [
    "BY_NAME",
    "DIFF_KINDS",
    "FLOAT32_MAX",
    "FLOAT_FIELDS",
    "GPU_CAPTURE_PER_ARM",
    "GPU_CAPTURE_ROW",
    "JSON_KINDS",
    "NAMES",
    "OPTIONAL",
    "PER_ARM",
    "PER_SOURCE",
    "REQUIRED",
    "SCALAR",
    "SHARED",
    "SLOT_RECORD",
    "SlotField",
    "markdown_table",
    "record_for",
]
