"""corraoi.recorder.walk, the one MCAP walker (issue 23): a file cut short is told from a damaged
one, it gives the records mcap's StreamReader gives, every MCAP reader walks through it, and the
formats' names are defined once, in corraoi.recorder.vocab."""

from __future__ import annotations

import ast
import struct
import zlib
from pathlib import Path

import pytest
import zstandard
from mcap.reader import make_reader
from mcap.records import DataEnd, MessageIndex
from mcap.stream_reader import StreamReader

from corraoi.engine.block import FIELDS
from corraoi.errors import LogError
from corraoi.recorder import vocab
from corraoi.recorder.slotlog.encode import slot_schema
from corraoi.recorder.slotlog.reader import open_log
from corraoi.recorder.sweeplog.read import read_sweep
from corraoi.recorder.sweeplog.results import is_sweep_path
from corraoi.recorder.walk import Walker, records_in
from corraoi.viewer.recover import recover
from tests.test_sweep_log import small_sweep, write_log

ROOT = Path(__file__).resolve().parent.parent


def _chunks(path: Path) -> list[int]:
    """Chunk offsets from mcap's own reader (the summary's chunk index), not the walker."""
    with path.open("rb") as f:
        summary = make_reader(f).get_summary()
    assert summary is not None
    return sorted(c.chunk_start_offset for c in summary.chunk_indexes)


def _walk(path: Path) -> tuple[Walker, list[str]]:
    with path.open("rb") as f:
        walker = Walker(f, path)
        kinds = [kind for kind, _ in walker.records(read_chunks=True)]
    return walker, kinds


def _variant(tmp_path: Path, source: Path, name: str, data: bytes) -> Path:
    out = tmp_path / name
    out.write_bytes(data)
    assert out.read_bytes() != source.read_bytes()
    return out


@pytest.fixture
def slot_log(record_mcap) -> tuple[Path, list[int]]:
    path, _, _ = record_mcap("cucb", horizon=2500)  # three chunks: 1000, 1000, 500 slots
    offsets = _chunks(path)
    assert len(offsets) == 3
    return path, offsets


def test_a_finished_log_walks_to_its_footer(slot_log):
    path, _ = slot_log
    walker, kinds = _walk(path)
    assert kinds.count("chunk") == 3 and kinds[0] == "header" and kinds[-1] == "footer"
    assert not walker.truncated and walker.sealed
    assert walker.position == path.stat().st_size  # the closing magic included


def test_a_torn_last_chunk_is_cut_short_not_damage(tmp_path, slot_log):
    path, offsets = slot_log
    cut = _variant(tmp_path, path, "cut.mcap", path.read_bytes()[: offsets[2] + 40])
    walker, kinds = _walk(cut)
    assert walker.truncated and not walker.sealed
    assert kinds.count("chunk") == 2 and "footer" not in kinds
    assert walker.position == offsets[2]  # the byte after the last complete record
    log = open_log(cut)
    assert (log.status, log.n_slots) == ("truncated", 2000)


def test_the_same_tear_in_a_finished_file_is_damage(tmp_path, slot_log):
    """A file that ends with the MCAP magic was closed by its writer: a record that runs past
    its end cannot be a killed writer's torn tail."""
    path, offsets = slot_log
    sealed = path.read_bytes()[: offsets[2] + 40] + vocab.MAGIC
    bad = _variant(tmp_path, path, "sealed.mcap", sealed)
    with pytest.raises(LogError, match=rf"damaged at byte {offsets[2]}: a record \(opcode 0x06\)"):
        _walk(bad)


def _patched(tmp_path: Path, path: Path, at: int, data: bytes, name: str) -> Path:
    raw = bytearray(path.read_bytes())
    raw[at : at + len(data)] = data
    return _variant(tmp_path, path, name, bytes(raw))


def test_a_flipped_byte_in_a_chunk_is_damage(tmp_path, slot_log):
    path, offsets = slot_log
    at = offsets[0] + 9 + 32 + 4 + 8 + 200  # inside the compressed records
    flipped = bytes([path.read_bytes()[at] ^ 0xFF])
    bad = _patched(tmp_path, path, at, flipped, "flipped.mcap")
    with pytest.raises(LogError, match=rf"chunk at byte {offsets[0]} is damaged"):
        _walk(bad)


def test_an_absurd_chunk_size_is_refused_before_decompressing(tmp_path, slot_log):
    path, offsets = slot_log
    bad = _patched(tmp_path, path, offsets[0] + 9 + 16, struct.pack("<Q", 2**40), "big.mcap")
    with pytest.raises(LogError, match=r"it claims 1099511627776 bytes uncompressed"):
        _walk(bad)


def test_an_unknown_compression_is_named(tmp_path, slot_log):
    path, offsets = slot_log
    bad = _patched(tmp_path, path, offsets[0] + 9 + 32, b"zzzz", "zzzz.mcap")
    with pytest.raises(LogError, match=r"unknown compression 'zzzz'"):
        _walk(bad)


def _stream_reader_data(path: Path) -> list[object]:
    """StreamReader's data section, less the message indexes (which no reader uses)."""
    out: list[object] = []
    with path.open("rb") as f:
        for record in StreamReader(f).records:
            if isinstance(record, DataEnd):
                return out
            if not isinstance(record, MessageIndex):
                out.append(record)
    raise AssertionError("no data end")


def _walker_data(path: Path) -> list[object]:
    out: list[object] = []
    with path.open("rb") as f:
        for record in Walker(f, path).mcap_records():
            if record is None:
                return out
            out.append(record)
    raise AssertionError("no data end")


