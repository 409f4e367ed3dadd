"""Every command output README.md, docs/replay.md and docs/tuning.md quote is what it
prints today.

BENCHMARKS.md quotes no command output: it is rendered from the committed results
(test/test_benchmarks_report.py holds it equal to that rendering; ``cf-estimator bench report``
regenerates both).

A quoted example is a fenced block whose first line is ``$ cf-estimator ...`` (then its output,
then maybe more ``$`` lines), or a block right after ``<!-- output of: cf-estimator ... -->``
(an excerpt of that command's output). Each example runs in a fresh directory next to a link to
``../shared`` (examples reading ``../shared/data`` are skipped when it is absent); its quoted
lines must appear, in order and contiguously, in what the command prints. A single-command
example runs once per session (test/cli_runs.py), shared with any test that reads the same
run's files. Only wall-clock
figures are masked (``N messages/s (T s)``, ``done in T s``, tune's ``(T s)`` per pass):
everything else is deterministic.

When a change of the defaults changes the outputs, the failure shows the new output to paste.
"""

from __future__ import annotations

import re
import shlex
from dataclasses import dataclass, field

import pytest
from cli_runs import REPO, SHARED, run_documented

from cf_estimator.cli.main import main

DOCS = (REPO / "README.md", REPO / "docs" / "replay.md", REPO / "docs" / "tuning.md")
MARKER = re.compile(r"<!-- output of: (cf-estimator .*?) -->")
MASKS = (
    (re.compile(r"\d+ messages/s \([\d.]+ s\)"), "<N> messages/s (<T> s)"),
    (re.compile(r"done in [\d.]+ s"), "done in <T> s"),
    (re.compile(r"\(\d+ s\)$"), "(<T> s)"),  # tune's elapsed seconds per pass
)


@dataclass
class Example:
    doc: str
    line: int
    steps: list[tuple[str, list[str]]] = field(default_factory=list)

    @property
    def id(self) -> str:
        return f"{self.doc}:{self.line}"


def examples() -> list[Example]:
    found = []
    for path in DOCS:
        lines = path.read_text(encoding="utf-8").splitlines()
        i = 0
        while i < len(lines):
            if not lines[i].startswith("```"):
                i += 1
                continue
            start = i
            j = i + 1
            while not lines[j].startswith("```"):
                j += 1
            body = lines[start + 1:j]
            marker = MARKER.search(lines[start - 1]) if start else None
            ex = Example(path.relative_to(REPO).as_posix(), start + 1)
            if marker:
                ex.steps.append((marker.group(1), body))
            elif body and body[0].startswith("$ cf-estimator "):
                for text in body:
                    if text.startswith("$ "):
                        ex.steps.append((text[2:], []))
                    else:
                        ex.steps[-1][1].append(text)
            if ex.steps:
                found.append(ex)
            i = j + 1
    return found


def mask(text: str) -> str:
    for pattern, repl in MASKS:
        text = pattern.sub(repl, text)
    return text.rstrip()


def contains_block(actual: list[str], expected: list[str]) -> bool:
    exp = [mask(x) for x in expected]
    act = [mask(x) for x in actual]
    if not exp:
        return True
    return any(act[k:k + len(exp)] == exp for k in range(len(act) - len(exp) + 1))


def _missing_peers(command: str) -> list[str]:
    """The peers a ``bench`` command's table has a column for that are not installed here."""
    argv = shlex.split(command)
    if argv[1:2] != ["bench"]:
        return []
    names = ["vqf"] if argv[2:3] in (["cross"], ["sustained"]) else []  # VQF beside, always
    if "--peers" in argv:
        names = argv[argv.index("--peers") + 1].split(",")
    if names in (["none"], []):
        return []
    from cf_estimator.bench.euroc_eval import peer_names, select_peers

    return select_peers(peer_names() if names == ["all"] else names)[1]


def _run(command: str, capsys) -> tuple[int, str]:
    argv = shlex.split(command)
    assert argv[0] == "cf-estimator"
    rc = main(argv[1:])
    return rc, capsys.readouterr().out


@pytest.mark.parametrize("example", examples(), ids=lambda e: e.id)
def test_quoted_output_is_what_the_command_prints(example, tmp_path, tmp_path_factory,
                                                  monkeypatch, capsys):
    if any("../shared" in cmd for cmd, _ in example.steps) and not SHARED.is_dir():
        pytest.skip(f"{SHARED} not available")
    missing = [peer for cmd, _ in example.steps for peer in _missing_peers(cmd)]
    if missing:  # a table with a peer's column: that peer must run (not on a plain [test] install)
        pytest.skip(f"peers not installed: {', '.join(missing)} (pip install '.[bench]')")
    work = tmp_path / "work"
    work.mkdir()
    if SHARED.is_dir():
        (tmp_path / "shared").symlink_to(SHARED, target_is_directory=True)
    monkeypatch.chdir(work)
    for k, (command, expected) in enumerate(example.steps):
        if len(example.steps) == 1:  # its output depends on nothing run before: run once
            run = run_documented(command, tmp_path_factory)
            rc, out = run.rc, run.out
        else:
            rc, out = _run(command, capsys)
        assert rc == 0, f"{example.id}: `{command}` exited {rc}"
        assert contains_block(out.splitlines(), expected), (
            f"{example.id}, step {k + 1}: `{command}` no longer prints what the doc quotes. "
            f"It prints:\n{out}"
        )


def test_the_docs_quote_the_commands_users_run_first():
    ids = {cmd.split()[1] for e in examples() for cmd, _ in e.steps}
    assert {"demo", "replay", "simulate", "design", "tune"} <= ids


def test_contains_block_masks_only_wall_clock_figures():
    actual = ["a", "speed   6261 messages/s (1.38 s)", "done in 18.3 s", "b"]
    assert contains_block(actual, ["speed   9999 messages/s (0.10 s)", "done in 1 s"])
    assert not contains_block(actual, ["speed   6261 messages/s (1.38 s)", "b", "c"])
    assert not contains_block(["clipped 5.2%"], ["clipped 75.9%"])
    assert contains_block(["  pass 1/2: best 0.8676  (1 s)"], ["  pass 1/2: best 0.8676  (0 s)"])
