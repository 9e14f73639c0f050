"""PartialFile (corraoi/files/partial.py): the one protocol every writer follows -- the target
checked, ``<path>.partial`` created under its lock, then published, left or discarded -- and
what it does with foreign files under the names it writes."""

from __future__ import annotations

import errno
import os
import subprocess
import sys
from pathlib import Path

import pytest

from corraoi.errors import OutputError, WriteError
from corraoi.files import partial as partial_file
from corraoi.files.locks import lock_holder
from corraoi.files.partial import PartialFile, partial_path


def test_publish_renames_the_finished_file_into_place(tmp_path: Path):
    out = PartialFile(tmp_path / "sub" / "a.bin", what="test file").create()
    assert out.partial == tmp_path / "sub" / "a.bin.partial" and out.partial.exists()
    assert lock_holder(out.partial) == os.getpid()  # locked while written
    out.file.write(b"hello")
    assert not out.path.exists()  # never under the final name before it is whole
    assert out.publish() == tmp_path / "sub" / "a.bin"
    assert out.path.read_bytes() == b"hello" and not out.partial.exists()
    assert out.state == "published"


def test_a_second_writer_is_refused_naming_the_holder(tmp_path: Path):
    target = tmp_path / "a.bin"
    code = ("import time; from corraoi.files.partial import PartialFile;"
            f"f = PartialFile({str(target)!r}).create(); print('locked', flush=True); "
            "time.sleep(60)")  # fmt: skip
    holder = subprocess.Popen([sys.executable, "-c", code], stdout=subprocess.PIPE, text=True)
    try:
        assert holder.stdout is not None and holder.stdout.readline().strip() == "locked"
        for overwrite in (False, True):  # --force never takes a file someone is writing
            with pytest.raises(OutputError) as info:
                PartialFile(target, overwrite=overwrite)
            assert str(info.value) == (
                f"{target}.partial: is being written by process {holder.pid} right now; not "
                "touched (wait for it, stop it, or give another output path)"
            )
    finally:
        holder.kill()
        holder.wait()
    # its writer is gone: the lock went with it; the file it left is refused without --force
    with pytest.raises(OutputError, match="a partial file of an earlier run"):
        PartialFile(target)
    out = PartialFile(target, overwrite=True).create()  # --force takes it over
    out.file.write(b"mine")
    out.publish()
    assert target.read_bytes() == b"mine"


def test_a_partial_that_replaceable_accepts_is_taken_over_without_force(tmp_path: Path):
    target = tmp_path / "run.log"
    partial_path(target).write_bytes(b"the same run, cut short")
    seen: list[Path] = []

    def same(part: Path) -> bool:
        seen.append(part)
        return part.read_bytes().startswith(b"the same run")

    with PartialFile(target, replaceable=same) as out:
        out.file.write(b"whole")
    assert target.read_bytes() == b"whole" and seen[0] == partial_path(target)
    target.unlink()
    partial_path(target).write_bytes(b"another run")
    with pytest.raises(OutputError, match="a partial file of an earlier run"):
        PartialFile(target, replaceable=same)
    assert partial_path(target).read_bytes() == b"another run"  # untouched


def test_discard_removes_the_partial_and_leave_keeps_it(tmp_path: Path):
    a = PartialFile(tmp_path / "a").create()
    a.file.write(b"x")
    a.discard()
    assert not a.partial.exists() and not a.path.exists() and lock_holder(a.partial) is None
    b = PartialFile(tmp_path / "b").create()
    b.file.write(b"kept")
    assert b.leave() == b.partial
    assert b.partial.read_bytes() == b"kept" and not b.path.exists()
    assert lock_holder(b.partial) is None  # released


def test_the_context_manager_discards_on_an_error(tmp_path: Path):
    target = tmp_path / "c"
    target.write_bytes(b"old")
    with pytest.raises(ZeroDivisionError), PartialFile(target, overwrite=True) as out:
        out.file.write(b"half")
        raise ZeroDivisionError
    assert target.read_bytes() == b"old" and not partial_path(target).exists()


def test_without_overwrite_a_target_that_appeared_meanwhile_is_never_clobbered(tmp_path: Path):
    target = tmp_path / "d"
    out = PartialFile(target).create()
    out.file.write(b"ours")
    target.write_bytes(b"theirs")
    with pytest.raises(OutputError, match="appeared while the output was being written"):
        out.publish()
    assert target.read_bytes() == b"theirs" and out.partial.read_bytes() == b"ours"


@pytest.mark.parametrize("kind", ["dir", "fifo", "symlink", "dangling"])
def test_foreign_files_under_the_partial_name_are_refused_in_one_line(tmp_path: Path, kind: str):
    target = tmp_path / "e.mcap"
    part = partial_path(target)
    elsewhere = tmp_path / "elsewhere"
    elsewhere.write_bytes(b"precious")
    if kind == "dir":
        part.mkdir()
    elif kind == "fifo":
        os.mkfifo(part)
    elif kind == "symlink":
        part.symlink_to(elsewhere)
    else:
        part.symlink_to(tmp_path / "nowhere")
    with pytest.raises(OutputError) as info:  # never blocks on a FIFO, never follows a link
        PartialFile(target, overwrite=True, what="MCAP log").create()
    assert "\n" not in str(info.value) and str(part) in str(info.value)
    assert elsewhere.read_bytes() == b"precious" and not target.exists()


