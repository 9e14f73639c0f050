"""Every argument of the Python face checked at the door (issue 45, item 5).

ONE table, :data:`TABLE`: for every face function (``record``, ``sweep``, ``load``,
``compare``, ``diff``, ``show``, the ``Run`` and ``Sweep`` methods, ``Param``, a policy
class's declarations, ``check_policy`` and the ``corraoi_run`` fixture) a wrong type for each
of its arguments, the error class expected (the kind's variant that is also a TypeError or
ValueError) and the words the one-line message must hold: the argument, the value given and
what is accepted. :func:`test_every_argument_of_every_face_function_is_in_the_table` holds
the table to the functions' signatures. Then what the checks change for a caller:
``fields="arm"`` is one field, ``web_port=0`` a free port, ``2.5`` runs refused and ``2.0``
taken, ``except TypeError`` / ``except ValueError`` catch them.
"""

from __future__ import annotations

import inspect
import socket
from collections.abc import Callable
from pathlib import Path
from typing import Any
from urllib.parse import urlsplit

import pytest

import corraoi
from corraoi.errors import (
    ArgumentTypeError,
    ArgumentValueError,
    ConfigError,
    ConfigTypeError,
    ConfigValueError,
    CorraoiError,
    InstanceTypeError,
    InstanceValueError,
    OutputTypeError,
    OutputValueError,
    PolicyTypeError,
    PolicyValueError,
    UsageError,
)
from corraoi.face.runs import Run
from corraoi.face.sweeps import Sweep
from corraoi.face.viewing import open_viewer
from corraoi.policies import Param, Policy
from corraoi.testing import check_policy


class Ctx:
    """What the calls of the table are made on: a recorded run, a sweep folder, the fixture."""

    run: Run
    sweep: Sweep
    fixture: Callable[..., Any]


class Uniform(Policy):
    name = "args-uniform"
    params = {"epsilon": Param(0.1, "unused", low=0, high=1)}

    def select(self, t, state):
        return state.rng.integers(state.arms)


def declare(**attrs: Any) -> type:
    """A plain-Python policy class declared with ``attrs`` (what a class body says)."""
    body = {"name": "args-declared", "select": lambda self, t, state: state.rng.integers(2)}
    return type("Declared", (Policy,), {**body, **attrs})


#: Each face function, called on the table's kwargs over valid values of the others.
CALLS: dict[str, Callable[..., Any]] = {
    "record": lambda c, **kw: corraoi.record(
        **{"policy": "ucb", "horizon": 50, "rrd": False, "path": "runs/x.mcap", **kw}
    ),  # fmt: skip
    "sweep": lambda c, **kw: corraoi.sweep(
        **{"instances": "I1", "policies": ["ucb"], "runs": 2, "horizon": 50, **kw}
    ),  # fmt: skip
    "load": lambda c, **kw: corraoi.load(**{"path": c.run.path, **kw}),
    "compare": lambda c, **kw: corraoi.compare(**{"runs": [c.run, c.run], **kw}),
    "diff": lambda c, **kw: corraoi.diff(**{"a": c.run, "b": c.run, **kw}),
    "show": lambda c, **kw: corraoi.show(**{"target": c.run, **kw}),
    "info": lambda c, **kw: corraoi.info(**{"path": c.run.path, **kw}),
    "recover": lambda c, **kw: corraoi.recover(**{"log": c.run.path, "out": "f.mcap", **kw}),
    "replay": lambda c, **kw: corraoi.replay(**{"run": c.run, "rrd": "r.rrd", **kw}),
    "export": lambda c, **kw: corraoi.export(**{"path": c.run.path, "out": "t.csv", **kw}),
    "Run": lambda c, **kw: Run(**{"path": c.run.path, **kw}),
    "Run.diff": lambda c, **kw: c.run.diff(**{"other": c.run, **kw}),
    "Run.show": lambda c, **kw: c.run.show(**kw),
    "Sweep": lambda c, **kw: Sweep(**kw),
    "Sweep.record": lambda c, **kw: c.sweep.record(**{"policy": "ucb", **kw}),
    "Sweep.record_each": lambda c, **kw: c.sweep.record_each(**kw),
    "Sweep.figure": lambda c, **kw: c.sweep.figure(**{"path": "fig.png", **kw}),
    "Sweep.show": lambda c, **kw: c.sweep.show(**kw),
    "Param": lambda c, **kw: Param(**{"default": 0.5, **kw}),
    "Policy class": lambda c, **kw: declare(**kw),
    "Policy()": lambda c, **kw: Uniform(**kw),
    "register": lambda c, **kw: corraoi.register(**kw),
    "check_policy": lambda c, **kw: check_policy(
        **{"policy": "ucb", "arms": (2,), "horizon": 20, "runs": 2, **kw}
    ),  # fmt: skip
    "corraoi_run": lambda c, **kw: c.fixture(**{"horizon": 50, **kw}),
    "Logger": lambda c, **kw: corraoi.Logger(**{"path": "log.mcap", "instance": "I1", **kw}),
}

