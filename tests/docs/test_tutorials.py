"""The tutorials cannot rot: each script runs at a tiny budget, and each page includes code that exists."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

DOCS = Path(__file__).resolve().parents[2] / "docs"
TUTORIALS = sorted((DOCS / "tutorials").glob("*.py"))
#: what each script must print at any budget (its output file holds the same text)
EXPECTED = {
    "adding_a_domain": [r"^HRS: mean steps per episode \d", r"^SARSA: mean steps per episode \d"],
    "cartpole": [
        r"^unshaped +\d",
        r"^default +\d",
        r"^as learned +\d",
        r"^learned values, default \(mean\): V\(start\)=",
        r"^learned values, as learned \(mean\): V\(start\)=",
    ],
    "shape_your_env": [
        r"^unshaped ",
        r"^default ",
        r"^as learned ",
        r"learned potential, default, at \d+ frames \(mean\): Φ\(0\)=",
        r"learned potential, as learned, at the end \(mean\): Φ\(0\)=",
    ],
    "quickstart": [r"^unshaped: \d+ episodes", r"^shaped: \d+ episodes"],
    "train_the_potential": [
        r"^first batch: 256 steps, \d+ SMDP transitions",
        r"^V at start \(z=0\)",
        r"^V at above_goal \(z=3\)",
        r"buffer holds \d+",
    ],
}


def test_every_tutorial_script_is_checked() -> None:
    assert {p.stem for p in TUTORIALS} == set(EXPECTED)


@pytest.mark.parametrize("script", TUTORIALS, ids=lambda p: p.stem)
def test_tutorial_runs_at_a_tiny_budget(script: Path, tmp_path: Path) -> None:
    """Each script at its tiny budget (``TUTORIAL_TINY=1``, which ``--tiny`` also sets): it prints
    what its page shows, and the scripts with a figure write it and the printed text to ``--out``."""
    figures = script.stem != "quickstart"  # the home page's snippet takes no arguments
    args = ["--tiny", "--out", str(tmp_path)] if figures else []
    done = subprocess.run(
        [sys.executable, str(script), *args],
        capture_output=True,
        text=True,
        timeout=600,
        cwd=tmp_path,
        env={**os.environ, "TUTORIAL_TINY": "1"},
    )
    assert done.returncode == 0, done.stderr[-3000:]
    for pattern in EXPECTED[script.stem]:
        assert re.search(pattern, done.stdout, re.MULTILINE), f"{pattern!r} not in:\n{done.stdout}"
    if figures:
        assert (tmp_path / f"{script.stem}.txt").read_text().strip() in done.stdout  # (TorchRL logs on stdout too)
        assert (tmp_path / f"{script.stem}.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_pages_include_sections_that_exist() -> None:
    """Every ``--8<-- "file:section"`` of a page names a section marked in that file, and every
    figure or output a page shows was committed (the run at the default budget)."""
    includes = 0
    for page in DOCS.rglob("*.md"):
        text = page.read_text()
        for path, section in re.findall(r'--8<-- "([^":]+)(?::([\w-]+))?"', text):
            source = (DOCS / path).read_text()
            includes += 1
            if section:
                assert f"[start:{section}]" in source and f"[end:{section}]" in source, (page.name, path, section)
        prose = re.sub(r"```.*?```", "", text, flags=re.DOTALL)  # not the verbatim outputs of benchmarks.md
        for image in re.findall(r"!\[[^\]]*\]\(([^)]+\.png)\)", prose):
            assert (page.parent / image).exists(), (page.name, image)
    assert includes > 0
