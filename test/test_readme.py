"""The README is a newcomer's page that holds: its two commands, its links, its length; and the
Python API example (docs/python_api.md, moved there from the README) runs as written."""

from __future__ import annotations

import re
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
README = REPO / "README.md"
PYTHON_API = REPO / "docs" / "python_api.md"
#: The pages whose relative links must resolve: the README and every page under docs/.
PAGES = (README, *sorted((REPO / "docs").rglob("*.md")))
MAX_README_LINES = 200

FENCE = re.compile(r"^```.*?^```", flags=re.S | re.M)
LINK = re.compile(r"\[[^\]]*\]\(([^)\s]+)\)")


def code_blocks(text: str, lang: str) -> list[str]:
    return re.findall(rf"^```{lang}\n(.*?)^```", text, flags=re.S | re.M)


def slug(heading: str) -> str:
    """GitHub's anchor for a heading: lower case, punctuation dropped, spaces to hyphens."""
    text = heading.strip().lower().replace("`", "")
    text = re.sub(r"[^\w\- ]", "", text)
    return text.replace(" ", "-")


def anchors(path: Path) -> set[str]:
    text = FENCE.sub("", path.read_text(encoding="utf-8"))
    seen: dict[str, int] = {}
    found = set()
    for heading in re.findall(r"^#{1,6} (.+)$", text, flags=re.M):
        base = slug(heading)
        n = seen.get(base, 0)
        seen[base] = n + 1
        found.add(base if n == 0 else f"{base}-{n}")
    return found


def relative_links(path: Path) -> list[str]:
    text = FENCE.sub("", path.read_text(encoding="utf-8"))
    return [t for t in LINK.findall(text) if not re.match(r"^[a-z][a-z0-9+.-]*:", t)]


def test_python_api_example_runs(capsys):
    blocks = code_blocks(PYTHON_API.read_text(encoding="utf-8"), "python")
    assert len(blocks) == 1
    namespace: dict = {}
    exec(compile(blocks[0], "docs/python_api.md", "exec"), namespace)  # noqa: S102
    out = capsys.readouterr().out
    n = len(namespace["gyro"])
    assert f"({n}, 4)" in out and "final roll" in out and "phase=" in out
    assert namespace["q_many"].shape == (3, n, 4)
    assert namespace["res_6d"].quaternion.shape == (n, 4)


def test_readme_is_short_and_gives_the_two_commands():
    text = README.read_text(encoding="utf-8")
    assert len(text.splitlines()) <= MAX_README_LINES
    quick = text.split("\n## Quick start", 1)[1].split("\n## ", 1)[0]
    commands = [b.strip() for b in code_blocks(quick, "bash")]
    # the demo on a built-in default, and install + every test (what CI runs: .ci/run)
    assert "python3 -m pip install . && cf-estimator demo" in commands
    assert "bash scripts/test.sh" in commands
    assert "bash scripts/test.sh" in (REPO / ".ci" / "run").read_text(encoding="utf-8")
    assert "<!-- output of: cf-estimator demo -->" in quick  # its output, run by the doc test
    assert "skip" in quick and "../shared" in quick  # a plain clone skips, and says why


def test_readme_points_to_every_docs_page():
    targets = {t.split("#", 1)[0] for t in relative_links(README)}
    pages = {p.relative_to(REPO).as_posix() for p in (REPO / "docs").glob("*.md")}
    assert pages <= targets, f"README's 'Where the rest lives' misses {sorted(pages - targets)}"
    assert "docs/decisions/" in targets and "BENCHMARKS.md" in targets


def test_relative_links_resolve():
    broken = []
    for page in PAGES:
        for target in relative_links(page):
            file_part, _, anchor = target.partition("#")
            dest = (page.parent / file_part).resolve() if file_part else page
            name = f"{page.relative_to(REPO)}: {target}"
            if not dest.exists():
                broken.append(f"{name} (no such file)")
            elif anchor and dest.suffix == ".md" and anchor not in anchors(dest):
                broken.append(f"{name} (no such heading)")
    assert not broken, "\n".join(broken)


def test_slug_is_githubs():
    assert slug("`cf-estimator calibrate-mag`") == "cf-estimator-calibrate-mag"
    assert slug("ArduPilot DataFlash logs (`.bin`)") == "ardupilot-dataflash-logs-bin"
    assert slug('Why three sets of "thesis" numbers') == "why-three-sets-of-thesis-numbers"
    assert slug("Time, magnetometer and input guards (failure modes)") == (
        "time-magnetometer-and-input-guards-failure-modes")