#: (function, kwargs, error class, words of the message): a wrong type for every argument.
TABLE: list[tuple[str, dict[str, Any], type[Exception], str]] = [
    # corraoi.Logger
    ("Logger", {"path": 3}, OutputTypeError, "path 3: expected the slot log's path"),
    ("Logger", {"instance": 3}, InstanceTypeError, "instance 3: expected a built-in name"),
    ("Logger", {"instance": None}, ConfigTypeError, "arms None: not an integer"),
    ("Logger", {"instance": None, "arms": 0}, ConfigValueError, "arms 0: out of range"),
    ("Logger", {"arms": 2.5}, ConfigTypeError, "arms 2.5: not an integer"),
    ("Logger", {"arms": 3}, ConfigValueError, "expected 4, the arms of instance I1"),
    ("Logger", {"horizon": "10"}, ConfigTypeError, "horizon '10': not an integer"),
    ("Logger", {"policy": 3}, PolicyTypeError, "policy 3: expected the name the run is"),
    ("Logger", {"params": [1]}, PolicyTypeError, "params [1]: expected a dict of numbers"),
    ("Logger", {"seed": 1.5}, ConfigTypeError, "seed 1.5: not an integer"),
    ("Logger", {"channel": 3}, ConfigTypeError, "channel 3: expected iid, markov or trace:"),
    (
        "Logger",
        {"instance": None, "arms": 4, "channel": "markov"},
        ConfigValueError,
        "channel 'markov': expected None (a log without an instance has no hidden states)",
    ),
    ("Logger", {"rrd": 3}, OutputTypeError, "rrd 3: expected the Rerun recording's path"),
    ("Logger", {"source": 3}, ArgumentTypeError, "source 3: expected text"),
    ("Logger", {"version": 3}, ArgumentTypeError, "version 3: expected text"),
    ("Logger", {"overwrite": "yes"}, ArgumentTypeError, "overwrite 'yes': expected True or"),
    ("Logger", {"sinks": "x"}, ArgumentTypeError, "sinks 'x': expected a list or tuple"),
    # corraoi.record
    ("record", {"policy": 3}, PolicyTypeError, "policy 3: expected a policy name"),
    ("record", {"policy": ["ucb", "cucb"]}, PolicyTypeError, "expected one policy"),
    ("record", {"policy": ""}, PolicyValueError, "policy '': empty"),
    ("record", {"instance": 3}, InstanceTypeError, "instance 3: expected a built-in name"),
    ("record", {"seed": 1.5}, ConfigTypeError, "seed 1.5: not an integer"),
    ("record", {"seed": -1}, ConfigValueError, "seed -1: out of range, expected 0.."),
    ("record", {"horizon": "10"}, ConfigTypeError, "horizon '10': not an integer"),
    ("record", {"horizon": True}, ConfigTypeError, "horizon True: not an integer"),
    ("record", {"params": [1]}, PolicyTypeError, "params [1]: expected a dict"),
    ("record", {"params": {"c": "x"}}, PolicyTypeError, "params['c'] 'x': expected a number"),
    ("record", {"channel": 3}, ConfigTypeError, "channel 3: expected iid, markov or trace:"),
    ("record", {"channel": "markof"}, ConfigValueError, "channel 'markof': expected iid, markov"),
    ("record", {"policy": "no-such-policy"}, PolicyValueError, "unknown policy 'no-such-policy'"),
    ("record", {"instance": "I9"}, InstanceValueError, "I9: no such instance file"),
    ("record", {"path": 3}, OutputTypeError, "path 3: expected a path"),
    ("record", {"path": ""}, OutputValueError, "path '': empty"),
    (
        "record",
        {"rrd": 3},
        OutputTypeError,
        "rrd 3: expected the Rerun recording's path, None, True or False",
    ),  # fmt: skip
    ("record", {"force": "yes"}, ArgumentTypeError, "force 'yes': expected True or False"),
    ("record", {"score": "on"}, ArgumentTypeError, "score 'on': expected True or False"),
    ("record", {"sources": 2.5}, ConfigTypeError, "sources 2.5: not an integer"),
    ("record", {"sources": 0}, ConfigValueError, "sources 0: out of range, expected 1..4 (at"),
    ("record", {"sources": 5}, ConfigValueError, "expected 1..4 (at most the 4 arms of instance"),
    ("record", {"viewer": 9876}, ArgumentTypeError, "viewer 9876: expected a running Rerun"),
    ("record", {"sinks": "x"}, ArgumentTypeError, "sinks 'x': expected a list or tuple"),
    (
        "record",
        {"sinks": [3]},
        ArgumentTypeError,
        "sinks[0] 3: expected a corraoi.recorder.sink.Sink",
    ),
    ("record", {"on_block": 3}, ArgumentTypeError, "on_block 3: expected a function"),
    ("record", {"should_stop": True}, ArgumentTypeError, "should_stop True: expected a function"),
    # corraoi.sweep
    ("sweep", {"instances": 3}, InstanceTypeError, "instance 3: expected a built-in name"),
    ("sweep", {"instances": []}, InstanceValueError, "instances []: empty"),
    ("sweep", {"policies": 3}, PolicyTypeError, "policies 3: expected a policy name"),
    ("sweep", {"policies": []}, PolicyValueError, "policies []: empty"),
    (
        "sweep",
        {"runs": 2.5},
        ConfigTypeError,
        "runs 2.5: not an integer (a float is never rounded), expected 1..",
    ),  # fmt: skip
    ("sweep", {"runs": 0}, ConfigValueError, "runs 0: out of range, expected 1.."),
    ("sweep", {"horizon": 100.7}, ConfigTypeError, "horizon 100.7: not an integer"),
    ("sweep", {"horizon": [50, "x"]}, ConfigTypeError, "horizon[1] 'x': not an integer"),
    ("sweep", {"horizon": []}, ConfigValueError, "horizon []: empty"),
    ("sweep", {"seed": "0"}, ConfigTypeError, "seed '0': not an integer"),
    (
        "sweep",
        {"params": {"c": [1, "x"]}},
        PolicyTypeError,
        "params['c'][1] 'x': expected a finite number",
    ),  # fmt: skip
    ("sweep", {"out": 3}, OutputTypeError, "out 3: expected the sweep folder's path"),
    ("sweep", {"backend": "tpu"}, ConfigValueError, "backend 'tpu': expected cpu, gpu or auto"),
    ("sweep", {"backend": None}, ConfigTypeError, "backend None: expected cpu, gpu or auto"),
    ("sweep", {"scheduler": 3}, ConfigTypeError, "scheduler 3: expected 'local:N'"),
    ("sweep", {"channel": ["iid"]}, ConfigTypeError, "channel ['iid']: expected iid, markov"),
    ("sweep", {"baseline": 3}, PolicyTypeError, "baseline 3: expected the name of one of"),
    ("sweep", {"chunk": 1.5}, ConfigTypeError, "chunk 1.5: not an integer"),
    ("sweep", {"sources": 2.5}, ConfigTypeError, "sources 2.5: not an integer"),
    ("sweep", {"checkpoints": 1}, ConfigValueError, "checkpoints 1: out of range, expected 2.."),
    ("sweep", {"resume": 1}, ArgumentTypeError, "resume 1: expected True or False"),
    ("sweep", {"force": None}, ArgumentTypeError, "force None: expected True or False"),
    ("sweep", {"workers": "x"}, ConfigTypeError, "workers 'x': not an integer, expected 1.."),
    ("sweep", {"workers": 0}, ConfigValueError, "workers 0: out of range, expected 1.."),
    ("sweep", {"allow_huge": "no"}, ArgumentTypeError, "allow_huge 'no': expected True or"),
    ("sweep", {"on_slots": 3}, ArgumentTypeError, "on_slots 3: expected a function"),
    # corraoi.load
    (
        "load",
        {"path": 3},
        ArgumentTypeError,
        "path 3: expected the path of a slot log or a sweep folder",
    ),  # fmt: skip
    ("load", {"slots": (2.5, 9)}, ArgumentTypeError, "slots[0] 2.5: not an integer"),
    ("load", {"slots": "1,9"}, ArgumentTypeError, "slots '1,9': expected a pair (first, last)"),
    ("load", {"slots": (9, 2)}, ArgumentValueError, "slots[1] 2: out of range, expected >= 9"),
    # corraoi.compare
    ("compare", {"runs": "a.mcap"}, ArgumentTypeError, "runs 'a.mcap': expected a list"),
    ("compare", {"runs": []}, ArgumentValueError, "runs []: empty"),
    (
        "compare",
        {"runs": [3]},
        ArgumentTypeError,
        "runs[0] 3: expected a corraoi.Run or a slot log's path",
    ),  # fmt: skip
    ("compare", {"rrd": 3}, OutputTypeError, "rrd 3: expected the Rerun recording's path"),
    ("compare", {"viewer": 3}, ArgumentTypeError, "viewer 3: expected a running Rerun"),
    ("compare", {"force": "x"}, ArgumentTypeError, "force 'x': expected True or False"),
    # corraoi.diff
    ("diff", {"a": 3}, ArgumentTypeError, "a 3: expected a corraoi.Run or a slot log's path"),
    ("diff", {"b": None}, ArgumentTypeError, "b None: expected a corraoi.Run or a slot log's"),
    ("diff", {"fields": 3}, ArgumentTypeError, "fields 3: expected one of the fields or a list"),
    ("diff", {"fields": ["arm", 3]}, ArgumentTypeError, "fields[1] 3: expected one of the"),
    ("diff", {"fields": "a"}, ArgumentValueError, "fields 'a': expected fields of "),
    ("diff", {"atol": "0"}, ArgumentTypeError, "atol '0': expected a finite number >= 0.0"),
    ("diff", {"atol": -1.0}, ArgumentValueError, "atol -1.0: out of range, expected a finite"),
    # corraoi.show, Run.show, Sweep.show
    (
        "show",
        {"target": 42},
        ArgumentTypeError,
        "target 42: expected a corraoi.Run, a corraoi.Sweep, or the path",
    ),  # fmt: skip
    ("show", {"spawn": "no"}, ArgumentTypeError, "spawn 'no': expected True or False"),
    ("show", {"notebook": 1}, ArgumentTypeError, "notebook 1: expected True or False"),
    (
        "show",
        {"web_port": 70000},
        ArgumentValueError,
        "web_port 70000: out of range, expected 0..65535",
    ),  # fmt: skip
    ("show", {"web_port": "9090"}, ArgumentTypeError, "web_port '9090': not an integer"),
    ("show", {"width": "wide"}, ArgumentValueError, "width 'wide': expected a width in pixels"),
    ("show", {"width": 0}, ArgumentValueError, "width 0: out of range, expected >= 1"),
    ("show", {"height": 2.5}, ArgumentTypeError, "height 2.5: not an integer"),
    ("Run.show", {"web_port": -1}, ArgumentValueError, "web_port -1: out of range"),
    ("Run.show", {"spawn": None}, ArgumentTypeError, "spawn None: expected True or False"),
    ("Run.show", {"notebook": "yes"}, ArgumentTypeError, "notebook 'yes': expected True or"),
    ("Run.show", {"width": None}, ArgumentTypeError, "width None: not an integer"),
    ("Run.show", {"height": "640"}, ArgumentTypeError, "height '640': not an integer"),
    ("Sweep.show", {"web_port": 1.5}, ArgumentTypeError, "web_port 1.5: not an integer"),
    ("Sweep.show", {"spawn": 0}, ArgumentTypeError, "spawn 0: expected True or False"),
    ("Sweep.show", {"notebook": "x"}, ArgumentTypeError, "notebook 'x': expected True or"),
    ("Sweep.show", {"width": [1]}, ArgumentTypeError, "width [1]: not an integer"),
    ("Sweep.show", {"height": 0}, ArgumentValueError, "height 0: out of range"),
    # corraoi.info, recover, replay, export
    ("info", {"path": 3}, ArgumentTypeError, "path 3: expected the path of a slot log or a"),
    ("recover", {"log": 3}, ArgumentTypeError, "log 3: expected a slot log's path"),
    ("recover", {"out": 3}, OutputTypeError, "out 3: expected the recovered log's path"),
    ("recover", {"force": "x"}, ArgumentTypeError, "force 'x': expected True or False"),
    ("replay", {"run": 3}, ArgumentTypeError, "run 3: expected a corraoi.Run or a slot log's"),
    ("replay", {"rrd": 3}, OutputTypeError, "rrd 3: expected the Rerun recording's path"),
    ("replay", {"force": 1}, ArgumentTypeError, "force 1: expected True or False"),
    ("export", {"path": 3}, ArgumentTypeError, "path 3: expected the path of a slot log or a"),
    ("export", {"out": None}, OutputTypeError, "out None: expected the table's path"),
    ("export", {"force": "y"}, ArgumentTypeError, "force 'y': expected True or False"),
    # Run and its methods
    ("Run", {"path": 3}, ArgumentTypeError, "path 3: expected a slot log's path"),
    ("Run", {"slots": (1, "x")}, ArgumentTypeError, "slots[1] 'x': not an integer"),
    ("Run", {"rrd": 3}, ArgumentTypeError, "rrd 3: expected a Rerun recording's path"),
    ("Run.diff", {"other": 3}, ArgumentTypeError, "other 3: expected a corraoi.Run"),
    ("Run.diff", {"fields": {"arm": 1}}, ArgumentTypeError, "fields {'arm': 1}: expected one"),
    ("Run.diff", {"atol": float("nan")}, ArgumentValueError, "atol nan: not finite"),
    # Sweep and its methods
    ("Sweep", {"path": 3}, ArgumentTypeError, "path 3: expected a sweep folder's path"),
    ("Sweep.record", {"which": 1.5}, ArgumentTypeError, "which 1.5: not an integer"),
    (
        "Sweep.record",
        {"which": None},
        ArgumentTypeError,
        "which None: expected an index (0, 1, ...) or one of worst",
    ),  # fmt: skip
    ("Sweep.record", {"which": "worse"}, ArgumentValueError, "which 'worse': expected an index"),
    ("Sweep.record", {"which": -1}, ArgumentValueError, "which -1: out of range, expected >= 0"),
    ("Sweep.record", {"policy": 3}, PolicyTypeError, "policy 3: expected a policy name"),
    ("Sweep.record", {"cell": 3}, ArgumentTypeError, "cell 3: expected a cell's label"),
    ("Sweep.record", {"path": 3}, OutputTypeError, "path 3: expected a path"),
    ("Sweep.record", {"rrd": 1}, OutputTypeError, "rrd 1: expected the Rerun recording's path"),
    ("Sweep.record", {"force": 1}, ArgumentTypeError, "force 1: expected True or False"),
    ("Sweep.record", {"kept_code": "y"}, ArgumentTypeError, "kept_code 'y': expected True or"),
    (
        "Sweep.record",
        {"allow_changed_code": 1},
        ArgumentTypeError,
        "allow_changed_code 1: expected True or False",
    ),
    ("Sweep.record_each", {"which": True}, ArgumentTypeError, "which True: expected an index"),
    (
        "Sweep.record_each",
        {"cells": 3},
        ArgumentTypeError,
        "cells 3: expected one of the cells' labels or a list",
    ),
    ("Sweep.record_each", {"cells": ["ucb", 3]}, ArgumentTypeError, "cells[1] 3: expected"),
    ("Sweep.record_each", {"folder": 3}, OutputTypeError, "folder 3: expected a folder's path"),
    ("Sweep.record_each", {"force": "x"}, ArgumentTypeError, "force 'x': expected True or"),
    ("Sweep.record_each", {"kept_code": 1}, ArgumentTypeError, "kept_code 1: expected True"),
    ("Sweep.record_each", {"allow_changed_code": "x"}, ArgumentTypeError, "allow_changed_code"),
    ("Sweep.record_each", {"say": 3}, ArgumentTypeError, "say 3: expected a function"),
    ("Sweep.record_each", {"warn": None}, ArgumentTypeError, "warn None: expected a function"),
    ("Sweep.record_each", {"words": "--force"}, ArgumentTypeError, "words '--force': expected"),
    ("Sweep.figure", {"path": 3}, OutputTypeError, "path 3: expected the figure's path"),
    ("Sweep.figure", {"log_x": 1}, ArgumentTypeError, "log_x 1: expected True or False"),
    ("Sweep.figure", {"log_y": "y"}, ArgumentTypeError, "log_y 'y': expected True or False"),
    # Param, a policy class's declarations, an instance of one, register
    ("Param", {"default": "0.1"}, PolicyTypeError, "Param default '0.1': expected a number"),
    ("Param", {"default": 5, "high": 1}, PolicyValueError, "Param default 5: out of range"),
    ("Param", {"help": 0}, PolicyTypeError, "Param help 0: expected a line of text"),
    ("Param", {"low": "0"}, PolicyTypeError, "Param low '0': expected a number or None"),
    ("Param", {"high": [1]}, PolicyTypeError, "Param high [1]: expected a number or None"),
    ("Param", {"low": 2, "high": 1}, PolicyValueError, "Param low 2: expected a low bound"),
    ("Param", {"open_low": 1}, PolicyTypeError, "Param open_low 1: expected True or False"),
    ("Param", {"open_high": "x"}, PolicyTypeError, "Param open_high 'x': expected True or"),
    ("Param", {"integer": None}, PolicyTypeError, "Param integer None: expected True or False"),
    (
        "Policy class",
        {"params": {"epsilon": 0.1}},
        PolicyTypeError,
        "Declared.params['epsilon'] 0.1: expected a corraoi.Param (e.g. Param(0.1, ",
    ),
    ("Policy class", {"params": [Param(0.1)]}, PolicyTypeError, "Declared.params [Param("),
    (
        "Policy class",
        {"params": {"2x": Param(0.1)}},
        PolicyValueError,
        "Declared.params key '2x': expected a parameter name",
    ),
    ("Policy class", {"name": 3}, PolicyTypeError, "Declared.name 3: expected text"),
    ("Policy class", {"label": None}, PolicyTypeError, "Declared.label None: expected text"),
    ("Policy class", {"color": "red"}, PolicyTypeError, "Declared.color 'red': expected None or"),
    ("Policy()", {"epsilon": "x"}, PolicyTypeError, "Uniform(epsilon=...) 'x': expected a"),
    ("Policy()", {"epsilon": 2.0}, PolicyValueError, "Uniform(epsilon=...) 2.0: must be in"),
    ("Policy()", {"eps": 0.1}, PolicyTypeError, "Uniform(eps=...): not a parameter it declares"),
    ("register", {"cls": 3}, PolicyTypeError, "3 is not a policy class"),
    # corraoi.testing.check_policy and the corraoi_run fixture
    ("check_policy", {"policy": 3}, PolicyTypeError, "policy 3: expected a policy name"),
    ("check_policy", {"params": {"c": None}}, PolicyTypeError, "params['c'] None: expected a"),
    ("check_policy", {"arms": 3}, InstanceTypeError, "arms 3: expected a list of numbers"),
    ("check_policy", {"arms": [1]}, InstanceValueError, "arms[0] 1: out of range, expected >= 2"),
    ("check_policy", {"horizon": 2.5}, ConfigTypeError, "horizon 2.5: not an integer"),
    ("check_policy", {"runs": "4"}, ConfigTypeError, "runs '4': not an integer"),
    ("check_policy", {"seed": None}, ConfigTypeError, "seed None: not an integer"),
    ("check_policy", {"tmp_path": 3}, OutputTypeError, "tmp_path 3: expected a folder's path"),
    ("check_policy", {"sources": 2.5}, ConfigTypeError, "sources 2.5: not an integer"),
    ("check_policy", {"sources": 3}, InstanceValueError, "expected a number of arms of at least "
     "sources (3)"),
    ("check_policy", {"sources": 2}, ConfigValueError, "policy ucb is single-source; with "
     "sources 2"),
    ("corraoi_run", {"policy": 3}, PolicyTypeError, "policy 3: expected a policy name"),
    ("corraoi_run", {"seed": 0.5}, ConfigTypeError, "seed 0.5: not an integer"),
    ("corraoi_run", {"horizon": 0}, ConfigValueError, "horizon 0: out of range, expected 1.."),
    ("corraoi_run", {"instance": 1}, InstanceTypeError, "instance 1: expected a built-in name"),
    ("corraoi_run", {"params": "c=1"}, PolicyTypeError, "params 'c=1': expected a dict"),
    ("corraoi_run", {"channel": 1}, ConfigTypeError, "channel 1: expected iid, markov"),
]


