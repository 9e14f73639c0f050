"""corraoi.forked: the one object and safety rule of every forked worker."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time

import pytest

from corraoi import forked

pytestmark = pytest.mark.skipif(not hasattr(os, "fork"), reason="no fork on this platform")


def _echo(conn) -> None:
    while True:
        message = conn.recv()
        if message == "bye":
            return
        conn.send(("echo", message, os.getpid()))


def test_the_rule_forks_only_a_process_of_one_thread(monkeypatch):
    monkeypatch.delenv(forked.ENV, raising=False)
    assert forked.can_fork() == (threading.active_count() == 1)
    stop = threading.Event()
    other = threading.Thread(target=stop.wait)
    other.start()
    try:
        assert forked.can_fork() is False  # a lock that thread holds would never be freed
    finally:
        stop.set()
        other.join()
    for off in ("0", "off"):
        monkeypatch.setenv(forked.ENV, off)
        assert forked.can_fork() is False


def test_a_worker_serves_ignores_the_terminals_signals_and_stops_when_asked():
    worker = forked.ForkedWorker(_echo, "corraoi-test")
    try:
        worker.conn.send(41)
        kind, value, pid = worker.conn.recv()
        assert (kind, value) == ("echo", 41) and pid == worker.proc.pid != os.getpid()
        for sig in (signal.SIGINT, signal.SIGTERM, signal.SIGHUP):  # the parent decides
            os.kill(pid, sig)
        time.sleep(0.2)
        assert worker.alive()
        worker.conn.send(42)
        assert worker.conn.recv()[1] == 42
    finally:
        worker.stop(goodbye="bye")
    assert not worker.alive() and worker.exitcode() == 0
    worker.stop(goodbye="bye")  # safe twice


def test_a_worker_dies_with_its_parent_even_by_sigkill(tmp_path):
    code = (
        "import os, sys, time\n"
        "from corraoi.forked import ForkedWorker\n"
        "w = ForkedWorker(lambda conn: time.sleep(60), 'corraoi-test')\n"
        "print(w.proc.pid, flush=True)\n"
        "time.sleep(60)\n"
    )
    parent = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    assert parent.stdout is not None
    child = int(parent.stdout.readline())
    os.kill(child, 0)  # alive
    parent.kill()
    parent.wait()
    deadline = time.monotonic() + 5
    while time.monotonic() < deadline:
        try:
            os.kill(child, 0)
        except ProcessLookupError:
            break
        time.sleep(0.05)
    else:
        os.kill(child, signal.SIGKILL)
        pytest.fail("the worker outlived its parent")


def test_workers_off_does_every_job_in_this_process(monkeypatch):
    import multiprocessing

    from corraoi.recorder.rerun.worker import RerunWorker
    from corraoi.viewer.figure_worker import FigureWorker

    monkeypatch.setenv(forked.ENV, "0")
    assert RerunWorker.start() is None
    assert FigureWorker.start() is None
    assert multiprocessing.active_children() == []


def test_a_signal_during_the_fork_reaches_the_parents_handler_after_it():
    # Ctrl-C landing in the fork's own hooks (logging's lock release runs there) used to be
    # printed as "Exception ignored ... KeyboardInterrupt" and lost
    code = (
        "import os, signal, time\n"
        "from corraoi.forked import ForkedWorker\n"
        "os.register_at_fork(after_in_parent=lambda: os.kill(os.getpid(), signal.SIGINT))\n"
        "try:\n"
        "    w = ForkedWorker(lambda conn: None, 'corraoi-test')\n"
        "    time.sleep(5)\n"
        "    print('not interrupted')\n"
        "except KeyboardInterrupt:\n"
        "    print('interrupted after the fork')\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert out.stdout.strip() == "interrupted after the fork", out.stderr
    assert "Exception ignored" not in out.stderr and "Traceback" not in out.stderr