@pytest.mark.parametrize("kind", ["dir", "fifo", "dangling"])
def test_foreign_files_under_the_target_name_are_refused_in_one_line(tmp_path: Path, kind: str):
    target = tmp_path / "f.png"
    if kind == "dir":
        target.mkdir()
    elif kind == "fifo":
        os.mkfifo(target)
    else:
        target.symlink_to(tmp_path / "nowhere")
    with pytest.raises(OutputError) as info:
        PartialFile(target, overwrite=True, what="figure")
    assert str(info.value).startswith(f"{target}: ") and "\n" not in str(info.value)


def test_a_symlink_target_is_replaced_not_followed(tmp_path: Path):
    precious = tmp_path / "precious"
    precious.write_bytes(b"keep")
    target = tmp_path / "g"
    target.symlink_to(precious)
    PartialFile.write_bytes(target, b"new", overwrite=True)
    assert precious.read_bytes() == b"keep"
    assert not target.is_symlink() and target.read_bytes() == b"new"


def test_a_full_disk_is_one_write_error_and_nothing_is_left(tmp_path: Path, monkeypatch):
    class Full:
        def __init__(self, f):
            self.f = f

        def write(self, data):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))

        def __getattr__(self, name):
            return getattr(self.f, name)

    real = partial_file.fdopen
    monkeypatch.setattr(partial_file, "fdopen", lambda fd: Full(real(fd)))
    target = tmp_path / "h.json"
    target.write_bytes(b"old")
    with pytest.raises(WriteError) as info:
        PartialFile.write_bytes(target, b"{}", what="summary")
    assert str(info.value) == f"{target}.partial: cannot write the summary: No space left on device"
    assert target.read_bytes() == b"old" and not partial_path(target).exists()


def test_a_folder_target_is_written_whole_and_replaces_the_old_one(tmp_path: Path):
    target = tmp_path / "results.parquet"
    (target / "old").mkdir(parents=True)
    (target / "old" / "part-0").write_bytes(b"old")
    out = PartialFile(target, overwrite=True, what="results", folder=True).create()
    assert out.partial.is_dir() and lock_holder(out.partial) == os.getpid()
    (out.partial / "instance=I1").mkdir()
    (out.partial / "instance=I1" / "part-0").write_bytes(b"new")
    out.publish()
    assert sorted(p.name for p in target.iterdir()) == ["instance=I1"]
    assert not out.partial.exists()
    assert not list(tmp_path.glob("*.old-*"))  # the old folder is gone, not set aside
    again = PartialFile(target, overwrite=True, folder=True).create()
    again.discard()
    assert not again.partial.exists() and (target / "instance=I1" / "part-0").exists()


def test_a_regular_file_under_a_folder_target_is_refused(tmp_path: Path):
    target = tmp_path / "results.parquet"
    target.write_bytes(b"not a dataset")
    with pytest.raises(OutputError, match="exists and is not a directory"):
        PartialFile(target, overwrite=True, folder=True)


def test_an_export_a_killed_export_left_is_made_again(tmp_path: Path):
    """A killed export leaves its .partial: the next export writes over it (it is made again
    from the source), while a file at the final name still needs --force."""
    pytest.importorskip("pyarrow")
    from click.testing import CliRunner

    from corraoi.cli import main

    log = tmp_path / "r.mcap"
    assert CliRunner().invoke(main, ["record", "-T", "200", "--no-rrd", "-o",
                                     str(log)]).exit_code == 0  # fmt: skip
    out = tmp_path / "r.csv"
    partial_path(out).write_bytes(b"t,x\n1,")  # cut short by a kill
    res = CliRunner().invoke(main, ["export", str(log), "-o", str(out)])
    assert res.exit_code == 0, res.output
    assert out.read_text().count("\n") == 201 and not partial_path(out).exists()
    res = CliRunner().invoke(main, ["export", str(log), "-o", str(out)])
    assert res.exit_code == 2 and "already exists (use --force" in res.output


def test_an_interrupt_a_library_masks_while_cleaning_up_stays_an_interrupt(tmp_path: Path):
    """Ctrl-C landing in a library's write whose clean-up then fails: numpy's ``savez``
    interrupted between ``ZipFile.open(name, "w")`` and the block that closes the member
    closes the zip in its ``finally``, which raises ValueError ("an open writing handle")
    in place of the KeyboardInterrupt (the shape of it here, as Python chains it). Through
    PartialFile the interrupt comes out, and nothing is left at either name."""
    target = tmp_path / "part.npz"
    with pytest.raises(KeyboardInterrupt), PartialFile(target) as out:
        try:
            out.file.write(b"half")
            raise KeyboardInterrupt
        finally:
            raise ValueError("Can't close the ZIP file while there is an open writing handle")
    assert not target.exists() and not partial_path(target).exists()
    # an OSError so raised (a close that failed) is the interrupt too, not a WriteError
    with pytest.raises(KeyboardInterrupt), PartialFile(target) as out:
        try:
            raise KeyboardInterrupt
        finally:
            raise OSError(errno.EIO, "Input/output error")
    # an error with no interrupt behind it is left as it is
    with pytest.raises(ValueError, match="plain"), PartialFile(target) as out:
        raise ValueError("plain")
    assert not partial_path(target).exists()
    assert partial_file.masked_interrupt(ValueError("plain")) is None