@pytest.fixture(scope="module")
def recorded(tmp_path_factory: pytest.TempPathFactory) -> tuple[Run, Sweep]:
    folder = tmp_path_factory.mktemp("face-arguments")
    run = corraoi.record("ucb", "I1", seed=1, horizon=300, path=folder / "ucb.mcap")
    sweep = corraoi.sweep("I1", ["ucb"], runs=3, horizon=200, out=folder / "sweep")
    return run, sweep


@pytest.fixture
def ctx(recorded, corraoi_run, tmp_path, monkeypatch) -> Ctx:
    monkeypatch.chdir(tmp_path)  # whatever a call would write lands here: nothing must
    c = Ctx()
    c.run, c.sweep = recorded
    c.fixture = corraoi_run
    return c


@pytest.mark.parametrize(
    ("function", "kwargs", "error", "words"),
    TABLE,
    ids=[f"{f}-{'-'.join(k)}-{i}" for i, (f, k, _, _) in enumerate(TABLE)],
)
def test_a_wrong_argument_is_one_line_of_its_kind_before_anything_is_done(
    ctx, tmp_path, function, kwargs, error, words
):  # fmt: skip
    with pytest.raises(error) as info:
        CALLS[function](ctx, **kwargs)
    exc = info.value
    assert type(exc) is error  # the variant itself, not a cousin
    assert isinstance(exc, CorraoiError) and isinstance(exc, UsageError)
    assert isinstance(exc, TypeError) != isinstance(exc, ValueError)
    text = str(exc)
    assert words in text and "\n" not in text, text
    assert list(tmp_path.iterdir()) == []  # refused before anything was written


