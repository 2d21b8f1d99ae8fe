"""Potentials: tabular (per learner), neural, naive."""

from __future__ import annotations

import pytest
import torch
from torch import nn

from torchrl_subgoal import NaivePotential, NeuralPotential, TabularPotential


def test_tabular_one_table_per_learner_and_time_dims() -> None:
    v = TabularPotential(3, batch_shape=(2,))
    with torch.no_grad():
        v.table.copy_(torch.tensor([[0.0, 1.0, 2.0], [10.0, 11.0, 12.0]]))
    assert v(torch.tensor([[2], [0]])).tolist() == [[2.0], [10.0]]
    # a rollout [B, T, 1] reads each learner's own table at every time step
    z = torch.tensor([[[0], [1], [2]], [[2], [2], [1]]])
    assert v(z).squeeze(-1).tolist() == [[0.0, 1.0, 2.0], [12.0, 12.0, 11.0]]


def test_tabular_shared_table() -> None:
    v = TabularPotential(2, init=0.5)
    assert v(torch.tensor([[0], [1], [1]])).tolist() == [[0.5]] * 3


def test_tabular_shape_errors() -> None:
    v = TabularPotential(3, batch_shape=(2,))
    with pytest.raises(ValueError, match="singleton"):
        v(torch.tensor([0, 1]))
    with pytest.raises(ValueError, match="learner batch shape"):
        v(torch.tensor([[0], [1], [2]]))


def test_neural_reads_the_anchor() -> None:
    net = nn.Linear(3, 1)
    v = NeuralPotential(net)
    anchor = torch.randn(5, 3)
    assert torch.allclose(v(anchor), net(anchor))
    assert v.in_keys == ["subgoal_anchor"]


def test_naive_is_eta_on_achievement() -> None:
    v = NaivePotential(10_000.0)
    assert v(torch.tensor([[True], [False]])).tolist() == [[10_000.0], [0.0]]
    assert list(v.parameters()) == []


def test_value_operator_writes_state_value() -> None:
    from tensordict import TensorDict

    v = TabularPotential(3, batch_shape=(2,), init=1.0)
    td = TensorDict({"subgoal_index": torch.tensor([[0], [2]])}, batch_size=[2])
    assert v.as_value_operator()(td)["state_value"].tolist() == [[1.0], [1.0]]


def test_potentials_are_tensordict_modules() -> None:
    from tensordict import TensorDict
    from tensordict.nn import TensorDictModuleBase

    v = TabularPotential(4, batch_shape=(2,))
    with torch.no_grad():
        v.table.copy_(torch.arange(8.0).reshape(2, 4))
    assert isinstance(v, TensorDictModuleBase)
    assert v.in_keys == ["subgoal_index", "subgoal_learner"] and v.out_keys == ["subgoal_value"]
    td = TensorDict(
        {"subgoal_index": torch.tensor([[3], [1], [0]]), "subgoal_learner": torch.tensor([[0], [1], [1]])}, [3]
    )
    assert v(td)["subgoal_value"].squeeze(-1).tolist() == [3.0, 5.0, 4.0]  # rows by the learner key
    shared = TabularPotential(4)
    assert shared.in_keys == ["subgoal_index"]
    naive = NaivePotential(2.0, achieved_key="hit")
    assert naive(TensorDict({"hit": torch.tensor([[True]])}, [1]))["subgoal_value"].item() == 2.0


def test_learner_key_errors() -> None:
    v = TabularPotential(3, batch_shape=(2,))
    with pytest.raises(ValueError, match=r"subgoal_learner values must lie in \[0, 2\)"):
        v(torch.zeros(2, 1, dtype=torch.long), torch.tensor([[0], [2]]))
    with pytest.raises(ValueError, match=r"subgoal_index values must lie in \[0, 3\)"):
        v(torch.tensor([[0], [3]]))
    with pytest.raises(ValueError, match="must be an integer tensor"):
        v(torch.zeros(2, 1))
    with pytest.raises(KeyError, match="reads 'subgoal_index'"):
        from tensordict import TensorDict

        v(TensorDict({}, [2]))


def test_a_frozen_table_is_not_trained_online() -> None:
    """The same random walk moves a table that is not frozen (it closes an SMDP transition) and not a frozen one."""
    from torchrl.envs import TransformedEnv

    from torchrl_subgoal import SubgoalPotentialTransform, SubgoalSeries
    from torchrl_subgoal.envs import FourRoomsEnv
    from torchrl_subgoal.subgoals import Cell

    tables = {}
    for frozen in (False, True):
        potential = TabularPotential(2)
        if frozen:
            potential.freeze([0.25, 0.75])
        else:
            with torch.no_grad():
                potential.table.copy_(torch.tensor([0.25, 0.75]))
        transform = SubgoalPotentialTransform(
            SubgoalSeries([Cell(4, 9)]), potential, gamma=0.99, observation_key="cell", value_update=0.5
        )
        assert transform.learning != frozen
        torch.manual_seed(1)  # a walk that reaches the hallway within 200 steps
        TransformedEnv(FourRoomsEnv(), transform).rollout(200)
        tables[frozen] = potential.table.tolist()
    assert tables[False] != [0.25, 0.75] and tables[True] == [0.25, 0.75]
    with pytest.raises(ValueError, match="finite"):
        TabularPotential(2).freeze([0.0, float("nan")])
