"""The paper's methods as configurations of the shaping transform."""

from __future__ import annotations

import pytest
import torch

from torchrl_subgoal import Cell, NaivePotential, SubgoalSeries, TabularPotential
from torchrl_subgoal.domains.four_rooms import check_subgoal
from torchrl_subgoal.envs.four_rooms import free_cells, room_aggregation
from torchrl_subgoal.methods import HRS_D, Method, paper_methods, random_patterns, shaping_transform


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


def test_the_potential_update_candidates_reach_the_transforms_update() -> None:
    t = shaping_transform(
        HRS_D,
        torch.Size([2]),
        gamma=0.99,
        value_lr=0.1,
        patterns=[SubgoalSeries([Cell(3, 6), Cell(7, 9)])],
        prior_weight=2.0,
        achievement_reward=0.25,
    )
    assert t is not None and t.value_update is not None and t.value_update.loss is not None
    assert t.value_update.prior_weight == 2.0 and t.value_update.loss.achievement_reward == 0.25


def test_missing_pieces_are_errors() -> None:
    with pytest.raises(ValueError, match="needs subgoal patterns"):
        shaping_transform(paper_methods("SARSA")["HRS"], torch.Size([2]), gamma=0.9, value_lr=0.1)
    with pytest.raises(ValueError, match="needs an aggregation"):
        shaping_transform(paper_methods("SARSA")["SARSA-RS"], torch.Size([2]), gamma=0.9, value_lr=0.1)


# --------------------------------------------------------------- the default potential under a sparse goal reward

CORRIDOR = "w" * 17 + "\nw" + " " * 15 + "w\n" + "w" * 17  # 15 cells in a row: start at one end, goal at the other
TWO_ROUTES = "\n".join(  # from (3, 1) to (3, 11): 14 steps along the top corridor or along the bottom one
    [
        "wwwwwwwwwwwww",
        "w           w",
        "w wwwwwwwww w",
        "w wwwwwwwww w",
        "w wwwwwwwww w",
        "w           w",
        "wwwwwwwwwwwww",
    ]
)


def _episodes_to_success(method: str | None, learners: int = 16, episodes: int = 40, **conventions: object) -> float:
    """Tabular Q over (s, z) on the corridor (+1 at the goal only, 60 steps per episode): the mean episode in
    which each learner first reaches the goal (``episodes + 1`` if it never does). ``method=None``: the library's
    default potential, built as the README builds it (``TabularPotential.for_subgoals``)."""
    from torchrl.envs import TransformedEnv

    from torchrl_subgoal import SubgoalPotentialTransform
    from torchrl_subgoal.envs import FourRoomsEnv
    from torchrl_subgoal.methods import all_methods
    from torchrl_subgoal.training.qlearning import QLearningConfig, train_qlearning

    env = FourRoomsEnv(learners, layout=CORRIDOR, start=(1, 1), goal=(1, 15), max_steps=60)
    series = SubgoalSeries([Cell(1, 5), Cell(1, 10)])
    if method is None:
        potential = TabularPotential.for_subgoals(series, scale=1.0, batch_shape=env.batch_size)
        shaping = SubgoalPotentialTransform(series, potential, gamma=0.99, observation_key="cell", value_update=0.1)
    else:
        shaping = shaping_transform(
            all_methods("Q")[method],
            env.batch_size,
            gamma=0.99,
            value_lr=0.1,
            patterns=[series],
            observation_key="cell",
            **conventions,
        )
    shaped = TransformedEnv(env, shaping) if shaping is not None else env
    records = train_qlearning(shaped, QLearningConfig(episodes=episodes, lr=0.25, epsilon=0.1), seed=0).records
    found = records.steps < 60
    first = torch.where(found.any(1), found.float().argmax(1) + 1, torch.tensor(episodes + 1))
    return float(first.float().mean())