def _arguments(function: str) -> set[str]:
    """The parameters of a face function, as a caller names them."""
    targets: dict[str, Any] = {
        "record": corraoi.record, "sweep": corraoi.sweep, "load": corraoi.load,
        "compare": corraoi.compare, "diff": corraoi.diff, "show": corraoi.show,
        "info": corraoi.info, "recover": corraoi.recover, "replay": corraoi.replay,
        "export": corraoi.export,
        "Run": Run.__init__, "Run.diff": Run.diff, "Run.show": open_viewer,
        "Sweep": Sweep.__init__, "Sweep.record": Sweep.record,
        "Sweep.record_each": Sweep.record_each, "Sweep.figure": Sweep.figure,
        "Sweep.show": open_viewer, "Param": Param, "register": corraoi.register,
        "check_policy": check_policy, "Logger": corraoi.Logger.__init__,
    }  # fmt: skip
    if function == "Policy class":
        return {"params", "name", "label", "color"}
    if function == "Policy()":
        return {"epsilon"}
    if function == "corraoi_run":
        return {"policy", "seed", "horizon", "instance", "params", "channel"}
    names = set(inspect.signature(targets[function]).parameters)
    # self; Run's summary is the one measured while it was recorded; open_viewer's find is
    # the method's own
    return names - {"self", "summary", "find"}


