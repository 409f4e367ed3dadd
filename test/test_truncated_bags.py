"""Truncated bags (a recorder that lost power): a ROS 1 bag, a ROS 2 mcap bag (bare file and
bag directory) and a ROS 2 sqlite3 bag cut at several byte offsets replay what is readable,
exit 0, say in one line how much was read, and their estimates are the first N of the whole
bag's replay. Cut inside the header: one line, exit 1. Bags written by rosbags' writers (through
``rosbags.convert``) from a simulated IMU stream; no ROS graph."""

from __future__ import annotations

import shutil
import struct
from pathlib import Path

import numpy as np
import pytest
from rosbags.convert import convert
from rosbags.highlevel import AnyReader

from cf_estimator.bag import salvage
from cf_estimator.bag.simulate import write_scenario_bag
from cf_estimator.bag.types import typestore
from cf_estimator.cli.main import main
from cf_estimator.scenarios import make_scenario


def _convert(src: Path, dst: Path, storage: str, compress: str | None = None) -> None:
    convert([src], dst, dst_storage=storage, dst_version=None if dst.suffix == ".bag" else 9,
            compress=compress, compress_mode="file" if dst.suffix != ".bag" else "storage",
            default_typestore=None, typestore=None, exclude_topics=[], include_topics=[],
            exclude_msgtypes=[], include_msgtypes=[])


@pytest.fixture(scope="module")
def bags(tmp_path_factory) -> dict[str, Path]:
    """Complete bags, 15 s at 200 Hz (IMU, magnetometer, ground truth): mcap (two chunks),
    ROS 1 (uncompressed and lz4 chunks), sqlite3."""
    d = tmp_path_factory.mktemp("full")
    sim = d / "sim"
    write_scenario_bag(make_scenario("static", rate_hz=200.0, duration_s=15.0), sim)
    out = {"mcap": d / "m", "ros1": d / "r.bag", "ros1-lz4": d / "rl.bag", "sqlite3": d / "s"}
    _convert(sim, out["mcap"], "mcap")
    _convert(sim, out["ros1"], "sqlite3")
    _convert(sim, out["ros1-lz4"], "sqlite3", "lz4")
    _convert(sim, out["sqlite3"], "sqlite3")
    return out


def _storage(bag: Path) -> Path:
    if bag.is_file():
        return bag
    return next(p for p in bag.iterdir() if p.suffix in (".mcap", ".db3"))


def _first_chunk_end(kind: str, data: bytes) -> int:
    """The byte after the first chunk record (mcap: after its message indexes too)."""
    if kind == "mcap":
        pos = 8
        while data[pos] != 0x06:
            pos += 9 + struct.unpack_from("<Q", data, pos + 1)[0]
        pos += 9 + struct.unpack_from("<Q", data, pos + 1)[0]
        while data[pos] == 0x07:
            pos += 9 + struct.unpack_from("<Q", data, pos + 1)[0]
        return pos
    pos = len(salvage.ROS1_MAGIC)
    _f, _d, pos = salvage._ros1_record(data, pos)  # noqa: SLF001 - the bag header
    while True:
        fields, _d, end = salvage._ros1_record(data, pos)  # noqa: SLF001
        if fields["op"] == b"\x05":
            return end
        pos = end


def _cut(bag: Path, where: str, dst_dir: Path, kind: str) -> Path:
    """A copy of ``bag`` whose storage file ends at ``where``."""
    data = _storage(bag).read_bytes()
    offset = {"mid": len(data) // 2, "late": len(data) * 3 // 4, "header": 50,
              "after-chunk": _first_chunk_end(kind, data) if where == "after-chunk" else 0,
              }[where]
    if bag.is_file():
        dst = dst_dir / f"cut_{where}{bag.suffix}"
        dst.write_bytes(data[:offset])
        return dst
    dst = dst_dir / f"cut_{where}"
    dst.mkdir()
    shutil.copy(bag / "metadata.yaml", dst / "metadata.yaml")
    (dst / _storage(bag).name).write_bytes(data[:offset])
    return dst


