"""The NumPy mcap reader (cf_estimator/bag/mcapread.py) yields what rosbags yields.

Message for message — connection, log time, bytes, order — against ``AnyReader.messages`` on
simulated, hostile (log times going back: chunks overlapping in time), replay-output (three
topics), compressed and damaged bags; the replay through it writes the bag the replay through
rosbags writes; bags it does not read (ROS 1, sqlite3) go to rosbags; a damaged bag is one
error line, never a traceback.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from rosbags.highlevel import AnyReader
from test_bulk_decode import _assert_same_bags, _hostile_bag
from test_replay import _convert

from cf_estimator.bag import io, mcapread
from cf_estimator.bag.formats import open_bag
from cf_estimator.bag.replay import ReplayOptions, replay_bag
from cf_estimator.bag.simulate import write_scenario_bag
from cf_estimator.cli.main import main
from cf_estimator.scenarios import make_scenario


def _with_rosbags(path: Path, topics: list[str] | None = None) -> list[tuple]:
    with AnyReader([path], default_typestore=io.typestore()) as reader:
        conns = [c for c in reader.connections if topics is None or c.topic in topics]
        return [(c.topic, c.msgtype, c.id, t, bytes(raw))
                for c, t, raw in reader.messages(connections=conns)]


def _with_mcapread(path: Path, topics: list[str] | None = None, size: int = 8192
                   ) -> list[tuple]:
    with AnyReader([path], default_typestore=io.typestore()) as reader:
        conns = [c for c in reader.connections if topics is None or c.topic in topics]
        source = mcapread.source_for(reader, conns)
        assert source is not None
        out = []
        for batch in source.batches(size):
            for i in range(len(batch)):
                c = source.connections[int(batch.conn[i])]
                out.append((c.topic, c.msgtype, c.id, int(batch.log_ns[i]), batch.raw(i)))
        return out


@pytest.fixture(scope="module")
def bags(tmp_path_factory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("mcapread")
    out = {"hostile": _hostile_bag(d / "hostile")}
    flight = make_scenario("flight", rate_hz=400.0, duration_s=30.0, seed=3)
    out["flight"] = write_scenario_bag(flight, d / "flight").path  # 3 topics, ~20 chunks
    replay_bag(out["flight"], d / "replayed", options=ReplayOptions(progress=False))
    out["replayed"] = d / "replayed"  # /imu/data, /imu/rpy, /diagnostics
    # chunks compressed with zstd (rosbags' storage compression)
    from rosbags.rosbag2 import CompressionFormat, CompressionMode, StoragePlugin, Writer

    src = out["flight"]
    w = Writer(d / "zstd", version=9, storage_plugin=StoragePlugin.MCAP)
    w.set_compression(CompressionMode.STORAGE, CompressionFormat.ZSTD)
    with AnyReader([src]) as reader, w:
        conns = {c.id: w.add_connection(c.topic, c.msgtype, typestore=io.typestore())
                 for c in reader.connections}
        for c, t, raw in reader.messages():
            w.write(conns[c.id], t, raw)
    out["zstd"] = d / "zstd"
    out["overlap"] = _overlapping_chunks(d / "overlap")
    return out


def _overlapping_chunks(path: Path) -> Path:
    """Three passes over the same log times (equal stamps in different chunks, several chunks
    per pass), two topics: rosbags' merge across chunks decides the order."""
    from cf_estimator.bag import cdr

    with io.OutputBag(path) as bag:
        for rep in range(3):
            for i in range(4000):
                t = 10**9 + 1_000_000 * i
                data = cdr.imu_cdr_fields(t // 10**9, t % 10**9, "imu", (0.0, 0.0, 0.0, 1.0),
                                          None, (rep, i, 0.0), None, (0.0, 0.0, 9.8), None)
                bag.write_raw("/imu/data_raw", io.IMU_TYPE, t, data)
                if i % 3 == rep:
                    bag.write_raw("/other", io.IMU_TYPE, t + 1, data)
    return path


@pytest.mark.parametrize("name", ["hostile", "flight", "replayed", "zstd", "overlap"])
def test_the_messages_and_their_order_are_rosbags(bags, name):
    path = bags[name]
    ref = _with_rosbags(path)
    assert len(ref) > 1000
    assert _with_mcapread(path) == ref
    topics = sorted({m[0] for m in ref})[:2]
    sub = _with_rosbags(path, topics)
    assert _with_mcapread(path, topics) == sub
    assert _with_mcapread(path, topics, size=7) == sub  # batches across chunk boundaries


def test_the_overlap_bag_has_chunks_overlapping_in_time(bags):
    """The merge across chunks (rosbags' heapq.merge of per-chunk sorted messages) is taken."""
    with AnyReader([bags["overlap"]]) as reader:
        chunks = sorted(reader.readers[0].storage.storages[0].chunks,
                        key=lambda c: c.chunk_start_offset)
    assert any(b.message_start_time <= a.message_end_time for a, b in zip(chunks, chunks[1:],
                                                                         strict=False))