def test_every_argument_of_every_face_function_is_in_the_table():
    covered: dict[str, set[str]] = {}
    for function, kwargs, _, _ in TABLE:
        covered.setdefault(function, set()).update(kwargs)
    assert set(covered) == set(CALLS)
    for function in CALLS:
        assert _arguments(function) <= covered[function], (
            function,
            _arguments(function) - covered[function],
        )


def test_a_str_of_fields_is_one_field_not_its_letters(recorded):
    run, _ = recorded
    other = corraoi.record("cucb", "I1", seed=1, horizon=300, path=run.path.with_name("c.mcap"),
                           rrd=False)  # fmt: skip
    report = corraoi.diff(run, other, fields="arm")
    assert list(report.fields) == ["arm"]
    assert report["arm"].first_slot is not None  # ucb and cucb part somewhere
    assert list(run.diff(other, fields="x").fields) == ["x"]
    assert (
        report.fields["arm"].first_slot
        == corraoi.diff(run, other, fields=["arm"])["arm"].first_slot
    )


def _listening(port: int) -> bool:
    with socket.socket() as s:
        s.settimeout(0.5)
        return s.connect_ex(("127.0.0.1", port)) == 0


def test_web_port_0_serves_the_viewer_on_a_free_port_named_in_the_url(recorded):
    import time

    run, _ = recorded
    shown = corraoi.show(run, web_port=0)
    try:
        parts = urlsplit(shown.url)
        assert parts.hostname == "127.0.0.1"
        assert parts.port and parts.port != 0 and _listening(parts.port)
    finally:
        shown.close()
    time.sleep(0.3)
    assert not _listening(parts.port)


