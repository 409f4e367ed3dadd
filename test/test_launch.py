"""The launch file compiles, defines generate_launch_description and declares its arguments."""

from __future__ import annotations

import ast
import importlib.util
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
LAUNCH = REPO / "launch_scripts" / "cf_estimator.launch.py"
EXPECTED_ARGUMENTS = {
    "params_file", "use_sim_time", "namespace", "node_name", "imu_topic", "mag_topic", "log_level",
    "velocity_topic", "world_frame", "body_frame", "output_frame_id", "tf_parent_frame",
    "publish_tf", "strict_parameters",
}


def _tree() -> ast.Module:
    return ast.parse(LAUNCH.read_text(encoding="utf-8"), str(LAUNCH))


def test_launch_file_compiles_and_defines_generate_launch_description():
    compile(LAUNCH.read_text(encoding="utf-8"), str(LAUNCH), "exec")
    functions = {n.name for n in _tree().body if isinstance(n, ast.FunctionDef)}
    assert "generate_launch_description" in functions


def test_launch_file_runs_the_installed_executable_with_the_shipped_config():
    text = LAUNCH.read_text(encoding="utf-8")
    assert 'executable="cf_estimator_node"' in text
    assert '"cf_estimator.yaml"' in text and (REPO / "config" / "cf_estimator.yaml").is_file()
    setup = (REPO / "setup.py").read_text(encoding="utf-8")
    assert "cf_estimator_node = cf_estimator.node.cf_estimator_node:main" in setup


def _declared_without_launch() -> set[str]:
    for node in _tree().body:
        if isinstance(node, ast.Assign) and any(
            isinstance(t, ast.Name) and t.id == "ARGUMENTS" for t in node.targets
        ):
            return {elt.elts[0].value for elt in node.value.elts}
    raise AssertionError("ARGUMENTS table not found")


def test_launch_arguments():
    if importlib.util.find_spec("launch") is None or importlib.util.find_spec("launch_ros") is None:
        # no ROS here: read the argument table from the source instead of running it
        assert _declared_without_launch() == EXPECTED_ARGUMENTS
        return
    from launch import LaunchDescription
    from launch.actions import DeclareLaunchArgument

    spec = importlib.util.spec_from_file_location("cf_estimator_launch", LAUNCH)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    description = module.generate_launch_description()
    assert isinstance(description, LaunchDescription)
    declared = {a.name for a in description.entities if isinstance(a, DeclareLaunchArgument)}
    assert declared == EXPECTED_ARGUMENTS
