"""Parameter files: the shipped YAML, the schema and the dataclass defaults agree key by key."""

from __future__ import annotations

import dataclasses
import re
from pathlib import Path

import pytest
import yaml

from cf_estimator.core.params import FilterParams
from cf_estimator.params_file import (
    all_specs,
    build_params,
    describe_unknown,
    format_value,
    load_params_file,
    node_key_matches,
    render_params_yaml,
    unknown_keys,
    unknown_names,
)
from cf_estimator.pipeline.params import PipelineParams
from cf_estimator.schema import ParameterError, as_dict, specs_of

REPO = Path(__file__).resolve().parents[1]
SHIPPED = REPO / "config" / "cf_estimator.yaml"


def _section(path: Path) -> dict:
    doc = yaml.safe_load(path.read_text(encoding="utf-8"))
    assert list(doc) == ["/**"], "the shipped file must use the /** wildcard"
    return doc["/**"]["ros__parameters"]


def test_all_specs_is_filter_then_pipeline_without_duplicates():
    names = [s.name for s in all_specs()]
    expected = [s.name for s in specs_of(FilterParams) + specs_of(PipelineParams)]
    assert names == expected
    assert len(names) == len(set(names))


def test_shipped_yaml_is_the_rendered_defaults():
    assert SHIPPED.read_text(encoding="utf-8") == render_params_yaml(), (
        "config/cf_estimator.yaml is stale: run "
        "`python3 -m cf_estimator.params_file > config/cf_estimator.yaml`"
    )


def test_yaml_schema_and_dataclass_defaults_agree_key_by_key():
    section = _section(SHIPPED)
    specs = {s.name: s for s in all_specs()}
    defaults = {**as_dict(FilterParams()), **as_dict(PipelineParams())}
    assert list(section) == list(specs) == list(defaults)
    for name, spec in specs.items():
        field_default = next(
            f.default for cls in (FilterParams, PipelineParams)
            for f in dataclasses.fields(cls) if f.name == name
        )
        value = section[name]
        if spec.kind == "float_list":  # a YAML list of floats, a tuple in Python
            assert all(type(v) is float for v in value), f"{name}: YAML elements not floats"
            value = tuple(value)
        assert value == spec.default == defaults[name] == field_default, name
        assert type(value) is type(spec.default), f"{name}: YAML type differs"


def test_every_parameter_has_a_comment_with_unit_and_range():
    text = SHIPPED.read_text(encoding="utf-8")
    for spec in all_specs():
        block = re.search(rf"((?:    #.*\n)+)    {spec.name}: ", text)
        assert block, f"{spec.name}: no comment above it"
        comment = " ".join(line.strip("# ") for line in block.group(1).splitlines())
        if spec.unit:
            assert f"[{spec.unit}]" in comment, spec.name
        if spec.range_text():
            assert spec.range_text() in comment, spec.name
        assert spec.description.split()[0] in comment, spec.name


def test_floats_are_always_written_as_floats():
    text = SHIPPED.read_text(encoding="utf-8")
    for spec in all_specs():
        if spec.kind == "float":
            value = re.search(rf"^    {spec.name}: (\S+)$", text, re.M).group(1)
            assert "." in value, f"{spec.name}: {value}"
    spec = next(s for s in all_specs() if s.name == "k1")
    for x, text in [(0.0, "0.0"), (3.0, "3.0"), (1e-05, "1.0e-05"), (2.5e20, "2.5e+20"),
                    (1e16, "1.0e+16"), (-0.125, "-0.125")]:
        assert format_value(spec, x) == text
        assert yaml.safe_load(text) == x and isinstance(yaml.safe_load(text), float)


def test_shipped_file_loads_to_the_defaults_without_warnings():
    fp, pp, warnings = load_params_file(SHIPPED, "cf_estimator")
    assert fp == FilterParams() and pp == PipelineParams()
    assert warnings == []


def test_round_trip_of_non_default_values(tmp_path):
    fp = FilterParams(k1=0.75, k2=1e-5, world_frame="ned", use_mag=False, r2=0.01)
    pp = PipelineParams(mag_timeout_s=0.25, publish_rpy=False, reset_after_gap_s=0.0)
    path = tmp_path / "p.yaml"
    path.write_text(render_params_yaml(fp, pp), encoding="utf-8")
    assert load_params_file(path) == (fp, pp, [])


