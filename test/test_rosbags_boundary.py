"""The rosbags range bag/io.py is tested with: pinned in setup.py, and what happens past it.

The reader and writer use rosbags' public API; the direct mcap path of ``OutputBag.write_raw``
and ``write_rows`` also writes into ``McapWriter``'s pending chunk (rosbags internals, for
replay speed). It is checked byte for byte against ``Writer.write`` in test/test_bulk_decode.py
on the installed release (and was on 0.11.0 and 0.11.9). Here: the pin and the gate agree, the
installed release takes the direct path (so those byte tests test it), and a release past the
pin falls back to the public ``Writer.write`` with the same file.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np
import pytest

from cf_estimator.bag import cdr, io, writer

SETUP = Path(__file__).resolve().parents[1] / "setup.py"


def test_setup_py_pins_the_range_the_gate_accepts():
    spec = re.search(r'"rosbags([^"]*)"', SETUP.read_text())
    assert spec is not None
    (lo_major, lo_minor), (hi_major, hi_minor) = io.ROSBAGS_TESTED
    assert spec.group(1) == f">={lo_major}.{lo_minor},<{hi_major}.{hi_minor}"


@pytest.mark.parametrize(("version", "inside"), [
    ((0, 10, 11), False), ((0, 11, 0), True), ((0, 11, 9), True), ((0, 11, 42), True),
    ((0, 12, 0), False), ((1, 0, 0), False), ((), False),
])
def test_the_gate_takes_exactly_the_tested_releases(version, inside):
    assert io.direct_mcap_supported(version) is inside


def test_the_installed_rosbags_is_in_the_range_and_takes_the_direct_path(tmp_path):
    assert io.direct_mcap_supported(), io.rosbags_version()
    with io.OutputBag(tmp_path / "bag") as bag:
        assert bag._mcap is not None  # the byte-for-byte tests exercise the direct path
    with io.OutputBag(tmp_path / "sq", storage="sqlite3") as bag:
        assert bag._mcap is None


def _write(path: Path, n: int) -> bytes:
    rng = np.random.default_rng(1)
    sec, nsec = rng.integers(0, 2**31 - 1, n), rng.integers(0, 10**9, n)
    q, g, a, rpy = (rng.normal(size=(n, k)) for k in (4, 3, 3, 3))
    rows = cdr.imu_cdr_rows(sec, nsec, "imu_link", q, (0.1,) * 9, g, (0.0,) * 9, a, (0.0,) * 9)
    vrows = cdr.vector3_stamped_rows(sec, nsec, "imu_link", rpy)
    log = (10**9 + 1000 * np.arange(n) - (np.arange(n) % 3) * 400).astype(np.int64)
    with io.OutputBag(path) as bag:
        bag.write_raw("/imu/first", io.IMU_TYPE, int(log[0]), rows[0].tobytes())
        bag.write_rows(log, [("/imu/data", io.IMU_TYPE, rows),
                             ("/imu/rpy", io.VECTOR3_STAMPED_TYPE, vrows)])
    return (path / f"{path.name}.mcap").read_bytes()


def test_past_the_pin_the_public_writer_writes_the_same_file(tmp_path, monkeypatch):
    """Over two mcap chunks: the direct path (installed rosbags) and the public Writer.write
    (a rosbags outside the range: 0.12) give the same bytes."""
    (tmp_path / "direct").mkdir()
    (tmp_path / "public").mkdir()
    direct = _write(tmp_path / "direct" / "bag", 6000)  # same name: it is inside the file
    assert len(direct) > 2**20
    monkeypatch.setattr(writer, "rosbags_version", lambda: (0, 12, 0))
    with io.OutputBag(tmp_path / "probe") as bag:
        assert bag._mcap is None
    public = _write(tmp_path / "public" / "bag", 6000)
    assert public == direct
