"""Ctrl-C in a notebook: ``corraoi.record`` and ``corraoi.sweep`` interrupted in a Jupyter
kernel (``KernelManager.interrupt_kernel``, what the stop button does) leave the kernel usable
(the next cell runs), no process of theirs behind (the Rerun worker, the figure worker), the
slot log never presented as complete, and the sweep folder resumable (resumed, it equals the
uninterrupted sweep).

The log: a KeyboardInterrupt between two writes finishes it with the slots so far, marked
``interrupted``, at its name; one that lands inside a write (the kernel raises it wherever
the main thread is) leaves it at its ``.partial`` name, its whole chunks readable
(``corraoi.recorder.slotlog.sink.McapSink``, docs/log-format.md). Either is accepted; both say
so."""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any

import pytest


def children(pid: int) -> list[int]:
    """The processes whose parent is ``pid`` (Linux /proc)."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:
            continue
        # pid (comm) state ppid ...: comm may hold spaces, so split after its ')'
        if int(stat.rsplit(")", 1)[1].split()[1]) == pid:
            found.append(int(entry.name))
    return found


def _plain(text: str) -> str:
    """``text`` without terminal colour codes (IPython colours its tracebacks)."""
    import re

    return re.sub(r"\x1b\[[0-9;]*m", "", text)


class Kernel:
    """An IPython kernel in ``cwd`` and a blocking client to it."""

    traceback = ""  # the last error's traceback, for a failing assertion's message

    def __init__(self, cwd: Path | None) -> None:
        if cwd is None:  # a client handed in afterwards (tests of this class)
            return
        from jupyter_client import KernelManager

        self.km = KernelManager(kernel_name="python3")
        self.km.start_kernel(cwd=str(cwd), env=dict(os.environ))
        self.kc = self.km.client()
        self.kc.start_channels()
        self.kc.wait_for_ready(timeout=60)
        self.pid = int(self.km.provisioner.pid)  # type: ignore[union-attr]

    def start(self, code: str) -> str:
        return str(self.kc.execute(code))

    def result(self, msg_id: str, timeout: float = 120) -> tuple[dict[str, Any], str]:
        """The execute reply's content and what the cell printed."""
        out = []
        deadline = time.monotonic() + timeout
        while True:
            msg = self.kc.get_iopub_msg(timeout=max(1, deadline - time.monotonic()))
            if msg["parent_header"].get("msg_id") != msg_id:
                continue
            if msg["msg_type"] == "stream":
                out.append(msg["content"]["text"])
            elif msg["msg_type"] == "error":
                out.append(msg["content"]["ename"])
                self.traceback = _plain("\n".join(msg["content"].get("traceback", [])))
            elif msg["msg_type"] == "status" and msg["content"]["execution_state"] == "idle":
                break
        return self.reply(msg_id, deadline)["content"], "".join(out)

    def reply(self, msg_id: str, deadline: float) -> dict[str, Any]:
        """The shell reply to ``msg_id``. Replies to other requests are passed over: under
        load ``wait_for_ready`` sends ``kernel_info`` again before the first reply comes, and
        the extra replies wait on the shell channel for whoever reads it next."""
        import queue

        while True:
            left = deadline - time.monotonic()
            try:
                reply = self.kc.get_shell_msg(timeout=max(1.0, left))
            except queue.Empty:
                raise AssertionError(f"no reply to {msg_id} before the deadline") from None
            if reply["parent_header"].get("msg_id") == msg_id:
                return dict(reply)
            assert time.monotonic() < deadline, f"no reply to {msg_id} before the deadline"

    def run(self, code: str, timeout: float = 120) -> str:
        content, out = self.result(self.start(code), timeout)
        assert content["status"] == "ok", out
        return out

    def interrupt_when(self, ready: Any, what: str, timeout: float = 120) -> None:
        deadline = time.monotonic() + timeout
        while not ready():
            assert time.monotonic() < deadline, f"{what} did not happen within {timeout:g} s"
            time.sleep(0.05)
        self.km.interrupt_kernel()

    def close(self) -> None:
        self.kc.stop_channels()
        self.km.shutdown_kernel(now=True)


def no_children_soon(kernel: Kernel, timeout: float = 15) -> list[int]:
    deadline = time.monotonic() + timeout
    while (left := children(kernel.pid)) and time.monotonic() < deadline:
        time.sleep(0.2)
    return left


@pytest.fixture
def kernel(tmp_path: Path):
    pytest.importorskip("jupyter_client", reason="jupyter_client is not installed "
                        '(pip install -e ".[notebook]")')  # fmt: skip
    pytest.importorskip("ipykernel", reason="ipykernel is not installed "
                        '(pip install -e ".[notebook]")')  # fmt: skip
    k = Kernel(tmp_path)
    try:
        k.run("import corraoi")
        yield k
    finally:
        k.close()


