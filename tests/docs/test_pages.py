"""The pages are written for users, and the benchmarks page shows every maintained benchmark.

A page says what the package does and what was measured, with the command that reproduces each
figure; the history of how it got there is CHANGELOG.md's. So no page names a work session, an
issue number, a commit or a path of the machine a figure was measured on, nor a date or a time of
day.
"""

from __future__ import annotations

import ast
import importlib.util
import re
import sys
from pathlib import Path
from types import ModuleType

import pytest
import torch

ROOT = Path(__file__).resolve().parents[2]
PAGES = sorted([ROOT / "README.md", *(ROOT / "docs").rglob("*.md")])
#: what ties a page to the project's history or to one machine, with why
HISTORY = {
    r"\bsession [0-9]": "a work session",
    r"\bthis session\b": "a work session",
    r"\bissue #?[0-9]": "an issue number",
    r"(?<![\w/])(?=[0-9a-f]*[a-f])(?=[0-9a-f]*[0-9])[0-9a-f]{7,40}\b": "a commit hash",
    r"/[a-z]+/results/|/work/": "a path of the machine",
    r"\bUTC\b|\b[0-2][0-9]:[0-5][0-9]\s?(?:UTC|h)\b": "a time of day",
    r"\b20[0-9]{2}-[01][0-9]-[0-3][0-9]\b": "the date of a run",
    r"\bearlier engineer|\bother engineers'": "who measured, not what",
}


@pytest.mark.parametrize("page", PAGES, ids=lambda p: str(p.relative_to(ROOT)))
def test_page_names_no_history(page: Path) -> None:
    found = [
        f"{page.relative_to(ROOT)}:{number}: {why}: {line.strip()[:120]}"
        for number, line in enumerate(page.read_text().splitlines(), 1)
        for pattern, why in HISTORY.items()
        if re.search(pattern, line, re.IGNORECASE)
    ]
    assert not found, "history belongs in CHANGELOG.md:\n" + "\n".join(found)


def _docs_page() -> ModuleType:
    spec = importlib.util.spec_from_file_location("docs_page", ROOT / "benchmarks" / "docs_page.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault(spec.name, module)  # its dataclasses look their module up
    spec.loader.exec_module(sys.modules[spec.name])
    return sys.modules[spec.name]


def test_the_benchmarks_page_runs_every_benchmark() -> None:
    """Every script in benchmarks/ is a maintained benchmark: `make bench-docs` runs it, and its
    docstring says what it measures (checks and diagnostics live in tools/)."""
    run = {item.args[0] for item in _docs_page().RUNS}
    for script in sorted((ROOT / "benchmarks").glob("*.py")):
        if script.name == "docs_page.py":
            continue
        assert f"benchmarks/{script.name}" in run, f"{script.name}: not run by benchmarks/docs_page.py"
        assert ast.get_docstring(ast.parse(script.read_text())), f"{script.name}: no docstring"
    for script in sorted((ROOT / "tools").glob("*.py")):
        assert ast.get_docstring(ast.parse(script.read_text())), f"tools/{script.name}: no docstring"


def test_the_benchmarks_page_keeps_no_time_stamp_or_temporary_path() -> None:
    clean = _docs_page().clean
    out = (
        "\x1b[32mraw\x1b[0m 994 env-steps/s\n"
        "2026-01-02 03:04:05,678 [torchrl][INFO]    Initialized LazyTensorStorage\n"
        "Results: `/tmp/bench-docs-x/four_rooms`, 1000 episodes per learner.\n"
    )
    assert clean(out, Path("/tmp/bench-docs-x")) == (
        "raw 994 env-steps/s\nResults: `RESULTS/four_rooms`, 1000 episodes per learner.\n"
    )


def test_the_readme_snippet_shapes_a_collector_and_learns_the_potential(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    """The README's 'Use it on your env' code, as printed, on a four-rooms batch behind a collector: the
    reward is shaped and the potential trains only on steps that close a transition."""
    from torchrl.collectors import Collector

    from torchrl_subgoal import State, SubgoalSeries, save_patterns
    from torchrl_subgoal.envs import FourRoomsEnv

    text = (ROOT / "README.md").read_text()
    start = text.index("## Use it on your env")
    code = text[
        text.index("```python\n", start) + len("```python\n") : text.index("```", text.index("```python\n", start) + 3)
    ]
    monkeypatch.chdir(tmp_path)
    # two states next to the start (state 0): a random walk reaches them within the first batch
    save_patterns(tmp_path / "my_subgoals.yaml", {"alice": SubgoalSeries([State(1), State(2)], name="alice")})
    namespace: dict = {"base_env": FourRoomsEnv(num_envs=4, goal_reward=0.0, step_reward=-1.0)}
    exec(compile(code, "README.md", "exec"), namespace)
    shaping, env, potential = namespace["shaping"], namespace["env"], namespace["potential"]
    torch.manual_seed(0)
    collector = Collector(env, None, frames_per_batch=400, total_frames=1200)
    collector.set_seed(0)
    shaped = []
    try:
        for data in collector:
            nxt = data["next"]
            shaped.append(not torch.equal(nxt["reward"], nxt["env_reward"]))
    finally:
        collector.shutdown()
    assert shaping.value_update is not None and potential.table.detach().abs().sum() > 0
    assert any(shaped)


def test_every_test_the_reliability_page_names_exists() -> None:
    """docs/reliability.md states each promise with the tests that check it: ``tests/x.py::test_y``,
    ``test_x.py::test_y`` (found under tests/) or ``::test_y`` (of the file named last)."""
    text = (ROOT / "docs" / "reliability.md").read_text()
    named, current, missing = 0, None, []
    for file, name in re.findall(r"`((?:tests/)?[\w/]*test_\w+\.py)?::(test_\w+)", text):
        if file:
            found = [ROOT / file] if file.startswith("tests/") else sorted((ROOT / "tests").rglob(file))
            assert len(found) == 1 and found[0].exists(), f"{file}: no such test file (or several)"
            current = found[0]
        assert current is not None, f"::{name} follows no test file"
        named += 1
        if not re.search(rf"^def {name}\(", current.read_text(), re.MULTILINE):
            missing.append(f"{current.relative_to(ROOT)}::{name}")
    assert named >= 20 and not missing, missing