def test_node_name_sections_apply_and_others_are_reported(tmp_path):
    """Issue 13.1: only the sections the node of that name reads apply (ROS's rule)."""
    path = tmp_path / "p.yaml"
    path.write_text(
        "/**:\n  ros__parameters:\n    k1: 0.6\n    use_sim_time: true\n"
        "/robot/cf_estimator:\n  ros__parameters:\n    k1: 0.8\n"
        "imu_filter_madgwick:\n  ros__parameters:\n    gain: 0.1\n",
        encoding="utf-8",
    )
    fp, _, warnings = load_params_file(path, "cf_estimator")  # /cf_estimator: root namespace
    assert fp.k1 == 0.6
    assert len(warnings) == 2 and "imu_filter_madgwick" in warnings[1]
    assert "/robot/cf_estimator" in warnings[0] and "ignored" in warnings[0]
    fp, _, warnings = load_params_file(path, "/robot/cf_estimator")
    assert fp.k1 == 0.8  # the later, node-specific section overrides the wildcard
    assert len(warnings) == 1 and "imu_filter_madgwick" in warnings[0]


def test_a_section_for_another_node_does_not_change_the_parameters(tmp_path):
    """Issue 13.1: ``imu_filter: ros__parameters: k1: 0.7`` changed the replay; the node
    ignores it."""
    path = tmp_path / "p.yaml"
    path.write_text("/**:\n  ros__parameters:\n    k2: 0.004\n"
                    "imu_filter:\n  ros__parameters:\n    k1: 0.7\n", encoding="utf-8")
    fp, _, warnings = load_params_file(path)
    assert fp.k1 == FilterParams().k1 and fp.k2 == 0.004
    assert warnings and "imu_filter" in warnings[0]
    fp, _, _ = load_params_file(path, "imu_filter")  # a node of that name reads both
    assert fp.k1 == 0.7


@pytest.mark.parametrize(("key", "name", "applies"), [
    ("/**", "cf_estimator", True), ("/**", "/a/b/c", True), ("cf_estimator", "cf_estimator", True),
    ("/cf_estimator", "cf_estimator", True), ("/**/cf_estimator", "/robot/cf_estimator", True),
    ("/**/cf_estimator", "cf_estimator", True), ("/*/cf_estimator", "/robot/cf_estimator", True),
    ("/*/cf_estimator", "cf_estimator", False), ("/robot/cf_estimator", "cf_estimator", False),
    ("imu_filter", "cf_estimator", False), ("/robot/*", "/robot/cf_estimator", True),
    ("cf_est", "cf_estimator", False),
])
def test_node_key_matching_follows_ros(key, name, applies):
    assert node_key_matches(key, name) is applies


def test_unknown_keys_are_refused_with_the_nearest_name(tmp_path):
    """Issue 13.2: ``k_1: 0.5`` ran the whole replay on defaults."""
    path = tmp_path / "p.yaml"
    path.write_text("cf_estimator:\n  ros__parameters:\n    k_1: 0.5\n    gian: 2.0\n"
                    "    qos_overrides:\n      /imu/data_raw:\n        subscription:\n"
                    "          depth: 20\n", encoding="utf-8")
    with pytest.raises(ParameterError) as info:
        load_params_file(path, "cf_estimator")
    text = str(info.value)
    assert "'k_1' (did you mean 'k1'?)" in text and "'gian'" in text and "\n" not in text
    assert unknown_keys(path) == ["gian", "k_1"]  # qos_overrides.* is ROS's own


def test_flat_and_empty_files_and_files_for_no_section_are_refused(tmp_path):
    """Issue 13.2: a flat file without ros__parameters ran on defaults."""
    for body, words in [("k1: 0.6\n", "ros__parameters"), ("", "empty"),
                        ("imu_filter:\n  ros__parameters:\n    k1: 0.6\n", "no section applies")]:
        path = tmp_path / "p.yaml"
        path.write_text(body, encoding="utf-8")
        with pytest.raises(ParameterError, match=words):
            load_params_file(path)


