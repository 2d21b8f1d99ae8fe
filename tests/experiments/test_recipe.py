"""The recipes' shared helpers: pattern sets, learners per method, chunk decoding."""

from __future__ import annotations

import json

import pytest
import torch

from torchrl_subgoal.experiments import plan_chunks
from torchrl_subgoal.experiments.cli import ConfigError
from torchrl_subgoal.experiments.recipe import (
    chunk_patterns,
    method_specs,
    pattern_config,
    pattern_sets,
)
from torchrl_subgoal.methods import paper_methods
from torchrl_subgoal.subgoals import Cell, SubgoalSeries

HUMAN = {
    "ann": SubgoalSeries([Cell(3, 6), Cell(7, 9)], name="ann"),
    "bob": SubgoalSeries([Cell(6, 2)], name="bob"),
}
CANDIDATES = [Cell(r, c) for r, c in ((1, 1), (1, 2), (2, 1), (2, 2), (5, 5))]


def test_pattern_sets_are_seeded_and_as_long_as_the_longest_human_one() -> None:
    sets = pattern_sets(HUMAN, CANDIDATES, 3, seed=4)
    assert sets["human"] == HUMAN and sets["none"] == {}
    assert list(sets["random"]) == ["random_1", "random_2", "random_3"]
    assert all(len(p) == 2 for p in sets["random"].values())
    again = pattern_sets(HUMAN, CANDIDATES, 3, seed=4)
    assert pattern_config(again) == pattern_config(sets)
    assert pattern_config(pattern_sets(HUMAN, CANDIDATES, 3, seed=5)) != pattern_config(sets)


def test_unshaped_methods_get_as_many_learners_of_one_pseudo_pattern() -> None:
    sets = pattern_sets(HUMAN, CANDIDATES, 3, seed=0)
    specs = {s.name: s for s in method_specs(paper_methods("SARSA"), ["HRS", "RRS", "SARSA", "SARSA-RS"], sets, 4)}
    assert len(specs["HRS"].learners()) == 2 * 4
    assert len(specs["RRS"].learners()) == 3 * 4
    assert specs["SARSA"].learners() == [("none", i) for i in range(2 * 4)]
    assert tuple(specs["SARSA-RS"].patterns) == ("none",)


def test_chunk_patterns_read_back_what_the_config_stored() -> None:
    sets = pattern_sets(HUMAN, CANDIDATES, 2, seed=0)
    config = json.loads(json.dumps({"patterns": pattern_config(sets)}))  # as config.json holds it
    (chunk,) = plan_chunks(method_specs(paper_methods("SARSA"), ["HRS"], sets, 2), seed=0, chunk_size=10)
    series, index = chunk_patterns(chunk, config)
    assert [s.name for s in series] == ["ann", "bob"]
    assert [s.to_dict() for s in series] == [HUMAN["ann"].to_dict(), HUMAN["bob"].to_dict()]
    assert torch.equal(index, torch.tensor([0 if p == "ann" else 1 for p, _ in chunk.learners]))
    (unshaped,) = plan_chunks(method_specs(paper_methods("SARSA"), ["SARSA"], sets, 1), seed=0, chunk_size=10)
    series, index = chunk_patterns(unshaped, config)
    assert series == [] and torch.equal(index, torch.zeros(2, dtype=torch.long))


def test_unknown_method_names_the_flag_and_the_known_ones() -> None:
    sets = pattern_sets(HUMAN, CANDIDATES, 1, seed=0)
    with pytest.raises(ConfigError, match=r"--methods: unknown method\(s\) \['XYZ'\]; choose from \['HRS'"):
        method_specs(paper_methods("SARSA"), ["HRS", "XYZ"], sets, 1)