def test_runs_and_horizons_are_integers_never_truncated(tmp_path):
    with pytest.raises(ConfigTypeError, match=r"runs 2\.5: not an integer"):
        corraoi.sweep("I1", ["ucb"], runs=2.5, horizon=50, out=tmp_path / "a")
    assert not (tmp_path / "a").exists()
    with pytest.raises(ConfigTypeError, match=r"horizon 100\.7: not an integer"):
        corraoi.sweep("I1", ["ucb"], runs=2, horizon=100.7, out=tmp_path / "b")
    # a float of integral value is that integer (1e2 is how one writes 100 in a notebook)
    sw = corraoi.sweep("I1", ["ucb"], runs=2.0, horizon=1e2, out=tmp_path / "c")
    assert sw.summary["runs"] == 2 and sw.summary["horizon"] == 100
    run = corraoi.record("ucb", horizon=60.0, seed=2.0, path=tmp_path / "r.mcap", rrd=False)
    assert run.log.config.horizon == 60 and run.log.config.seed == 2


def test_except_type_error_and_except_value_error_catch_them(tmp_path):
    try:
        corraoi.record("ucb", horizon="10", path=tmp_path / "r.mcap")
    except TypeError as exc:
        assert isinstance(exc, ConfigError)
    else:
        pytest.fail("no TypeError")
    try:
        corraoi.record("ucb", horizon=0, path=tmp_path / "r.mcap")
    except ValueError as exc:
        assert isinstance(exc, ConfigError)
    else:
        pytest.fail("no ValueError")
    with pytest.raises(TypeError):
        corraoi.diff(tmp_path / "r.mcap", tmp_path / "r.mcap", atol="x")
    with pytest.raises(ValueError):
        corraoi.show(tmp_path / "r.mcap", web_port=65536)
    assert list(tmp_path.iterdir()) == []


