"""The pipeline's rules (pipeline/process.py) work through its public state (issue 26 item 5).

pipeline/process.py changes an ImuPipeline through the objects of pipeline/state.py and public
methods and properties, never a private attribute of the pipeline or a private constant of its
module (checked on the source here). That a chunk gives the same outputs and state however it
is cut is test/test_bulk_decode.py's (same bags, same diagnostics, on hostile and real input).
"""

from __future__ import annotations

import ast
from pathlib import Path

from cf_estimator.pipeline import pipeline as pipeline_module
from cf_estimator.pipeline.pipeline import ImuPipeline
from cf_estimator.pipeline.state import ImuTime, InputRules, MagInput, MessageCounts

PROCESS = Path(pipeline_module.__file__).with_name("process.py")


def test_the_rules_read_and_write_no_private_attribute_of_the_pipeline():
    tree = ast.parse(PROCESS.read_text(encoding="utf-8"))
    private = [
        f"line {node.lineno}: {node.value.id}.{node.attr}"
        for node in ast.walk(tree)
        if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
        and node.value.id in ("p", "pipe") and node.attr.startswith("_")
    ]
    assert private == []


def test_a_new_pipeline_has_one_state_object_per_concern_at_its_start():
    pipe = ImuPipeline()
    assert pipe.tally == MessageCounts()
    assert pipe.clock == ImuTime()
    assert pipe.mag_input == MagInput()
    assert isinstance(pipe.rules, InputRules)
    assert pipe.rules.max_dt_ns == round(pipe.pipeline_params.max_dt_s * 1e9)
    assert pipe.rules.use_mag is pipe.filter_params.use_mag
    # the counters report reads the same object
    pipe.tally.mag_stale = 3
    assert pipe.counters["mag_stale"] == 3


def test_a_reset_clears_the_time_base_and_drops_the_pending_magnetometer_sample():
    pipe = ImuPipeline()
    pipe.clock = ImuTime(last_ns=5, dt_mean=0.01, unwrap_prev=(0.0, 0.0, 0.0))
    pipe.mag_input.pending = (5, 1.0, 0.0, 0.0)
    pipe.reset("test")
    assert pipe.clock == ImuTime()
    assert pipe.mag_input.pending is None
    assert pipe.tally.mag_dropped == 1
    assert pipe.reset_counts["test"] == 1


def test_the_filter_can_be_replaced_only_before_the_first_message():
    import pytest

    from cf_estimator.core.filter import ComplementaryFilter

    pipe = ImuPipeline()
    other = ComplementaryFilter(pipe.filter.params)
    pipe.replace_filter(other)
    assert pipe.filter is other
    pipe.tally.received_imu = 1
    with pytest.raises(RuntimeError, match="already processed"):
        pipe.replace_filter(ComplementaryFilter(pipe.filter.params))
    assert pipe.filter is other


def test_the_rules_use_only_what_their_pipeline_protocol_names_and_the_pipeline_has_it():
    """process.py types the pipeline it runs for as ``process.Pipeline`` (no import of
    pipeline.py: no import circle); every member the rules use on ``pipe``/``p`` is one the
    protocol names, and an ImuPipeline has each of them."""
    from cf_estimator.pipeline import process

    named = {n for n in vars(process.Pipeline) if not n.startswith("_")}
    named |= set(process.Pipeline.__annotations__)
    tree = ast.parse(PROCESS.read_text(encoding="utf-8"))
    used = {node.attr for node in ast.walk(tree)
            if isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name)
            and node.value.id in ("p", "pipe")}
    assert used and used <= named, sorted(used - named)
    pipe = ImuPipeline()
    assert [n for n in sorted(named) if not hasattr(pipe, n)] == []
    imports = [node.module for node in ast.walk(tree) if isinstance(node, ast.ImportFrom)]
    assert "cf_estimator.pipeline.pipeline" not in imports