def test_mcap_records_are_stream_readers_records(tmp_path, slot_log):
    path, _ = slot_log
    sweep = write_log(tmp_path / "sweep.mcap", small_sweep(("ucb", "cucb"), runs=2, horizon=60))
    for source in (path, sweep):
        expected = _stream_reader_data(source)
        assert len(expected) > 3
        assert _walker_data(source) == expected


def test_every_mcap_reader_walks_through_the_walker(tmp_path, slot_log, monkeypatch):
    path, offsets = slot_log
    sweep = write_log(tmp_path / "sweep.mcap", small_sweep(("ucb",), runs=2, horizon=60))
    partial = tmp_path / "run.mcap.partial"
    partial.write_bytes(path.read_bytes()[: offsets[2] + 40])
    seen: list[str] = []
    real = Walker.records

    def spy(self, **kwargs):
        seen.append(self.path.name)
        return real(self, **kwargs)

    monkeypatch.setattr(Walker, "records", spy)
    readers = {
        "slot log": lambda: open_log(path).read_all(),
        "sweep log": lambda: read_sweep(sweep),
        "results": lambda: is_sweep_path(sweep),
        "recover": lambda: recover(partial, tmp_path / "fixed.mcap"),
    }
    for what, read in readers.items():
        seen.clear()
        read()
        assert seen, f"the {what} reader did not walk through corraoi.recorder.walk.Walker"
    assert (tmp_path / "fixed.mcap").is_file()


def _constants(tree: ast.AST) -> list[object]:
    return [node.value for node in ast.walk(tree) if isinstance(node, ast.Constant)]


def test_the_formats_names_are_defined_once():
    """The magic bytes appear in vocab.py only, and no other module assigns a topic, a schema
    name, a format name or a metadata record name of the slot or sweep log."""
    names = {
        vocab.SLOT_TOPIC, vocab.SWEEP_TOPIC, vocab.SLOT_SCHEMA_NAME, vocab.SWEEP_SCHEMA_NAME,
        vocab.SLOT_FORMAT_NAME, vocab.SWEEP_FORMAT_NAME, vocab.RUN_METADATA,
        vocab.RUN_END_METADATA, vocab.SWEEP_METADATA, vocab.SWEEP_END_METADATA,
    }  # fmt: skip
    offenders = []
    for pkg in ("corraoi", "recorder", "viewer"):
        for path in sorted((ROOT / pkg).rglob("*.py")):
            if path == ROOT / "recorder" / "vocab.py":
                continue
            tree = ast.parse(path.read_text(encoding="utf-8"))
            if vocab.MAGIC in _constants(tree):
                offenders.append(f"{path.name}: the MCAP magic")
            for node in ast.walk(tree):
                if (
                    isinstance(node, ast.Assign)
                    and isinstance(node.value, ast.Constant)
                    and node.value.value in names
                ):
                    offenders.append(f"{path.name}:{node.lineno}: {node.value.value!r}")
    assert not offenders, offenders


def test_the_slot_schema_requires_the_fields_in_block_order(make_config):
    assert slot_schema(make_config())["required"] == list(FIELDS)


def _silent_flip(raw: bytes, offset: int) -> int:
    """A byte of the chunk at ``offset`` whose flip zstd decodes without complaint, to the
    same records with other bytes in a message: only the CRC can tell (mcap's StreamReader,
    which the sweep reader used before the walker, checks none and reads the garbage)."""
    _, _, usize, crc, clen = struct.unpack_from("<QQQII", raw, offset + 9)
    (dlen,) = struct.unpack_from("<Q", raw, offset + 9 + 32 + clen)
    data_at = offset + 9 + 32 + clen + 8
    good = zstandard.ZstdDecompressor().decompress(raw[data_at : data_at + dlen], usize)
    heads = [body - 9 for _, body, _ in records_in(good, Path("x"), offset)]
    for at in range(data_at + 20, data_at + dlen):
        data = bytearray(raw[data_at : data_at + dlen])
        data[at - data_at] ^= 0x01
        try:
            out = zstandard.ZstdDecompressor().decompress(bytes(data), max_output_size=usize)
        except zstandard.ZstdError:
            continue
        same_frames = all(out[h : h + 9] == good[h : h + 9] for h in heads)
        if len(out) == usize and zlib.crc32(out) != crc and same_frames:
            return at
    raise AssertionError("no silent flip in the chunk")


def test_a_damaged_chunk_ends_a_sweep_log_where_it_starts(tmp_path):
    """The sweep reader checks each chunk's CRC through the walker: a flipped byte ends the
    curves at the chunk before it (status truncated), never decodes garbage as points."""
    path = write_log(tmp_path / "sweep.mcap", small_sweep(("ucb", "cucb"), runs=2, horizon=60),
                     flush_every=4)  # several chunks: the damaged one is not the first
    full = read_sweep(path)
    raw = path.read_bytes()
    at = _silent_flip(raw, _chunks(path)[-1])
    cut = read_sweep(_patched(tmp_path, path, at, bytes([raw[at] ^ 0x01]), "bad.mcap"))
    assert cut.status == "truncated" and 0 < cut.messages < full.messages
    for name, curve in cut.curves.items():
        assert list(curve.t) == list(full.curves[name].t[: len(curve)])


def test_a_damaged_slot_log_is_still_named_a_slot_log_by_the_sweep_reader(tmp_path, slot_log):
    path, offsets = slot_log
    at = offsets[0] + 9 + 32 + 4 + 8 + 200
    bad = _patched(tmp_path, path, at, bytes([path.read_bytes()[at] ^ 0xFF]), "bad.mcap")
    with pytest.raises(LogError, match="a per-slot run log, not a sweep log"):
        read_sweep(bad)