@pytest.mark.slow
def test_an_interrupted_record_leaves_the_kernel_usable_and_the_log_cut_short(tmp_path, kernel):
    partial = tmp_path / "long.mcap.partial"
    msg = kernel.start('corraoi.record("cucb", "I1", horizon=20_000_000, path="long.mcap")')
    # interrupted while it records: its log has grown past its first chunks
    kernel.interrupt_when(lambda: partial.exists() and partial.stat().st_size > 200_000,
                          "the log's first chunks")  # fmt: skip
    content, out = kernel.result(msg)
    assert content["status"] == "error" and content["ename"] == "KeyboardInterrupt", (
        f"{out}\n{kernel.traceback}")  # fmt: skip
    assert "\n" in out or out == "KeyboardInterrupt"
    # the kernel goes on; nothing of the run is left running
    assert kernel.run("print(6 * 7)") == "42\n"
    assert no_children_soon(kernel) == []
    final = tmp_path / "long.mcap"
    assert final.exists() != partial.exists(), "one log, at one of its two names"
    name = final.name if final.exists() else partial.name
    cut = kernel.run(f"r = corraoi.load({name!r})\n"
                     "print(r.log.status, r.complete, r.summary.slots > 0, r.config['horizon'])")
    status, complete, some, horizon = cut.split()
    assert complete == "False" and some == "True" and horizon == "20000000", cut
    assert status == ("interrupted" if final.exists() else "truncated"), cut


@pytest.mark.slow
def test_an_interrupted_sweep_leaves_the_kernel_usable_and_resumable(tmp_path, kernel):
    args = 'I1", ["ucb", "cts"], runs=400, horizon=20_000, chunk=4, workers=1'
    parts = tmp_path / "cut" / "parts"
    msg = kernel.start(f'corraoi.sweep("{args}, out="cut")')
    kernel.interrupt_when(lambda: parts.is_dir() and len(list(parts.iterdir())) >= 2,
                          "the sweep's first chunks")  # fmt: skip
    content, out = kernel.result(msg)
    assert content["status"] == "error" and content["ename"] == "KeyboardInterrupt", (
        f"{out}\n{kernel.traceback}")  # fmt: skip
    assert kernel.run("print('still here')") == "still here\n"
    assert no_children_soon(kernel) == []
    import json

    manifest = json.loads((tmp_path / "cut" / "manifest.json").read_text())
    assert manifest["status"] != "complete"
    # the same call with resume=True finishes it, equal to the sweep never interrupted
    same = kernel.run(
        f'cut = corraoi.sweep("{args}, out="cut", resume=True)\n'
        f'whole = corraoi.sweep("{args}, out="whole")\n'
        'cols = ["policy", "run", "t", "regret", "estimator"]\n'
        'a, b = (s.runs.sort_values(["policy", "run", "t"])[cols].reset_index(drop=True)\n'
        '        for s in (cut, whole))\n'
        'print(a.equals(b), len(a))', timeout=300)  # fmt: skip
    flag, rows = same.split()
    assert flag == "True" and int(rows) > 0
    assert json.loads((tmp_path / "cut" / "manifest.json").read_text())["status"] == "complete"
    assert no_children_soon(kernel) == []


def test_a_cell_waits_for_its_own_reply_past_replies_to_other_requests():
    """A busy machine: ``wait_for_ready`` asked twice for ``kernel_info`` and one reply was
    left on the shell channel; the first cell's result is still its own reply (the fresh
    clone's full run erred in its setup with "a kernel reply for another message id")."""
    import queue

    def msg(kind: str, parent: str, **content: Any) -> dict[str, Any]:
        return {"msg_type": kind, "parent_header": {"msg_id": parent}, "content": content}

    class Client:
        shell = [msg("kernel_info_reply", "info-2", status="ok"),
                 msg("execute_reply", "other", status="ok"),
                 msg("execute_reply", "cell", status="ok", execution_count=1)]  # fmt: skip
        iopub = [msg("status", "info-2", execution_state="idle"),
                 msg("stream", "cell", text="42\n"),
                 msg("status", "cell", execution_state="idle")]  # fmt: skip

        def get_shell_msg(self, timeout: float) -> dict[str, Any]:
            if not self.shell:
                raise queue.Empty
            return self.shell.pop(0)

        def get_iopub_msg(self, timeout: float) -> dict[str, Any]:
            return self.iopub.pop(0)

    k = Kernel(None)
    k.kc = Client()
    content, out = k.result("cell", timeout=5)
    assert content == {"status": "ok", "execution_count": 1} and out == "42\n"
    k.kc.iopub.append(msg("status", "late", execution_state="idle"))
    with pytest.raises(AssertionError, match="no reply to late"):  # the channel ran dry
        k.result("late", timeout=0.1)
