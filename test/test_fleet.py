"""Many recordings per command (replay, tune, bench) and the same work on a Dask LocalCluster.

The fleet: short simulated flights (ROS 2 mcap and sqlite3), a copy of a real ROS 1 bag, and
broken ones (a truncated ROS 1 bag, storage without metadata.yaml, a bag without IMU topic).
The cluster tests start one LocalCluster of 2 worker processes on the loopback interface for the
module and compare every result with the local run: identical, bit for bit.
"""

from __future__ import annotations

import json
import shutil
import sys
from pathlib import Path

import pytest
from test_replay import diagnostics_values, raw_messages

from cf_estimator.bag import fleet, io
from cf_estimator.bag.replay import OUT_IMU_TOPIC, OUT_RPY_TOPIC, ReplayOptions
from cf_estimator.bag.simulate import write_scenario_bag
from cf_estimator.cli.main import main
from cf_estimator.core.params import FilterParams
from cf_estimator.pipeline import PipelineParams
from cf_estimator.scenarios import make_scenario

DATA_BAGS = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "bags"
ARDRONE = DATA_BAGS / "ardrone_imu.bag"


@pytest.fixture(scope="module")
def good_dir(tmp_path_factory) -> Path:
    """Three good bags: two simulated flights (mcap, sqlite3 in a sub-directory), one real."""
    d = tmp_path_factory.mktemp("fleet_good")
    write_scenario_bag(make_scenario("flight", rate_hz=100.0, duration_s=20.0, seed=1),
                       d / "a_flight", storage="mcap")
    (d / "sub").mkdir()
    write_scenario_bag(make_scenario("flight", rate_hz=50.0, duration_s=20.0, seed=2),
                       d / "sub" / "b_flight", storage="sqlite3")
    if ARDRONE.is_file():
        shutil.copy(ARDRONE, d / "ardrone_imu.bag")
    return d


@pytest.fixture(scope="module")
def mixed_dir(tmp_path_factory, good_dir) -> Path:
    """The good bags plus a truncated ROS 1 bag, a storage dir without metadata.yaml and a bag
    with no IMU topic."""
    d = tmp_path_factory.mktemp("fleet_mixed")
    shutil.copytree(good_dir, d, dirs_exist_ok=True)
    (d / "truncated.bag").write_bytes((good_dir / "a_flight" / "a_flight.mcap").read_bytes()
                                      [:5000] if not ARDRONE.is_file()
                                      else ARDRONE.read_bytes()[:30000])
    (d / "no_metadata").mkdir()
    shutil.copy(good_dir / "a_flight" / "a_flight.mcap", d / "no_metadata" / "x.mcap")
    with io.OutputBag(d / "no_imu") as bag:  # only a magnetometer topic
        bag.write("/imu/mag", io.MAG_TYPE, 1, io.magnetic_field_message(1, 0, "imu", (2e-5, 0, 0)))
    return d


def test_find_bags_lists_ros1_ros2_and_broken_bags_in_sorted_order(mixed_dir):
    names = [p.relative_to(mixed_dir).as_posix() for p in fleet.find_bags([mixed_dir])]
    expected = ["a_flight", "no_imu", "no_metadata", "sub/b_flight", "truncated.bag"]
    if ARDRONE.is_file():
        expected.insert(1, "ardrone_imu.bag")
    assert names == expected


def test_output_names_are_unique_even_when_bag_names_clash(tmp_path):
    bags = [tmp_path / "x" / "run.bag", tmp_path / "y" / "run.bag", tmp_path / "y" / "other"]
    assert fleet.output_names(bags) == ["x_run", "y_run", "y_other"]
    assert fleet.output_names(bags[1:]) == ["run", "other"]


def test_replay_of_a_directory_reports_each_broken_bag_on_one_line_and_goes_on(
        mixed_dir, tmp_path, capsys):
    out, js = tmp_path / "out", tmp_path / "fleet.json"
    code = main(["replay", str(mixed_dir), "-o", str(out), "--json", str(js), "--no-progress"])
    printed = capsys.readouterr().out
    failed = [line for line in printed.splitlines() if line.startswith("FAILED")]
    assert code == 1 and len(failed) == 3  # exit status 1: some bags failed (not 2: usage)
    assert any("truncated.bag" in f for f in failed)
    assert any("no_metadata" in f and "metadata.yaml" in f for f in failed)
    assert any("no_imu" in f and "no IMU messages" in f for f in failed)
    doc = json.loads(js.read_text())
    good = 3 if ARDRONE.is_file() else 2
    assert doc["fleet"]["bags"] == good + 3 and doc["fleet"]["replayed"] == good
    assert doc["fleet"]["failed"] == 3 and len(doc["failures"]) == 3
    for s in doc["bags"]:  # one output bag per good input, with every IMU message processed
        assert Path(s["output"]) == out / s["name"]
        assert (out / s["name"] / "metadata.yaml").is_file()
        assert s["outputs_written"][OUT_IMU_TOPIC] == s["messages_processed"] > 0
    assert sorted(p.name for p in out.iterdir()) == sorted(s["name"] for s in doc["bags"])
    assert "fleet   " in printed and f"{good} of {good + 3} bag(s) replayed, 3 failed" in printed