def test_walking_every_chunk_record_by_record_gives_the_same(bags, monkeypatch):
    monkeypatch.setattr(mcapread.McapSource, "_from_index", lambda self, info, buf: None)
    for name in ("hostile", "replayed", "overlap"):
        assert _with_mcapread(bags[name]) == _with_rosbags(bags[name])


def _damaged(src: Path, dst: Path, edit) -> Path:
    shutil.copytree(src, dst)
    mcap = next(dst.glob("*.mcap"))
    data = bytearray(mcap.read_bytes())
    edit(data, src)
    mcap.write_bytes(bytes(data))
    return dst


def test_a_message_index_that_disagrees_with_the_chunk_is_not_believed(bags, tmp_path):
    """The index only proposes where records start; offsets that do not tile the chunk make
    the reader walk it as rosbags does."""
    with AnyReader([bags["flight"]]) as reader:
        storage = reader.readers[0].storage.storages[0]
        spots = [(c.chunk_start_offset + c.chunk_length, c.message_index_length)
                 for c in storage.chunks[:3]]

    def edit(data: bytearray, _src: Path) -> None:
        for start, length in spots:  # shift an offset of each index by one record header
            pos = start + 9 + 2 + 4 + 8 * 3
            assert pos + 8 <= start + length
            value = int.from_bytes(data[pos:pos + 8], "little")
            data[pos:pos + 8] = (value + 31).to_bytes(8, "little")

    bad = _damaged(bags["flight"], tmp_path / "badindex", edit)
    assert _with_mcapread(bad) == _with_rosbags(bad)


@pytest.mark.parametrize("seed", range(12))
def test_garbage_inside_the_data_reads_as_rosbags_reads_it_or_fails_as_it_does(bags, tmp_path,
                                                                              seed):
    rng = np.random.default_rng(seed)

    def edit(data: bytearray, _src: Path) -> None:
        at = int(rng.integers(100, len(data) // 2))
        n = int(rng.integers(1, 3000))
        data[at:at + n] = rng.integers(0, 256, n, dtype=np.uint8).tobytes()

    bad = _damaged(bags["flight"], tmp_path / f"garbage{seed}", edit)
    try:
        ref: list | Exception = _with_rosbags(bad)
    except Exception as exc:  # noqa: BLE001
        ref = exc
    if isinstance(ref, Exception):
        with pytest.raises(Exception):  # noqa: B017, PT011 - whatever rosbags raised
            _with_mcapread(bad)
    else:
        assert _with_mcapread(bad) == ref


@pytest.mark.parametrize("name", ["hostile", "flight"])
def test_the_replay_through_it_writes_the_bag_the_replay_through_rosbags_writes(
        bags, tmp_path, monkeypatch, name):
    opts = ReplayOptions(progress=False, mag_topic=None)
    fast = replay_bag(bags[name], tmp_path / "fast", options=opts)
    monkeypatch.setenv("CF_ESTIMATOR_MCAP_READER", "rosbags")
    slow = replay_bag(bags[name], tmp_path / "slow", options=opts)
    _assert_same_bags(tmp_path / "fast", tmp_path / "slow", fast.summary, slow.summary)


def test_ros1_and_sqlite3_bags_read_through_rosbags(bags, tmp_path):
    sq, ros1 = tmp_path / "sq", tmp_path / "flight.bag"
    _convert(bags["flight"], sq, "sqlite3")
    _convert(bags["flight"], ros1, "sqlite3")
    for path in (sq, ros1):
        with open_bag(path) as bag:
            conns = list(bag._reader.connections)  # noqa: SLF001
            assert mcapread.source_for(bag._reader, conns) is None  # noqa: SLF001
    with open_bag(bags["flight"]) as bag:
        conns = list(bag._reader.connections)  # noqa: SLF001
        assert mcapread.source_for(bag._reader, conns) is not None  # noqa: SLF001


def test_a_chunk_cut_short_is_one_error_line(bags, tmp_path, capsys):
    """A chunk record whose payload runs past the file's data (its length field damaged):
    one line naming the bag, exit 1, no output."""
    with AnyReader([bags["flight"]]) as reader:
        info = reader.readers[0].storage.storages[0].chunks[2]

    def edit(data: bytearray, _src: Path) -> None:
        pos = info.chunk_start_offset + 9 + 40 + len(info.compression)  # first record
        data[pos + 1:pos + 9] = (2**40).to_bytes(8, "little")  # a record length past the end

    bad = _damaged(bags["flight"], tmp_path / "cutchunk", edit)
    rc = main(["replay", str(bad), "-o", str(tmp_path / "out")])
    err = capsys.readouterr().err
    assert rc == 1
    lines = [ln for ln in err.splitlines() if ln.strip()]
    assert len(lines) == 1 and "cutchunk" in lines[0] and "Traceback" not in err
    assert not (tmp_path / "out").exists()