def test_the_error_classes_are_the_kinds_with_a_type_or_value_error():
    for kind, variants in {
        UsageError: (ArgumentTypeError, ArgumentValueError),
        ConfigError: (ConfigTypeError, ConfigValueError),
    }.items():
        typed, valued = variants
        assert issubclass(typed, kind) and issubclass(typed, TypeError)
        assert issubclass(valued, kind) and issubclass(valued, ValueError)
    for cls in (PolicyTypeError, InstanceTypeError, OutputTypeError):
        assert issubclass(cls, ArgumentTypeError)
    for cls in (PolicyValueError, InstanceValueError, OutputValueError):
        assert issubclass(cls, ArgumentValueError)


def test_the_python_api_page_says_what_each_call_raises():
    """docs/python-api.md's table names every face call of :data:`CALLS` and only error
    classes of ``corraoi.errors`` (UsageError included), and its kinds' table is the code's."""
    import re

    import corraoi.errors as errors
    from corraoi.arguments import KINDS

    page = (Path(__file__).resolve().parent.parent / "docs" / "python-api.md").read_text()
    table = page.split("### What each call raises", 1)[1].split("\n\n", 2)[1]
    rows = [line.split("|")[1:3] for line in table.splitlines()[2:]]
    calls = " ".join(call for call, _ in rows)
    for function in CALLS:
        word = {
            "Policy class": "class statement",
            "Policy()": "an instance of one",
            "Run": "corraoi.Run(...)",
            "Sweep": "corraoi.Sweep(...)",
        }.get(function, function)
        assert word in calls, function
    named = {n for _, raised in rows for n in re.findall(r"`([A-Z]\w+)`", raised)}
    assert "UsageError" in named
    assert {n for n in named if not hasattr(errors, n)} == {"AssertionError"}
    for kind, (typed, valued) in KINDS.items():
        assert f"| `{kind.__name__}` | `{typed.__name__}` | `{valued.__name__}` |" in page


def test_a_params_table_changed_after_the_class_statement_is_refused_where_it_is_registered(
    tmp_path,
):
    """The class statement checks the table; registering (what record and sweep do with a
    class) checks it again, so a table replaced afterwards is refused there too."""

    class Later(Policy):
        name = "args-later"
        params = {"epsilon": Param(0.1, "exploration", low=0, high=1)}

        def select(self, t, state):
            return state.rng.integers(state.arms)

    Later.params = {"epsilon": 0.1}  # type: ignore[dict-item]
    with pytest.raises(PolicyTypeError, match=r"Later\.params\['epsilon'\] 0\.1: expected a "):
        corraoi.register(Later)
    with pytest.raises(PolicyTypeError, match=r"Later\.params\['epsilon'\] 0\.1"):
        corraoi.record(Later, horizon=50, path=tmp_path / "later.mcap")
    assert list(tmp_path.iterdir()) == []
