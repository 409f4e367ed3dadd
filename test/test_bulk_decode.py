"""Bulk CDR decoding of the inputs and one-call encoding of the outputs give the same bags.

Replay with ``bulk_decode`` (NumPy views over the fixed layout, :mod:`cf_estimator.bag.cdr`) and
message by message (rosbags' deserializer) must write the same output bag, bit for bit, on the
real ROS 1 bags and on hostile ones: NaN and Inf values, zero vectors, duplicate stamps, time
jumps back and forward, frame ids of every length and in UTF-8, a magnetometer with NaN.
"""

from __future__ import annotations

import math
import struct
from pathlib import Path

import numpy as np
import pytest
from test_replay import _convert, diagnostics_values, raw_messages

from cf_estimator.bag import cdr, io
from cf_estimator.bag.fleet import comparable
from cf_estimator.bag.replay import OUT_IMU_TOPIC, OUT_RPY_TOPIC, ReplayOptions, replay_bag
from cf_estimator.pipeline.pipeline import PipelineOutput

DATA_BAGS = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "bags"
REAL = sorted(DATA_BAGS.glob("*.bag")) if DATA_BAGS.is_dir() else []
FRAMES = ["", "a", "ab", "abc", "imu", "imu_", "imu_l", "imu_li", "imu_lin", "imu_link",
          "/imu", "ünïcødé_frame", "x" * 37]
NAN, INF = math.nan, math.inf


def _bits(x: float) -> bytes:
    return struct.pack("<d", x)


