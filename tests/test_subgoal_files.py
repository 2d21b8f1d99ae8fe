"""Subgoal files as a careless or hostile user writes them: duplicates, size, binary, aliases."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from torchrl_subgoal import SubgoalFileError, SubgoalSeries, load_patterns
from torchrl_subgoal.domains import four_rooms
from torchrl_subgoal.subgoals import (
    MAX_FILE_BYTES,
    MAX_SUBGOALS,
    Cell,
    parse_text,
    pattern_from_data,
    patterns_from_data,
)


def write(tmp_path: Path, name: str, content: str | bytes) -> Path:
    path = tmp_path / name
    path.write_bytes(content.encode() if isinstance(content, str) else content)
    return path


@pytest.mark.parametrize(
    ("name", "content", "message"),
    [
        (
            "p.yaml",
            "patterns:\n  p: {subgoals: [{cell: [3, 6]}, {cell: [7, 9]}]}\n  p: {subgoals: [{cell: [3, 6]}]}\n",
            "patterns: duplicate pattern name 'p' (line 3)",
        ),
        (
            "p.json",
            '{"patterns": {"p": {"subgoals": [{"cell": [3, 6]}]}, "p": {"subgoals": [{"cell": [7, 9]}]}}}',
            "patterns: duplicate pattern name 'p'",
        ),
        (
            "n.yaml",
            "patterns:\n  1: {subgoals: [{cell: [3, 6]}]}\n  '1': {subgoals: [{cell: [7, 9]}]}\n",
            "duplicate pattern name '1'",
        ),
        (
            "s.yaml",
            "patterns:\n  p:\n    subgoals:\n      a: {cell: [3, 6]}\n      a: {cell: [7, 9]}\n    order: []\n",
            "pattern 'p': subgoals: duplicate subgoal name 'a' (line 5)",
        ),
        (
            "s.json",
            '{"patterns": {"p": {"subgoals": {"a": {"cell": [3, 6]}, "a": {"cell": [7, 9]}}, "order": []}}}',
            "pattern 'p': subgoals: duplicate subgoal name 'a'",
        ),
        (
            "f.yaml",
            "patterns:\n  p:\n    subgoals: [{circle: {centre: [0.5, 0.5], radius: 0.1, radius: 0.2}}]\n",
            "pattern 'p': subgoals[0].circle: duplicate field 'radius' (line 3)",
        ),
        (
            "t.yaml",
            "domain: four_rooms\ndomain: pinball\npatterns: {p: [{cell: [3, 6]}]}\n",
            "duplicate field 'domain'",
        ),
        ("bin.yaml", b"\x00\x01\xff\xfe binary", "not a text file (byte 0xff at offset 2 is not UTF-8)"),
        ("nul.yaml", b"patterns: \x00", "not valid YAML/JSON"),
        (
            "alias.yaml",
            "a: &x [{cell: [3, 6]}]\npatterns: {p: {subgoals: *x}}\n",
            "line 1: this value is used again through a YAML alias",
        ),
        ("deep.json", '{"a": ' * 100_000 + "1" + "}" * 100_000, "nested too deeply"),
        ("big.yaml", "# comment\n" * (MAX_FILE_BYTES // 10 + 1), f"larger than {MAX_FILE_BYTES} bytes"),
        (
            "long.yaml",
            "patterns:\n  p: [" + ", ".join(["{cell: [3, 6]}"] * (MAX_SUBGOALS + 1)) + "]\n",
            f"pattern 'p': subgoals: {MAX_SUBGOALS + 1} subgoals; a pattern may have at most {MAX_SUBGOALS}",
        ),
    ],
)
def test_bad_files_name_the_file_and_field(tmp_path: Path, name: str, content: str | bytes, message: str) -> None:
    path = write(tmp_path, name, content)
    with pytest.raises(SubgoalFileError) as info:
        load_patterns(path)
    assert str(info.value).startswith(f"{path}: ") and message in str(info.value)
    assert "\n" not in str(info.value)


def test_a_file_at_the_size_limit_loads_and_an_endless_one_is_cut(tmp_path: Path) -> None:
    """Linear loading: a JSON file just under the limit (thousands of patterns) loads; a
    device that never ends is read only up to the limit. (Speed: docs/reliability.md.)"""
    body = {"subgoals": [{"cell": [3, 6]}, {"cell": [7, 9]}]}
    one = len(json.dumps({"p00000": body})) - 2
    count = (MAX_FILE_BYTES - 100) // (one + 2)
    data = {"domain": "four_rooms", "patterns": {f"p{i:05d}": body for i in range(count)}}
    path = write(tmp_path, "many.json", json.dumps(data))
    assert MAX_FILE_BYTES // 2 < path.stat().st_size <= MAX_FILE_BYTES
    assert len(load_patterns(path)) == count
    with pytest.raises(SubgoalFileError, match="larger than"):
        load_patterns("/dev/zero")


def test_a_large_partial_order_is_read_in_reasonable_time() -> None:
    """The covering relation of a 1,000-subgoal DAG with every transitive pair (an n³ walk before)."""
    n = 300
    names = [f"s{i}" for i in range(n)]
    order = [[names[a], names[b]] for a in range(n) for b in range(a + 1, min(n, a + 20))]
    series = pattern_from_data(
        {"subgoals": {nm: {"cell": [i, 0]} for i, nm in enumerate(names)}, "order": order}, name="dag"
    )
    assert [series.successors(z) for z in (0, 1, n)] == [(0,), (1,), ()]


def test_duplicate_names_given_in_code_are_refused_too() -> None:
    with pytest.raises(SubgoalFileError, match="duplicate subgoal name 'a'"):
        SubgoalSeries([Cell(3, 6), Cell(7, 9)], order=[], names=["a", "a"], name="p")


def test_parsed_data_can_be_checked_without_a_file() -> None:
    """What a web upload does: parse the bytes it received, then build the patterns."""
    text = b'{"patterns": {"p": {"subgoals": [{"cell": [3, 6]}]}}}'
    patterns = patterns_from_data(parse_text(text, "upload.json"), "upload.json", check=four_rooms.check_subgoal)
    assert patterns["p"].predicates == (Cell(3, 6),)
    with pytest.raises(SubgoalFileError, match=r"^upload\.json: pattern 'p': subgoals\[0\]\.cell: \(0, 0\) is a wall"):
        patterns_from_data(
            parse_text(b"patterns: {p: [{cell: [0, 0]}]}", "upload.json"), "upload.json", check=four_rooms.check_subgoal
        )


def test_cycles_are_still_named() -> None:
    body = {
        "subgoals": {"a": {"cell": [3, 6]}, "b": {"cell": [7, 9]}, "c": {"cell": [6, 2]}},
        "order": [["c", "a"], ["a", "b"], ["b", "a"]],
    }
    with pytest.raises(SubgoalFileError, match="order: the order has a cycle through subgoal 'a'"):
        pattern_from_data(body, name="p", source="f.yaml")
