"""A bare ``.mcap`` file (what people send each other) is a ROS 2 bag; a truncated one replays
its readable part, said in one line, no traceback (test/test_truncated_bags.py)."""

from __future__ import annotations

import json

from cf_estimator.cli.main import main


def _simulated(tmp_path):
    out = tmp_path / "sim"
    assert main(["simulate", "--scenario", "static", "--duration", "5", "-o", str(out)]) == 0
    return next(out.glob("*.mcap"))


def test_a_bare_mcap_file_replays_as_a_bag(tmp_path, capsys):
    mcap = _simulated(tmp_path)
    bare = tmp_path / "sent.mcap"
    bare.write_bytes(mcap.read_bytes())  # the file alone, no metadata.yaml beside it
    capsys.readouterr()
    assert main(["replay", str(bare), "--json", str(tmp_path / "s.json"), "--no-progress"]) == 0
    s = json.loads((tmp_path / "s.json").read_text())
    assert s["input_format"] == "ros2-mcap" and s["messages_in"] == 1000  # 5 s at 200 Hz


def test_a_truncated_bare_mcap_replays_its_readable_part_in_one_line(tmp_path, capsys):
    mcap = _simulated(tmp_path)
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(mcap.read_bytes()[: mcap.stat().st_size // 2])
    capsys.readouterr()
    code = main(["replay", str(cut), "--json", str(tmp_path / "s.json"), "--no-progress"])
    err = capsys.readouterr().err.strip().splitlines()
    s = json.loads((tmp_path / "s.json").read_text())
    assert code == 0 and not any("Traceback" in ln for ln in err)
    said = [ln for ln in err if "truncated mcap bag" in ln]
    assert len(said) == 1 and "cut.mcap" in said[0] and s["warnings"][0] in said[0]
    assert 0 < s["messages_in"] < 1000