def test_under_a_sparse_goal_reward_the_default_potential_finds_the_goal_sooner() -> None:
    """Before the first success every return is 0, so a potential learned from zero stays 0 and cannot guide;
    the table started at the subgoals' progress prior (HRS) guides from the first episode, and the default
    (``for_subgoals``: the prior, and a rise towards the next subgoal's cell within each segment) sooner still.
    A random walk needs about 15² = 225 steps to cross the corridor; an episode has 60. Measured: unshaped
    25.1 episodes, zero start about as many, HRS 4.9, the default 1.9."""
    torch.set_num_threads(1)
    unshaped = _episodes_to_success("Q")
    prior = _episodes_to_success("HRS")
    default = _episodes_to_success(None)
    from_zero = _episodes_to_success("HRS", progress_scale=0.0, monotone_potential=False)
    assert prior < 0.5 * unshaped
    assert default < 0.6 * prior  # the within-segment term: fails for a potential over z alone
    assert from_zero > 0.8 * unshaped  # the zero table gives nothing to follow


def test_a_learner_on_the_other_route_is_never_charged_for_entering_a_subgoal() -> None:
    """Subgoals on the top corridor; the learner goes along the bottom one, so only ``V(z_0)`` learns (from the
    goal's reward) while ``z_1`` and ``z_2`` keep their initial values. Entering the first subgoal afterwards is
    not charged with the default potential (a monotone table); with the previous default (a zero table shaped
    as it is) it cost almost the goal's whole value."""
    from torchrl.envs import TransformedEnv
    from torchrl.envs.utils import step_mdp

    from torchrl_subgoal.envs import FourRoomsEnv

    series = SubgoalSeries([Cell(1, 4), Cell(1, 8)])
    bottom, top = [0, 0] + [1] * 10 + [2, 2], [2, 2] + [1] * 10 + [0, 0]  # down, right, up, left = 0, 1, 2, 3

    hrs = paper_methods("Q")["HRS"]

    def entering_cost(method: Method = hrs, **conventions: object) -> float:
        env = FourRoomsEnv(1, layout=TWO_ROUTES, start=(3, 1), goal=(3, 11), max_steps=50)
        shaping = shaping_transform(
            method,
            env.batch_size,
            gamma=0.99,
            value_lr=0.25,
            patterns=[series],
            observation_key="cell",
            **conventions,
        )
        shaped = TransformedEnv(env, shaping)
        for route in [bottom] * 30 + [top]:
            td = shaped.reset()
            for action in route:
                td = shaped.step(td.set("action", torch.tensor([action])))
                entered = bool((td["next", "subgoal_index"] == 1).all() and (td["subgoal_index"] == 0).all())
                if route is top and entered:
                    return float(td["next", "reward"] - td["next", "env_reward"])
                td = step_mdp(td)
        raise AssertionError("the top route never entered the first subgoal")

    assert entering_cost() >= -1e-6
    assert entering_cost(HRS_D) >= -1e-6  # the default: its within-segment term rises up to the subgoal too
    assert entering_cost(progress_scale=0.0, monotone_potential=False) < -0.5


def test_hrs_d_is_hrs_with_an_interpolating_table() -> None:
    from torchrl_subgoal.experiments.learners import learner_methods

    assert learner_methods("dqn")["HRS-D"] is HRS_D
    patterns = [SubgoalSeries([Cell(3, 6), Cell(7, 9)])]
    t = shaping_transform(HRS_D, torch.Size([2]), gamma=0.99, value_lr=0.1, patterns=patterns,
                          observation_key="cell")  # fmt: skip
    assert t is not None and isinstance(t.potential, TabularPotential)
    assert t.potential.interpolate and t.potential.monotone and t._settings.interpolate
    plain = shaping_transform(paper_methods("A2C")["HRS"], torch.Size([2]), gamma=0.99, value_lr=0.1,
                              patterns=patterns, observation_key="cell")  # fmt: skip
    assert plain is not None and not plain._settings.interpolate
