"""``bench speed`` bag throughput: replay vs plain rosbags reads on a tiny simulated bag (fast).

No timing assertions: only counts, clean-up and the printed/JSON output are checked.
"""

from __future__ import annotations

import json
import tempfile
from pathlib import Path

import pytest

from cf_estimator.bag import replay
from cf_estimator.bag.simulate import IMU_TOPIC, MAG_TOPIC, write_scenario_bag
from cf_estimator.bench import speed
from cf_estimator.cli.main import main
from cf_estimator.scenarios import make_scenario


@pytest.fixture(scope="module")
def tiny_bag(tmp_path_factory):
    """1 s at rest, 200 Hz: 200 IMU, 100 mag, 100 ground-truth messages."""
    path = tmp_path_factory.mktemp("speed") / "static"
    return write_scenario_bag(make_scenario("static", duration_s=1.0), path)


@pytest.fixture
def private_tmp(tmp_path, monkeypatch):
    """tempfile's directory redirected to an empty folder, to see what is left behind."""
    d = tmp_path / "tmp"
    d.mkdir()
    monkeypatch.setattr(tempfile, "tempdir", str(d))
    return d


@pytest.fixture
def replay_outputs(monkeypatch):
    """Spy on replay_bag: (output path, was a bag, /imu/data count) of every call."""
    seen: list[tuple[Path, bool, int]] = []
    original = replay.replay_bag

    def spy(*args, **kwargs):
        result = original(*args, **kwargs)
        out = result.output
        seen.append((out, (out / "metadata.yaml").is_file(),
                     result.summary["outputs_written"].get(replay.OUT_IMU_TOPIC, 0)))
        return result

    monkeypatch.setattr(replay, "replay_bag", spy)
    return seen


def test_bag_throughput_counts_and_cleanup(tiny_bag, private_tmp, replay_outputs):
    n_imu, n_mag = tiny_bag.counts[IMU_TOPIC], tiny_bag.counts[MAG_TOPIC]
    r = speed.bag_throughput(tiny_bag.path, repeats=2)
    assert r.topics == {IMU_TOPIC: n_imu, MAG_TOPIC: n_mag}
    assert n_imu > 0
    assert r.messages == {"replay": n_imu + n_mag, "read": n_imu + n_mag,
                          "read_deserialize": n_imu + n_mag}
    assert min(r.replay_per_s, r.read_per_s, r.read_deserialize_per_s) > 0
    assert r.output_bytes > 0 and r.repeats == 2
    # the replay really wrote a bag (one /imu/data per IMU message), and it is gone now
    assert len(replay_outputs) == 2
    for out, was_bag, n_out in replay_outputs:
        assert was_bag and n_out == n_imu
        assert not out.exists()
    assert list(private_tmp.iterdir()) == []
    assert tiny_bag.path.is_dir()  # the input is left alone


def test_bag_throughput_default_bag_is_simulated_and_removed(private_tmp, monkeypatch):
    monkeypatch.setattr(speed, "DEFAULT_BAG_SCENARIO", ("static", 1.0))
    r = speed.bag_throughput(None, repeats=1)
    assert r.bag.startswith("simulated static")
    assert r.topics == {IMU_TOPIC: 200, MAG_TOPIC: 100}
    assert r.messages["read"] == r.messages["read_deserialize"] == r.messages["replay"] == 300
    assert list(private_tmp.iterdir()) == []


def test_cli_bench_speed_prints_replay_line(tiny_bag, private_tmp, tmp_path, capsys):
    out_json = tmp_path / "speed.json"
    # --peers "": the peers are optional extras; keeps the smoke test independent of them
    code = main(["bench", "speed", "--samples", "200", "--batch-sizes", "4", "--peers", "",
                 "--bag", str(tiny_bag.path), "--bag-repeats", "1", "--json", str(out_json)])
    assert code == 0
    text = capsys.readouterr().out
    assert "Bag throughput" in text
    replay_lines = [ln for ln in text.splitlines() if ln.strip().startswith("replay")]
    assert len(replay_lines) == 1 and "x" in replay_lines[0]
    doc = json.loads(out_json.read_text())
    assert doc["bag_throughput"]["topics"][IMU_TOPIC] == tiny_bag.counts[IMU_TOPIC]
    assert doc["bag_throughput"]["bag"] == str(tiny_bag.path)
    assert list(private_tmp.iterdir()) == []


def test_cli_bench_speed_bad_bag(tmp_path, capsys):
    code = main(["bench", "speed", "--samples", "200", "--peers", "",
                 "--bag", str(tmp_path / "missing.bag")])
    assert code == 2
    assert "missing.bag" in capsys.readouterr().err
