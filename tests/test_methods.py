"""The paper's methods as configurations of the shaping transform."""

from __future__ import annotations

import pytest
import torch

from torchrl_subgoal import Cell, NaivePotential, SubgoalSeries, TabularPotential
from torchrl_subgoal.envs.four_rooms import check_subgoal, free_cells, room_aggregation
from torchrl_subgoal.methods import paper_methods, random_patterns, shaping_transform


def test_paper_methods() -> None:
    methods = paper_methods("SARSA")
    assert list(methods) == ["HRS", "RRS", "SARSA", "NRS", "SARSA-RS"]
    assert methods["RRS"].subgoals == "random" and methods["NRS"].shaping == "naive"


def test_random_patterns_are_seeded_and_valid() -> None:
    candidates = [Cell(r, c) for r, c in free_cells()]
    a, b = random_patterns(candidates, 10, 2, seed=1), random_patterns(candidates, 10, 2, seed=1)
    assert [p.predicates for p in a] == [p.predicates for p in b]
    assert [p.predicates for p in a] != [p.predicates for p in random_patterns(candidates, 10, 2, seed=2)]
    assert all(check_subgoal(pred) is None for p in a for pred in p.predicates)
    assert len({p.name for p in a}) == 10


@pytest.mark.parametrize(
    ("name", "potential", "learning"),
    [
        ("HRS", TabularPotential, True),
        ("RRS", TabularPotential, True),
        ("NRS", NaivePotential, False),
        ("SARSA-RS", TabularPotential, True),
    ],
)
@pytest.mark.parametrize("monotone", [False, True])
def test_shaping_transform_per_method(name: str, potential: type, learning: bool, monotone: bool) -> None:
    patterns = [SubgoalSeries([Cell(3, 6), Cell(7, 9)])]
    t = shaping_transform(
        paper_methods("SARSA")[name],
        torch.Size([4]),
        gamma=0.99,
        value_lr=0.25,
        patterns=patterns,
        aggregation=room_aggregation(),
        eta=1.0,
        monotone_potential=monotone,
    )
    assert t is not None and isinstance(t.potential, potential) and t.learning == learning
    # a monotone table is one over a series: not the naive potential, not an aggregation's table
    assert getattr(t.potential, "monotone", False) == (monotone and name in ("HRS", "RRS"))
    assert shaping_transform(paper_methods("SARSA")["SARSA"], torch.Size([4]), gamma=0.99, value_lr=0.25) is None


def test_missing_pieces_are_errors() -> None:
    with pytest.raises(ValueError, match="needs subgoal patterns"):
        shaping_transform(paper_methods("SARSA")["HRS"], torch.Size([2]), gamma=0.9, value_lr=0.1)
    with pytest.raises(ValueError, match="needs an aggregation"):
        shaping_transform(paper_methods("SARSA")["SARSA-RS"], torch.Size([2]), gamma=0.9, value_lr=0.1)