def test_a_fleet_replay_writes_what_single_replays_write(good_dir, tmp_path):
    single = tmp_path / "single"
    assert main(["replay", str(good_dir / "a_flight"), "-o", str(single), "--no-progress"]) == 0
    assert main(["replay", str(good_dir), "-o", str(tmp_path / "many"), "--no-progress"]) == 0
    many = tmp_path / "many" / "a_flight"
    for topic in (OUT_IMU_TOPIC, OUT_RPY_TOPIC):
        assert raw_messages(single, topic) == raw_messages(many, topic)
    assert diagnostics_values(single) == diagnostics_values(many)


def test_no_bags_in_directories_is_a_one_line_usage_error(tmp_path, capsys):
    for d in ("empty", "empty2"):
        (tmp_path / d).mkdir()
    assert main(["replay", str(tmp_path / "empty"), str(tmp_path / "empty2"), "--json",
                 str(tmp_path / "j")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("cf-estimator: error: no bags found in") and "\n" not in err


def test_without_cluster_nothing_of_dask_is_imported(good_dir, tmp_path):
    import subprocess

    code = (
        "import sys\n"
        "from cf_estimator.cli.main import main\n"
        f"rc = main(['replay', {str(good_dir)!r}, '--json', {str(tmp_path / 'j.json')!r}, "
        "'--no-progress'])\n"
        "assert rc == 0, rc\n"
        "bad = sorted(m for m in sys.modules if m.split('.')[0] in ('dask', 'distributed'))\n"
        "print(bad)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip().splitlines()[-1] == "[]"


def test_cluster_option_errors_are_one_line(good_dir, tmp_path, capsys, monkeypatch):
    from cf_estimator import cluster

    # nothing listens on port 1: the refusal comes at once, the 20 s wait is for slow networks
    monkeypatch.setattr(cluster, "CONNECT_TIMEOUT_S", 2.0)
    for value, text in (("local:0", "N must be a whole number >= 1"),
                        ("tcp://127.0.0.1:1", "cannot start or reach the cluster")):
        rc = main(["replay", str(good_dir), "--json", str(tmp_path / "x.json"), "--cluster",
                   value, "--overwrite"])
        err = capsys.readouterr().err.strip()
        assert rc == 2, err
        assert text in err and "\n" not in err


# -- the same work on a LocalCluster ---------------------------------------------------------
@pytest.fixture(scope="module")
def engine():
    pytest.importorskip("distributed")
    from cf_estimator.cluster import make_engine

    with make_engine("local:2") as e:
        yield e


def test_replay_on_a_local_cluster_is_identical_to_the_local_run(mixed_dir, tmp_path, engine):
    opts = ReplayOptions(progress=False)
    bags = fleet.find_bags([mixed_dir])
    local = fleet.replay_fleet(fleet.make_tasks(bags, str(tmp_path / "local"), None,
                                                FilterParams(), PipelineParams(), opts))
    remote = fleet.replay_fleet(fleet.make_tasks(bags, str(tmp_path / "remote"), None,
                                                 FilterParams(), PipelineParams(), opts), engine)
    assert remote["fleet"]["engine"].startswith("Dask LocalCluster, 2 worker")
    assert local["failures"] == remote["failures"] and len(local["failures"]) == 3
    assert len(local["bags"]) == len(remote["bags"]) >= 2
    for a, b in zip(local["bags"], remote["bags"], strict=True):
        a, b = fleet.comparable(a), fleet.comparable(b)
        assert a.pop("output") != b.pop("output")
        assert a == b
        for topic in (OUT_IMU_TOPIC, OUT_RPY_TOPIC):
            assert raw_messages(tmp_path / "local" / a["name"], topic) == \
                raw_messages(tmp_path / "remote" / a["name"], topic)
        assert diagnostics_values(tmp_path / "local" / a["name"]) == \
            diagnostics_values(tmp_path / "remote" / a["name"])


def test_a_path_no_worker_can_read_is_refused_in_one_line(engine, tmp_path):
    from cf_estimator.cluster import ClusterError

    with pytest.raises(ClusterError, match="cannot read .*missing.bag.*every worker mounts"):
        engine.check_paths([str(tmp_path / "missing.bag")])
    a_file = tmp_path / "a_file"
    a_file.write_text("")
    with pytest.raises(ClusterError, match="not writable"):  # an output below a regular file
        engine.check_paths([], writable=[str(a_file / "out")])
    engine.check_paths([str(a_file)], writable=[str(tmp_path / "new" / "out")])  # fine


def test_tune_over_many_bags_on_a_local_cluster_matches_the_local_run(good_dir, tmp_path,
                                                                       engine, capsys):
    flights = [str(good_dir / "a_flight"), str(good_dir / "sub" / "b_flight")]
    common = ["tune", "--bag", *flights, "--candidates", "6", "--passes", "2", "--decimate",
              "4", "--scenario-limit", "none", "--seed", "3", "--force"]  # a tiny search
    assert main([*common, "--jobs", "1", "--out", str(tmp_path / "local.yaml")]) == 0
    local = capsys.readouterr().out
    assert main([*common, "--cluster", "local:2", "--out", str(tmp_path / "dask.yaml")]) == 0
    remote = capsys.readouterr().out
    assert "tune: 2 trial(s)" in local
    assert (tmp_path / "local.yaml").read_text() == (tmp_path / "dask.yaml").read_text()

    def objective(text: str) -> str:
        return next(line for line in text.splitlines() if line.startswith("objective"))

    assert objective(local) == objective(remote)


def test_tune_leaves_out_an_unreadable_bag_and_exits_with_the_count(mixed_dir, tmp_path,
                                                                     capsys):
    rc = main(["tune", "--bag", str(mixed_dir / "a_flight"), str(mixed_dir / "truncated.bag"),
               "--candidates", "4", "--passes", "1", "--scenario-limit", "none", "--decimate",
               "4", "--jobs", "1"])
    out = capsys.readouterr().out
    assert rc == 1
    assert out.splitlines()[0].startswith("FAILED") and "truncated.bag" in out.splitlines()[0]
    assert "1 bag(s) could not be read" in out


def test_score_candidates_on_a_cluster_gives_the_local_arrays(good_dir, engine):
    from cf_estimator.bench import bagtrial, tuning

    trials = [bagtrial.load_bag_trial(good_dir / "a_flight").decimated(2)]
    cands = [FilterParams(), FilterParams(k1=0.9, k2=0.02)]
    local = tuning.score_candidates(cands, trials, jobs=1)
    remote = tuning.score_candidates(cands, trials, jobs=engine)
    for name in local:
        for a, b in zip(local[name], remote[name], strict=True):
            assert a.tobytes() == b.tobytes()


BROAD = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "broad"


@pytest.mark.skipif(not BROAD.is_dir(), reason=f"BROAD data not available in {BROAD}")
def test_bench_broad_on_a_local_cluster_matches_the_local_run(tmp_path, engine, capsys):
    args = ["bench", "broad", "--data", str(BROAD), "--trials", "02,07", "--peers", "none",
            "--quiet"]
    assert main([*args, "--json", str(tmp_path / "l.json"), "--jobs", "1"]) == 0
    assert main([*args, "--json", str(tmp_path / "d.json"), "--cluster", "local:2"]) == 0
    capsys.readouterr()
    assert (tmp_path / "l.json").read_bytes() == (tmp_path / "d.json").read_bytes()


def test_bench_fleet_prints_throughputs_and_finds_the_cluster_results_identical(tmp_path,
                                                                                 capsys):
    pytest.importorskip("distributed")
    js = tmp_path / "fleet.json"
    rc = main(["bench", "fleet", "--flights", "2", "--duration", "40", "--rate", "50",
               "--workers", "1", "--candidates", "3", "--json", str(js)])
    out = capsys.readouterr().out
    assert rc == 0, out
    doc = json.loads(js.read_text())
    assert [r["workers"] for r in doc["runs"]] == [0, 1]
    assert doc["runs"][0]["identical"] is None and doc["runs"][1]["identical"] is True
    assert doc["imu_messages"] == 2 * 40 * 50 and doc["candidates"] == 3
    for r in doc["runs"]:
        assert r["replay_messages"] == 2 * (2000 + 2000) and r["replay_messages_per_s"] > 0
        assert r["param_samples"] == 3 * 4000 and r["param_samples_per_s"] > 0
    rows = [line.split() for line in out.splitlines() if line.startswith("  no Dask")
            or line.startswith("  LocalCluster")]
    assert len(rows) == 2 and rows[0][-1] == "reference" and rows[1][-1] == "yes"
