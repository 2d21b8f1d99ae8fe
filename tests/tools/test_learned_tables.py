"""tools/learned_tables.py: final tables, tables over time, and the file --frozen-potential reads."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from tests.tools import load_tool


def _results(root: Path, tables: dict[str, list[list[float]]]) -> Path:
    """A results directory whose HRS learners (one per pattern) logged ``tables[pattern]`` after batches 1, 2, …"""
    methods = [{"name": "PPO", "patterns": ["none"], "learnings_per_pattern": 2}]
    methods.append({"name": "HRS", "patterns": list(tables), "learnings_per_pattern": 1})
    root.mkdir()
    (root / "config.json").write_text(json.dumps({"methods": methods}))
    for pattern, over_time in tables.items():
        scalars = root / "logs" / f"HRS_{pattern}_0" / "scalars"
        scalars.mkdir(parents=True)
        for z in range(len(over_time[0])):
            rows = [f"{100 * (t + 1)},{table[z]}" for t, table in enumerate(over_time)]
            (scalars / f"potential_z{z}.csv").write_text("\n".join(rows) + "\n")
    return root


def test_final_tables_over_time_and_the_frozen_file(tmp_path, capsys) -> None:
    tool = load_tool("learned_tables")
    first = _results(tmp_path / "a", {"alice": [[0, 0, 0], [0.1, 0.4, 0.8]], "bob": [[0, 0, 0.1], [0.5, 0.2, 0.9]]})
    second = _results(tmp_path / "b", {"bob": [[0, 0, 0], [0.3, 0.6, 0.7]]})
    out = tmp_path / "tables.json"
    assert tool.main([str(first), str(second), "--at", "50,100,250", "--json", str(out), "--in-order"]) == 0
    printed = capsys.readouterr().out
    assert "2 learners, 1 tables out of order" in printed and "| bob 0 * | 0.5 | 0.2 | 0.9 | — |" in printed
    assert "| 50 | 0.000 (0.000) | 0.000 (0.000) | 0.000 (0.000) | 2 of 2 |" in printed  # before the first log
    assert "| 100 | 0.000 (0.000) | 0.000 (0.000) | 0.050 (0.050) | 1 of 2 |" in printed
    assert "| 250 | 0.300 (0.200) | 0.300 (0.100) | 0.850 (0.050) | 0 of 2 |" in printed
    # bob's first table decreases, so --in-order takes the second directory's
    assert json.loads(out.read_text()) == {"alice": [0.1, 0.4, 0.8], "bob": [0.3, 0.6, 0.7]}
    tool.main([str(first), "--json", str(out)])
    assert json.loads(out.read_text())["bob"] == [0.5, 0.2, 0.9]


def test_the_subgoals_each_learner_reached(tmp_path, capsys) -> None:
    tool = load_tool("learned_tables")
    root = _results(tmp_path / "a", {"alice": [[0, 1 / 3, 2 / 3], [-9.0, 1 / 3, 2 / 3]]})
    (root / "logs" / "HRS_alice_0" / "scalars" / "subgoals_reached.csv").write_text("100,0.0\n200,0.75\n300,0.5\n")
    assert tool.main([str(root)]) == 0
    assert "| alice 0 | -9 | 0.333 | 0.667 | 0.75, 0.50 |" in capsys.readouterr().out


def test_what_it_cannot_read_is_named(tmp_path) -> None:
    tool = load_tool("learned_tables")
    results = _results(tmp_path / "a", {"bob": [[0.5, 0.2, 0.9]]})
    with pytest.raises(SystemExit, match=r"no in-order table for pattern\(s\) \['bob'\]"):
        tool.main([str(results), "--json", str(tmp_path / "t.json"), "--in-order"])
    with pytest.raises(SystemExit, match=r"a: no NRS learner logged a table"):
        tool.main([str(results), "--method", "NRS"])
    with pytest.raises(SystemExit, match=r"config.json: not a recipe's results directory"):
        tool.main([str(tmp_path)])