def _hostile_bag(path: Path, storage: str = "mcap") -> Path:
    """IMU at 100 Hz with every kind of trouble, and a magnetometer beside it."""
    rng = np.random.default_rng(7)
    t_ns = 1_700_000_000 * 10**9
    with io.OutputBag(path, storage=storage) as bag:
        bag.add_topic("/imu/data_raw", io.IMU_TYPE)
        bag.add_topic("/imu/mag", io.MAG_TYPE)
        for i in range(1500):
            step = 10_000_000
            if i == 300:
                step = 0  # duplicate stamp
            elif i == 500:
                step = -2_000_000_000  # time jumps back (a bag loop)
            elif i == 700:
                step = 3_000_000_000  # a long gap
            elif i == 900:
                step = -3_000_000  # slightly out of order
            t_ns += step
            g = list(rng.normal(0.0, 0.05, 3))
            a = [0.3 * x for x in rng.normal(0.0, 1.0, 3)]
            a[2] += 9.81
            if i % 97 == 5:
                g[1] = NAN
            if i % 131 == 7:
                a[0] = INF
            if i % 173 == 11:
                a = [0.0, 0.0, 0.0]
            if i % 59 == 3:
                g[2] = -0.0
            sec, nsec = divmod(t_ns, 10**9)
            frame = FRAMES[(i // 50) % len(FRAMES)]
            cov = [0.01 * i, NAN, -0.0, INF, 1e-300, 5e-324, 1.0, 2.0, 3.0]
            log = t_ns + 200_000 if i != 500 else t_ns + 2_100_000_000
            msg = io.imu_message(sec, nsec, frame, (0.0, 0.0, 0.0, 1.0), [-1.0] + [0.0] * 8,
                                 g, cov, a, None)
            bag.write("/imu/data_raw", io.IMU_TYPE, max(log, 1), msg)
            if i % 2 == 0:
                m = [2e-5, 1e-5, -4e-5]
                if i % 41 == 0:
                    m[1] = NAN
                mf = io.magnetic_field_message(sec, nsec, frame if i % 3 else "mag", m,
                                               [NAN] + [0.0] * 8)
                bag.write("/imu/mag", io.MAG_TYPE, max(log - 100_000, 1), mf)
    return path


@pytest.fixture(scope="module")
def hostile(tmp_path_factory) -> dict[str, Path]:
    d = tmp_path_factory.mktemp("hostile")
    mcap = _hostile_bag(d / "hostile_mcap")
    out = {"mcap": mcap, "sqlite3": _hostile_bag(d / "hostile_sqlite3", "sqlite3")}
    ros1 = d / "hostile.bag"
    _convert(mcap, ros1, "sqlite3")
    out["ros1"] = ros1
    return out


def _replay_both(src: Path, tmp: Path, **kw) -> tuple[Path, Path, dict, dict]:
    a, b = tmp / "bulk", tmp / "one_by_one"
    ra = replay_bag(src, a, options=ReplayOptions(progress=False, bulk_decode=True, **kw))
    rb = replay_bag(src, b, options=ReplayOptions(progress=False, bulk_decode=False, **kw))
    return a, b, ra.summary, rb.summary


def _assert_same_bags(a: Path, b: Path, sa: dict, sb: dict) -> None:
    for topic in (OUT_IMU_TOPIC, OUT_RPY_TOPIC):
        ma, mb = raw_messages(a, topic), raw_messages(b, topic)
        assert ma == mb and len(ma) > 0
    assert diagnostics_values(a) == diagnostics_values(b)
    ca, cb = comparable(sa), comparable(sb)
    ca.pop("output"), cb.pop("output")
    assert ca == cb


@pytest.mark.parametrize("kind", ["mcap", "sqlite3", "ros1"])
def test_bulk_and_message_by_message_replays_write_the_same_bag_on_hostile_input(
        hostile, tmp_path, kind):
    a, b, sa, sb = _replay_both(hostile[kind], tmp_path)
    _assert_same_bags(a, b, sa, sb)
    rejected = sa["messages_rejected"]  # the hostile parts really were there
    assert {"duplicate_stamp", "nonfinite_gyro", "nonfinite_accel", "zero_accel"} <= set(rejected)
    assert sa["resets"].get("time_jump_back") == 1 and sa["gaps"] >= 1
    assert sa["counters"]["mag_invalid"] > 0 and sa["counters"]["mag_used"] > 0


def test_bulk_and_message_by_message_replays_sample_the_same_bias_series(clean_flight, hostile,
                                                                          tmp_path):
    """The bulk path reads the bias estimate from the run's extra columns (b − Rᵀẑ·z_m, its σ)
    instead of stopping the filter at every 50 Hz sample: the series are the same, bit for bit,
    with and without a magnetometer heading (z_m ≠ 0)."""
    for name, src in (("clean", clean_flight), ("hostile", hostile["mcap"])):
        series = []
        for mode in (True, False):
            r = replay_bag(src, tmp_path / f"{name}_{mode}",
                           options=ReplayOptions(progress=False, bulk_decode=mode))
            series.append(r.series)
        fast, slow = series
        assert fast.bias_t_s.size > 50
        assert np.array_equal(fast.bias_t_s, slow.bias_t_s)
        assert np.array_equal(fast.gyro_bias_rad_s, slow.gyro_bias_rad_s)
        assert np.array_equal(fast.gyro_bias_sigma_rad_s, slow.gyro_bias_sigma_rad_s,
                              equal_nan=True)


@pytest.mark.parametrize("bag", REAL or [pytest.param(None, marks=pytest.mark.skip(
    reason=f"no recorded bags in {DATA_BAGS}"))], ids=[p.name for p in REAL] or ["no-bags"])
def test_bulk_and_message_by_message_replays_write_the_same_bag_on_real_ros1_bags(bag, tmp_path):
    a, b, sa, sb = _replay_both(bag, tmp_path)
    _assert_same_bags(a, b, sa, sb)


def test_offline_replay_with_the_input_imu_as_reference_is_the_same_too(hostile, tmp_path):
    a, b, sa, sb = _replay_both(hostile["mcap"], tmp_path, offline=True,
                                reference_topic="/imu/data_raw")
    _assert_same_bags(a, b, sa, sb)


@pytest.mark.parametrize("kind", ["mcap", "ros1"])
def test_decoded_fields_equal_the_deserialized_message_bit_for_bit(hostile, kind):
    with io.open_bag(hostile[kind]) as bag:
        topics = ["/imu/data_raw", "/imu/mag"]
        fast = list(bag.messages(topics, bulk=True))
    with io.open_bag(hostile[kind]) as bag:
        slow = list(bag.messages(topics))
    assert len(fast) == len(slow) == 2250
    assert any(isinstance(m.msg, cdr.ImuView) for m in fast)
    for f, s in zip(fast, slow, strict=True):
        assert (f.topic, f.msgtype, f.log_time_ns) == (s.topic, s.msgtype, s.log_time_ns)
        fm, sm = f.msg, s.msg
        assert (fm.header.stamp.sec, fm.header.stamp.nanosec, fm.header.frame_id) == \
            (sm.header.stamp.sec, sm.header.stamp.nanosec, sm.header.frame_id)
        if f.msgtype == io.IMU_TYPE:
            vecs = ("angular_velocity", "linear_acceleration")
            covs = ("orientation_covariance", "angular_velocity_covariance",
                    "linear_acceleration_covariance")
            q = [_bits(getattr(fm.orientation, c)) for c in "xyzw"]
            assert q == [_bits(getattr(sm.orientation, c)) for c in "xyzw"]
        else:
            vecs, covs = ("magnetic_field",), ("magnetic_field_covariance",)
        for v in vecs:
            assert [_bits(getattr(getattr(fm, v), c)) for c in "xyz"] == \
                [_bits(getattr(getattr(sm, v), c)) for c in "xyz"]
        for c in covs:
            assert np.asarray(getattr(fm, c)).tobytes() == np.asarray(getattr(sm, c)).tobytes()


def test_an_unusual_message_falls_back_to_rosbags(tmp_path):
    good = io.imu_message(1, 2, "imu", (0, 0, 0, 1), None, (0.1, 0.2, 0.3), None,
                          (0, 0, 9.8), None)
    raw = bytes(io.typestore().serialize_cdr(good, io.IMU_TYPE))
    calls = []

    def fallback(r: bytes, mt: str):
        calls.append(r)
        return "rosbags"

    bad_frame = raw[:16] + b"\xff" + raw[17:]  # a frame id that is not UTF-8
    out = cdr.decode([raw, raw[:-8], bad_frame, b"\x01\x00" + raw[2:]], io.IMU_TYPE, True,
                     fallback)
    assert isinstance(out[0], cdr.ImuView) and out[0].angular_velocity.y == 0.2
    assert out[1:] == ["rosbags"] * 3 and len(calls) == 3  # short, bad UTF-8, big-endian


def _output(frame: str, values: list[float]) -> PipelineOutput:
    v = iter(values)
    return PipelineOutput(
        1_700_000_000, 999_999_999, frame, (next(v), next(v), next(v), next(v)),
        tuple(next(v) for _ in range(9)), (next(v), next(v), next(v)),
        tuple(next(v) for _ in range(9)), (next(v), next(v), next(v)),
        tuple(next(v) for _ in range(9)), (next(v), next(v), next(v)), True,
    )


def test_output_encoding_is_what_rosbags_serializes_for_every_frame_length_and_value():
    store = io.typestore()
    specials = [NAN, -NAN, INF, -INF, -0.0, 0.0, 5e-324, 1e308, -1.0, 0.1]
    for k, frame in enumerate(FRAMES + [chr(0x1F600), "a b\tc"]):
        values = [specials[(k + i) % len(specials)] for i in range(40)]
        out = _output(frame, values)
        assert cdr.imu_cdr(out) == bytes(store.serialize_cdr(io.imu_from_output(out),
                                                             io.IMU_TYPE)), frame
        assert cdr.vector3_stamped_cdr(out.stamp_sec, out.stamp_nanosec, frame, out.rpy_rad) \
            == bytes(store.serialize_cdr(io.rpy_from_output(out), io.VECTOR3_STAMPED_TYPE))


def test_diagnostics_encoding_is_what_rosbags_serializes():
    """cdr.diagnostic_array_cdr = rosbags' serialize_cdr of io.diagnostics_message: the
    pipeline's own reports (before and after data) and odd ones (empty and non-ASCII strings,
    non-string values, string lengths that need every padding)."""
    from types import SimpleNamespace

    from cf_estimator.pipeline import ImuPipeline

    store = io.typestore()
    pipe = ImuPipeline()
    reports = [pipe.diagnostics(1.0)]
    for i in range(300):
        t_ns = 10**9 + 10_000_000 * i
        pipe.on_imu(io.imu_message(t_ns // 10**9, t_ns % 10**9, "imu", (0.0, 0.0, 0.0, 1.0),
                                   None, (0.01, 0.0, 0.0), None, (0.0, 0.0, 9.81), None))
    reports.append(pipe.diagnostics(4.0))
    for n in range(6):
        reports.append(SimpleNamespace(
            level=n % 4, name="x" * n, message=FRAMES[n], hardware_id=chr(0x1F600) * n,
            values=[("k" * j, j * 0.5) for j in range(n)] + [("ünï", None), ("", "")]))
    for picked in ([], reports[:1], reports[1:2], reports):
        for t in (0, 1, 10**9 + 7, 1_700_000_000_123_456_789):
            assert cdr.diagnostic_array_cdr(t, picked) == bytes(store.serialize_cdr(
                io.diagnostics_message(t, picked), io.DIAGNOSTIC_ARRAY_TYPE))


@pytest.mark.parametrize("storage", ["mcap", "sqlite3"])
def test_write_raw_gives_the_file_rosbags_writer_writes(tmp_path, storage):
    """Over 1 MB (several chunks), three topics, non-monotonic log times: same bytes."""
    store = io.typestore()
    msgs = []
    for i in range(6000):
        out = _output(FRAMES[i % len(FRAMES)], [0.001 * i + k for k in range(40)])
        msgs.append((OUT_IMU_TOPIC, io.IMU_TYPE, 10**9 + 1000 * i - (i % 7) * 333,
                     io.imu_from_output(out)))
        msgs.append((OUT_RPY_TOPIC, io.VECTOR3_STAMPED_TYPE, 10**9 + 1000 * i,
                     io.rpy_from_output(out)))
        if i % 500 == 0:
            msgs.append(("/diagnostics", io.DIAGNOSTIC_ARRAY_TYPE, 10**9 + 1000 * i,
                         io.diagnostics_message(10**9 + 1000 * i, [])))
    # the reference: rosbags' own Writer, as OutputBag sets it up
    from rosbags.rosbag2 import Writer

    from cf_estimator.bag.writer import ROSBAG2_VERSION, STORAGES

    (tmp_path / "rosbags").mkdir()
    ref = Writer(tmp_path / "rosbags" / "bag", version=ROSBAG2_VERSION,
                 storage_plugin=STORAGES[storage])
    ref.open()
    conns = {}
    for topic, msgtype, t, m in msgs:
        if topic not in conns:
            conns[topic] = ref.add_connection(topic, msgtype, typestore=store)
        ref.write(conns[topic], t, store.serialize_cdr(m, msgtype))
    ref.close()
    for name, raw in (("objects", False), ("raw", True)):
        (tmp_path / name).mkdir()
        with io.OutputBag(tmp_path / name / "bag", storage=storage) as bag:
            for topic, msgtype, t, m in msgs:
                if raw:
                    bag.write_raw(topic, msgtype, t, bytes(store.serialize_cdr(m, msgtype)))
                else:
                    bag.write(topic, msgtype, t, m)
    a = tmp_path / "rosbags" / "bag"
    for b in (tmp_path / "objects" / "bag", tmp_path / "raw" / "bag"):
        files = sorted(p.name for p in a.iterdir())
        assert files == sorted(p.name for p in b.iterdir())
        if storage == "mcap":
            assert (a / "bag.mcap").stat().st_size > 2**21
            assert (a / "bag.mcap").read_bytes() == (b / "bag.mcap").read_bytes()
        assert (a / "metadata.yaml").read_text() == (b / "metadata.yaml").read_text()
        for topic in (OUT_IMU_TOPIC, OUT_RPY_TOPIC, "/diagnostics"):
            assert raw_messages(a, topic) == raw_messages(b, topic)


def test_bulk_encoding_and_write_rows_give_the_bytes_of_message_by_message_writes(tmp_path):
    """Vectorized CDR rows = one-call encodings; write_rows = write_raw per message (several
    mcap chunks, log times not monotonic, a NaN and -0.0 in the values)."""
    rng = np.random.default_rng(3)
    n = 9000
    sec = rng.integers(0, 2**31 - 1, n)
    nsec = rng.integers(0, 10**9, n)
    q = rng.normal(size=(n, 4))
    g, a, rpy = rng.normal(size=(n, 3)), rng.normal(size=(n, 3)), rng.normal(size=(n, 3))
    q[5, 2], g[7, 0], a[9, 1] = NAN, -0.0, INF
    cov, gcov, acov = (0.1,) * 9, tuple(np.arange(9.0)), (NAN,) + (0.0,) * 8
    log = (10**9 + 1000 * np.arange(n) - (np.arange(n) % 5) * 777).astype(np.int64)
    for frame in ("imu_link", "", "ünï"):
        rows = cdr.imu_cdr_rows(sec, nsec, frame, q, cov, g, gcov, a, acov)
        vrows = cdr.vector3_stamped_rows(sec, nsec, frame, rpy)
        for k in (0, 5, 7, 9, n - 1):
            assert rows[k].tobytes() == cdr.imu_cdr_fields(
                int(sec[k]), int(nsec[k]), frame, q[k].tolist(), cov, g[k].tolist(), gcov,
                a[k].tolist(), acov)
            assert vrows[k].tobytes() == cdr.vector3_stamped_cdr(int(sec[k]), int(nsec[k]),
                                                                 frame, rpy[k].tolist())
    (tmp_path / "one").mkdir()
    (tmp_path / "rows").mkdir()
    calls = ((0, 1), (1, 4000), (4000, 4001), (4001, 6500), (6500, n))  # several calls
    # a diagnostics message (bag.write) after each call but the last, as the replay writes
    diag_after = {hi - 1 for _lo, hi in calls[:-1]}

    def diagnostics(bag: io.OutputBag, k: int) -> None:
        bag.write("/diagnostics", io.DIAGNOSTIC_ARRAY_TYPE, int(log[k]),
                  io.diagnostics_message(int(log[k]), []))

    with io.OutputBag(tmp_path / "one" / "bag") as bag:
        for k in range(n):
            bag.write_raw(OUT_IMU_TOPIC, io.IMU_TYPE, int(log[k]), rows[k].tobytes())
            bag.write_raw(OUT_RPY_TOPIC, io.VECTOR3_STAMPED_TYPE, int(log[k]),
                          vrows[k].tobytes())
            if k in diag_after:
                diagnostics(bag, k)
    with io.OutputBag(tmp_path / "rows" / "bag") as bag:
        for lo, hi in calls:
            bag.write_rows(log[lo:hi], [(OUT_IMU_TOPIC, io.IMU_TYPE, rows[lo:hi]),
                                        (OUT_RPY_TOPIC, io.VECTOR3_STAMPED_TYPE,
                                         vrows[lo:hi])])
            if hi - 1 in diag_after:
                diagnostics(bag, hi - 1)
    one, many = tmp_path / "one" / "bag", tmp_path / "rows" / "bag"
    assert (one / "bag.mcap").stat().st_size > 3 * 2**20
    assert (one / "bag.mcap").read_bytes() == (many / "bag.mcap").read_bytes()
    assert (one / "metadata.yaml").read_text() == (many / "metadata.yaml").read_text()


#: The clean flight (the scenario's shortest): 40 diagnostics periods and four 1 024-message
#: chunks of message objects, so the two reading paths cut it differently.
CLEAN_RATE_HZ, CLEAN_S = 100.0, 40.0
CLEAN_MESSAGES = int(CLEAN_RATE_HZ * CLEAN_S)


@pytest.fixture(scope="module")
def clean_flight(tmp_path_factory) -> Path:
    from cf_estimator.bag.simulate import write_scenario_bag
    from cf_estimator.scenarios import make_scenario

    d = tmp_path_factory.mktemp("clean")
    flight = make_scenario("uav", rate_hz=CLEAN_RATE_HZ, duration_s=CLEAN_S, seed=5)
    return write_scenario_bag(flight, d / "uav").path


@pytest.mark.parametrize("variant", [
    {"filter": {"world_frame": "ned"}},
    {"filter": {"use_mag": False}},
    {"pipeline": {"publish_rpy": False, "rpy_unwrap": False}},
    {"pipeline": {"max_dt_s": 0.0021, "reset_after_gap_s": 0.0}},  # every interval a "gap"
    {"mag_topic": "none"},
    {"pipeline": {"body_frame": "frd"}},  # ENU world, FRD input: the half turn about x
    {"filter": {"world_frame": "ned"}, "pipeline": {"body_frame": "flu"}},
])
@pytest.mark.parametrize("bag", ["clean", "hostile"])
def test_bulk_pipeline_equals_message_by_message_for_other_parameters(
        variant, bag, clean_flight, hostile, tmp_path):
    import dataclasses

    from cf_estimator.core.params import FilterParams
    from cf_estimator.pipeline import PipelineParams

    src = clean_flight if bag == "clean" else hostile["mcap"]
    fp = dataclasses.replace(FilterParams(), **variant.get("filter", {}))
    pp = dataclasses.replace(PipelineParams(), **variant.get("pipeline", {}))
    out = {}
    for mode, kw in (("bulk", {}), ("one", {"bulk_decode": False})):
        opts = ReplayOptions(progress=False, mag_topic=variant.get("mag_topic"), **kw)
        out[mode] = replay_bag(src, tmp_path / mode, fp, pp, opts).summary
    a, b = tmp_path / "bulk", tmp_path / "one"
    topics = (OUT_IMU_TOPIC, OUT_RPY_TOPIC) if pp.publish_rpy else (OUT_IMU_TOPIC,)
    for topic in topics:
        assert raw_messages(a, topic) == raw_messages(b, topic)
    assert diagnostics_values(a) == diagnostics_values(b)
    ca, cb = comparable(out["bulk"]), comparable(out["one"])
    ca.pop("output"), cb.pop("output")
    assert ca == cb


def test_the_pipeline_takes_almost_every_message_of_a_clean_flight_in_runs(clean_flight,
                                                                          tmp_path,
                                                                          monkeypatch):
    from cf_estimator.pipeline import checks, process

    rows = []
    real = process._run  # noqa: SLF001 - counting the runs

    def counted(pipe, c, p, e):
        out = real(pipe, c, p, e)
        rows.extend(r.n for r in out or ())
        return out

    monkeypatch.setattr(process, "_run", counted)
    s = replay_bag(clean_flight, tmp_path / "o", options=ReplayOptions(progress=False)).summary
    assert s["messages_processed"] == s["messages_in"] == CLEAN_MESSAGES
    # after the start-up checks (the first 200 samples' units, one at a time): runs of about
    # a second each, up to the next diagnostics report
    runs = [n for n in rows if n > 1]
    assert sum(runs) >= CLEAN_MESSAGES - checks.ACCEL_CHECK_SAMPLES and len(runs) < 100