def _estimates(out: Path) -> tuple[np.ndarray, np.ndarray]:
    """Log times [ns] and (x, y, z, w) orientations of /imu/data in an output bag."""
    t, q = [], []
    with AnyReader([out], default_typestore=typestore()) as r:
        conns = [c for c in r.connections if c.topic == "/imu/data"]
        for c, log_ns, raw in r.messages(connections=conns):
            o = r.deserialize(raw, c.msgtype).orientation
            t.append(log_ns)
            q.append((o.x, o.y, o.z, o.w))
    return np.asarray(t), np.asarray(q)


@pytest.fixture(scope="module")
def full_replays(bags, tmp_path_factory) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    d = tmp_path_factory.mktemp("fullout")
    out = {}
    for kind, bag in bags.items():
        assert main(["replay", str(bag), "-o", str(d / kind), "--no-progress"]) == 0
        out[kind] = _estimates(d / kind)
    return out


CASES = [("mcap", "mid"), ("mcap", "after-chunk"), ("mcap", "late"),
         ("ros1", "mid"), ("ros1", "after-chunk"), ("ros1-lz4", "mid"), ("ros1-lz4", "late"),
         ("sqlite3", "mid"), ("sqlite3", "late")]


@pytest.mark.parametrize(("kind", "where"), CASES)
def test_a_truncated_bag_replays_what_is_readable(bags, full_replays, tmp_path, capsys, kind,
                                                  where):
    cut = _cut(bags[kind], where, tmp_path, kind)
    capsys.readouterr()
    rc = main(["replay", str(cut), "-o", str(tmp_path / "out"), "--no-progress"])
    err = capsys.readouterr().err
    assert rc == 0, err
    assert "Traceback" not in err
    lines = [ln for ln in err.splitlines() if "truncated" in ln]
    assert len(lines) == 1 and "the rest is lost" in lines[0] and cut.name in lines[0], err
    t, q = _estimates(tmp_path / "out")
    full_t, full_q = full_replays[kind]
    n = t.shape[0]
    assert 0 < n < full_t.shape[0]
    np.testing.assert_array_equal(t, full_t[:n])
    np.testing.assert_array_equal(q, full_q[:n])  # bit for bit: the same estimates
    # the line's count: every message read (IMU, magnetometer, ground truth)
    reader = salvage.SalvageReader(cut, salvage.truncation(cut) or "")
    assert f"read {reader.n_messages} messages" in lines[0]
    imu = sum(c.msgcount for c in reader.connections if c.topic == "/imu/data_raw")
    assert imu == n


def test_a_truncated_bare_mcap_replays_what_is_readable(bags, full_replays, tmp_path, capsys):
    data = _storage(bags["mcap"]).read_bytes()
    bare = tmp_path / "sent.mcap"
    bare.write_bytes(data[: len(data) * 2 // 3])
    capsys.readouterr()
    assert main(["replay", str(bare), "-o", str(tmp_path / "out"), "--no-progress"]) == 0
    err = capsys.readouterr().err
    assert "truncated mcap bag" in err and "Traceback" not in err
    t, q = _estimates(tmp_path / "out")
    np.testing.assert_array_equal(q, full_replays["mcap"][1][: t.shape[0]])


@pytest.mark.parametrize("kind", ["mcap", "ros1", "sqlite3"])
def test_a_bag_cut_inside_its_header_is_one_line(bags, tmp_path, capsys, kind):
    cut = _cut(bags[kind], "header", tmp_path, kind)
    capsys.readouterr()
    rc = main(["replay", str(cut), "-o", str(tmp_path / "out"), "--no-progress"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 1 and len(err) == 1 and cut.name in err[0] and "Traceback" not in err[0]
    assert not (tmp_path / "out").exists()


def test_complete_bags_are_not_taken_for_truncated(bags):
    for bag in bags.values():
        assert salvage.truncation(bag) is None
