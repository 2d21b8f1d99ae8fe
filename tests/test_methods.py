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
def test_shaping_transform_per_method(name: str, potential: type, learning: bool) -> None:
    patterns = [SubgoalSeries([Cell(3, 6), Cell(7, 9)])]
    t = shaping_transform(
        paper_methods("SARSA")[name],
        torch.Size([4]),
        gamma=0.99,
        value_lr=0.25,
        patterns=patterns,
        aggregation=room_aggregation(),
        eta=1.0,
    )
    assert t is not None and isinstance(t.potential, potential) and t.learning == learning
    assert shaping_transform(paper_methods("SARSA")["SARSA"], torch.Size([4]), gamma=0.99, value_lr=0.25) is None


def test_missing_pieces_are_errors() -> None:
    with pytest.raises(ValueError, match="needs subgoal patterns"):
        shaping_transform(paper_methods("SARSA")["HRS"], torch.Size([2]), gamma=0.9, value_lr=0.1)
    with pytest.raises(ValueError, match="needs an aggregation"):
        shaping_transform(paper_methods("SARSA")["SARSA-RS"], torch.Size([2]), gamma=0.9, value_lr=0.1)


def test_monotone_potential_applies_to_the_learned_tables_over_series() -> None:
    patterns = [SubgoalSeries([Cell(3, 6), Cell(7, 9)])]
    made = {
        name: shaping_transform(
            paper_methods("SARSA")[name],
            torch.Size([4]),
            gamma=0.99,
            value_lr=0.25,
            patterns=patterns,
            aggregation=room_aggregation(),
            monotone_potential=True,
        )
        for name in ("HRS", "RRS", "NRS", "SARSA-RS")
    }
    assert made["HRS"].potential.monotone and made["RRS"].potential.monotone  # type: ignore[union-attr]
    assert isinstance(made["NRS"].potential, NaivePotential)  # type: ignore[union-attr]
    assert not made["SARSA-RS"].potential.monotone  # type: ignore[union-attr]  # an aggregation has no order