def test_unknown_names_for_the_node_skip_ros_parameters():
    assert unknown_names(["k1", "use_sim_time", "qos_overrides./x.depth", "k_1"]) == ["k_1"]
    assert describe_unknown(["saturation_limit"]) == (
        "'saturation_limit' (did you mean 'saturation_limit_rad'?)")


def test_invalid_values_raise_one_line_errors(tmp_path):
    path = tmp_path / "p.yaml"
    for body, words in [
        ("k1: 1", "write 1.0"),
        ("k1: -0.5", "k1"),
        ("world_frame: ecef", "world_frame"),
        ("use_mag: 1", "use_mag"),
        ("aperiodic_time_constant_s: 500.0", "unstable"),
    ]:
        path.write_text(f"/**:\n  ros__parameters:\n    {body}\n", encoding="utf-8")
        with pytest.raises(ParameterError) as info:
            load_params_file(path)
        assert words in str(info.value) and "\n" not in str(info.value)


def test_build_params_rejects_unknown_names():
    with pytest.raises(ParameterError, match="unknown"):
        build_params({"k9": 1.0})
    assert build_params({}) == (FilterParams(), PipelineParams())


def test_ros_interface_doc_lists_every_parameter():
    doc = (REPO / "docs" / "ros_interface.md").read_text(encoding="utf-8")
    missing = [s.name for s in all_specs() if f"| `{s.name}` |" not in doc]
    assert not missing, f"docs/ros_interface.md lacks parameters: {missing}"


def test_docs_parameter_table_is_generated_from_the_schema():
    from cf_estimator.params_file import render_params_markdown

    doc = (Path(__file__).resolve().parents[1] / "docs" / "ros_interface.md").read_text()
    start = doc.index("<!-- parameter table:")
    body = doc[doc.index("\n", start) + 1 : doc.index("<!-- end of parameter table -->")]
    assert body == render_params_markdown(), "run: python3 -m cf_estimator.params_file --markdown"


def test_a_removed_parameter_at_its_old_off_value_loads_and_any_other_is_refused(tmp_path):
    """k3 and mag_mode are gone (docs/decisions/0011): a file written from the old shipped one
    still loads (the lines did nothing), and says so; a value that asked for the removed
    variant is refused with the reason, not silently dropped."""
    path = tmp_path / "old.yaml"
    path.write_text("/**:\n  ros__parameters:\n    k1: 0.5\n    k3: 0.0\n    mag_mode: yaw\n",
                    encoding="utf-8")
    fp, _, warnings = load_params_file(path)
    assert fp.k1 == 0.5
    assert len(warnings) == 2 and all("removed" in w for w in warnings)
    path.write_text("/**:\n  ros__parameters:\n    k3: 0.001\n", encoding="utf-8")
    with pytest.raises(ParameterError, match="k3: removed.*full-vector"):
        load_params_file(path)
    path.write_text("/**:\n  ros__parameters:\n    mag_mode: full\n", encoding="utf-8")
    with pytest.raises(ParameterError, match="mag_mode: removed"):
        load_params_file(path)


def test_the_parameter_file_shipped_before_the_2026_12_removals_still_loads(tmp_path):
    """The five parameters of docs/decisions/0013 at their old defaults (the lines of the old
    shipped file) load with one warning each and change nothing; a tuned value is refused,
    naming the record, instead of being silently dropped."""
    old = {"wide_saturation_limit_rad": 10.0, "acceleration_hold_s": 1.0, "rest_time_s": 1.0,
           "bias_limit_rad_s": 0.5, "mag_norm_tolerance": 0.2, "mag_dip_tolerance_rad": 0.17}
    path = tmp_path / "old.yaml"
    lines = "".join(f"    {k}: {v}\n" for k, v in old.items())
    path.write_text(f"/**:\n  ros__parameters:\n    k1: 0.5\n{lines}", encoding="utf-8")
    fp, _, warnings = load_params_file(path)
    assert fp == dataclasses.replace(FilterParams(), k1=0.5)
    assert len(warnings) == len(old) and all("0013" in w for w in warnings)
    path.write_text("/**:\n  ros__parameters:\n    rest_time_s: 3.0\n", encoding="utf-8")
    with pytest.raises(ParameterError, match="rest_time_s: removed.*0013"):
        load_params_file(path)
