"""SubgoalValueLoss: the SMDP TD(0) target, and SGD = the paper's tabular update."""

from __future__ import annotations

import pytest
import torch
from tensordict import TensorDict
from torchrl.objectives.utils import ValueEstimators
from torchrl.objectives.value import TD0Estimator

from torchrl_subgoal import NeuralPotential, SubgoalValueLoss, TabularPotential, ValueUpdate

#: the paper's target: the mean, time-outs bootstrapped
PAPER = {"expectile": 0.5, "bootstrap_truncated": True}


def transitions(n: int, num_states: int, seed: int) -> TensorDict:
    g = torch.Generator().manual_seed(seed)
    col = (n, 1)
    terminated = torch.rand(col, generator=g) < 0.3
    return TensorDict(
        {
            "subgoal_index": torch.randint(num_states, col, generator=g),
            "steps_to_next_obs": torch.randint(1, 30, col, generator=g),
            "mask": torch.rand(col, generator=g) < 0.7,
            "next": {
                "subgoal_index": torch.randint(num_states, col, generator=g),
                "reward": torch.randn(col, generator=g),
                "terminated": terminated,
                "done": terminated | (torch.rand(col, generator=g) < 0.2),
            },
        },
        batch_size=[n],
    )


def test_sgd_step_is_the_papers_update() -> None:
    """One SGD step (lr α_v) on the loss = V(z) += α_v (r_h + γ_v^k V(z') − V(z)) per learner."""
    n, num_states, lr, gamma = 50, 4, 0.25, 0.95
    v = TabularPotential(num_states, batch_shape=(n,))
    with torch.no_grad():
        v.table.copy_(torch.randn(n, num_states))
    data = transitions(n, num_states, seed=0)
    before = v.table.detach().clone()

    expected = before.clone()
    for b in range(n):
        if not data["mask"][b, 0]:
            continue
        z, z2 = int(data["subgoal_index"][b, 0]), int(data["next", "subgoal_index"][b, 0])
        k = int(data["steps_to_next_obs"][b, 0])
        v_next = 0.0 if data["next", "terminated"][b, 0] else float(before[b, z2])
        target = float(data["next", "reward"][b, 0]) + gamma**k * v_next
        expected[b, z] += lr * (target - float(before[b, z]))

    loss = SubgoalValueLoss(v, **PAPER).make_value_estimator(gamma=gamma)
    opt = torch.optim.SGD(v.parameters(), lr=lr)
    loss(data)["loss_value"].backward()
    opt.step()
    assert torch.allclose(v.table.detach(), expected, atol=1e-6)
    assert not torch.equal(expected, before)  # the test did exercise updates


def test_target_equals_torchrl_td0_estimator() -> None:
    """The SMDP target is TorchRL's TD(0) estimate with γ raised to steps_to_next_obs."""
    n, num_states = 40, 3
    v = TabularPotential(num_states, batch_shape=(n,))
    with torch.no_grad():
        v.table.copy_(torch.randn(n, num_states))
    data = transitions(n, num_states, seed=1)
    data["mask"] = torch.ones(n, 1, dtype=torch.bool)
    # an estimator built independently, reading the potential as its value network
    estimator = TD0Estimator(gamma=0.9, value_network=v.as_value_operator())
    with torch.no_grad():
        reference = estimator.value_estimate(data.clone())
    assert (data["steps_to_next_obs"] > 1).any() and not torch.allclose(reference, data["next", "reward"])
    out = SubgoalValueLoss(v, bootstrap_truncated=True).make_value_estimator(gamma=0.9)(data)
    value = v(data["subgoal_index"]).detach()
    assert torch.allclose(out["td_error"] + value, reference, atol=1e-6)


def test_mask_excludes_non_transitions_and_mean_reduction() -> None:
    v = TabularPotential(2, batch_shape=(2,))
    data = transitions(2, 2, seed=2)
    data["mask"] = torch.tensor([[True], [False]])
    total = SubgoalValueLoss(v).make_value_estimator(gamma=0.9)(data)
    assert total["td_error"][1, 0] == 0.0
    mean = SubgoalValueLoss(v, reduction="mean").make_value_estimator(gamma=0.9)(data)
    assert torch.isclose(mean["loss_value"], total["loss_value"])  # one transition: sum == mean


def test_neural_potential_learns_a_constant_target() -> None:
    torch.manual_seed(0)
    v = NeuralPotential(torch.nn.Sequential(torch.nn.Linear(2, 16), torch.nn.Tanh(), torch.nn.Linear(16, 1)))
    loss = SubgoalValueLoss(v, reduction="mean").make_value_estimator(gamma=0.9)
    opt = torch.optim.Adam(v.parameters(), lr=1e-2)
    n = 64
    data = TensorDict(
        {
            "subgoal_anchor": torch.randn(n, 2),
            "steps_to_next_obs": torch.ones(n, 1, dtype=torch.long),
            "mask": torch.ones(n, 1, dtype=torch.bool),
            "next": {
                "subgoal_anchor": torch.randn(n, 2),
                "reward": torch.full((n, 1), 2.0),
                "terminated": torch.ones(n, 1, dtype=torch.bool),
                "done": torch.ones(n, 1, dtype=torch.bool),
            },
        },
        batch_size=[n],
    )
    start = v(data["subgoal_anchor"]).detach()
    assert (start - 2.0).abs().max() > 1.0
    for _ in range(600):
        opt.zero_grad()
        loss(data)["loss_value"].backward()
        opt.step()
    assert torch.allclose(v(data["subgoal_anchor"]), torch.full((n, 1), 2.0), atol=0.1)


def test_configurable_keys_and_reduction_none() -> None:
    v = TabularPotential(3)
    data = transitions(6, 3, seed=4)
    renamed = data.rename_key_("mask", "real")
    renamed.rename_key_(("next", "reward"), ("next", "r_h"))
    loss = SubgoalValueLoss(v, reduction="none").make_value_estimator(gamma=0.9)
    loss.set_keys(mask="real", reward="r_h")
    out = loss(renamed)
    assert out["loss_value"].shape == (6, 1)
    assert torch.equal(out["loss_value"] == 0, ~renamed["real"] | (out["td_error"] == 0))
    with pytest.raises(ValueError, match="reduction"):
        SubgoalValueLoss(v, reduction="max")  # type: ignore[arg-type]


def test_misuse_gives_clear_errors() -> None:
    v = TabularPotential(3)
    collected = TensorDict({"observation": torch.zeros(4, 1), "next": {"reward": torch.zeros(4, 1)}}, [4])
    with pytest.raises(ValueError, match=r"SubgoalValueLoss reads SMDP transitions .*missing \['subgoal_index'"):
        SubgoalValueLoss(v).make_value_estimator(gamma=0.9)(collected)
    with pytest.raises(TypeError, match="TensorDict module"):
        SubgoalValueLoss(torch.nn.Linear(2, 1))  # type: ignore[arg-type]
    wide = NeuralPotential(torch.nn.Linear(2, 3))
    data = TensorDict(
        {
            "subgoal_anchor": torch.zeros(4, 2),
            "steps_to_next_obs": torch.ones(4, 1, dtype=torch.long),
            "next": {
                "subgoal_anchor": torch.zeros(4, 2),
                "reward": torch.zeros(4, 1),
                "terminated": torch.zeros(4, 1, dtype=torch.bool),
            },
        },
        [4],
    )
    with pytest.raises(ValueError, match=r"returned values of shape \(4, 3\)"):
        SubgoalValueLoss(wide).make_value_estimator(gamma=0.9)(data)


def test_any_tensordict_module_with_a_make_value_estimator_hook() -> None:
    from tensordict.nn import TensorDictModule

    net = TensorDictModule(torch.nn.Embedding(3, 1), in_keys=["z"], out_keys=["v"])
    data = transitions(8, 3, seed=5)
    data.rename_key_("subgoal_index", "z")
    data.rename_key_(("next", "subgoal_index"), ("next", "z"))
    data["z"], data["next", "z"] = data["z"].squeeze(-1), data["next", "z"].squeeze(-1)
    loss = SubgoalValueLoss(net).make_value_estimator(gamma=0.8)
    assert loss.tensor_keys.value == "v"
    out = loss(data)
    out["loss_value"].backward()
    assert net.module.weight.grad is not None
    loss.make_value_estimator(gamma=0.5)  # the TD(0) estimator, another discount
    assert float(loss.value_estimator.gamma) == 0.5
    with pytest.raises(NotImplementedError, match="TD"):
        loss.make_value_estimator(ValueEstimators.GAE)


def test_gamma_goes_through_make_value_estimator() -> None:
    v = TabularPotential(3)
    with pytest.raises(
        TypeError, match=r"make_value_estimator: SubgoalValueLoss\(potential\)\.make_value_estimator\(gamma=0\.9\)"
    ):
        SubgoalValueLoss(v, gamma=0.9)
    loss = SubgoalValueLoss(v)  # TorchRL's default discount until one is made
    assert loss.gamma == pytest.approx(0.99)
    assert loss.make_value_estimator(gamma=0.5) is loss and loss.gamma == 0.5
    with pytest.raises(ValueError, match=r"gamma must lie in \[0, 1\], got 1.5"):
        loss.make_value_estimator(gamma=1.5)


def test_a_masked_row_lets_no_nan_through() -> None:
    """A NaN in a masked row (a padding transition) reaches neither the loss nor the potential's gradient."""
    v = TabularPotential(3, batch_shape=(4,))
    data = transitions(4, 3, seed=6)
    data["mask"] = torch.tensor([[True], [False], [True], [False]])
    data["next", "reward"][1] = float("nan")
    data["next", "reward"][3] = float("inf")
    for reduction in ("sum", "mean", "none"):
        v.zero_grad()
        out = SubgoalValueLoss(v, reduction=reduction).make_value_estimator(gamma=0.9)(data)  # type: ignore[arg-type]
        assert torch.isfinite(out["loss_value"]).all() and torch.isfinite(out["td_error"]).all(), reduction
        out["loss_value"].sum().backward()
        assert v.table.grad is not None and torch.isfinite(v.table.grad).all(), reduction
        assert (v.table.grad[[1, 3]] == 0).all() and (v.table.grad[[0, 2]] != 0).any(), reduction


def test_set_keys_value_takes_effect() -> None:
    """forward reads the value entry named by tensor_keys.value, not the potential's last output."""
    from tensordict.nn import TensorDictModule

    both = TensorDictModule(lambda z: (z.float(), 10 * z.float()), in_keys=["subgoal_index"], out_keys=["small", "big"])
    data = transitions(5, 3, seed=7)
    data["mask"] = torch.ones(5, 1, dtype=torch.bool)
    loss = SubgoalValueLoss(both, bootstrap_truncated=True).make_value_estimator(gamma=0.9)
    assert loss.tensor_keys.value == "big"
    big = loss(data)["td_error"]
    loss.set_keys(value="small")
    small = loss(data)["td_error"]
    z, z2 = data["subgoal_index"].float(), data["next", "subgoal_index"].float()
    target = data["next", "reward"] + 0.9 ** data["steps_to_next_obs"] * z2 * ~data["next", "terminated"]
    assert torch.allclose(small, target - z, atol=1e-5)
    assert torch.allclose(
        big,
        data["next", "reward"] + 0.9 ** data["steps_to_next_obs"] * 10 * z2 * ~data["next", "terminated"] - 10 * z,
        atol=1e-4,
    )


def test_the_expectile_weights_each_sgd_step() -> None:
    """With ``τ`` and SGD (sum reduction), a target above ``V(z)`` moves it by ``α 2τ δ``, one below by
    ``α 2(1 − τ) δ``: ``V`` settles at the ``τ``-expectile of its targets."""
    v = TabularPotential(2, batch_shape=(2,))
    one = torch.ones(2, 1, dtype=torch.bool)
    data = TensorDict(
        {
            "subgoal_index": torch.zeros(2, 1, dtype=torch.long),
            "steps_to_next_obs": torch.ones(2, 1, dtype=torch.long),
            "mask": one,
            "achieved": one,
            "next": {
                "subgoal_index": torch.ones(2, 1, dtype=torch.long),
                "reward": torch.tensor([[2.0], [-2.0]]),
                "terminated": one,
                "done": one,
            },
        },
        batch_size=[2],
    )
    loss = SubgoalValueLoss(v, expectile=0.9).make_value_estimator(gamma=0.9)
    loss(data)["loss_value"].backward()
    with torch.no_grad():
        v.table -= 0.1 * v.table.grad
    assert v.table[:, 0].tolist() == pytest.approx([0.1 * 1.8 * 2.0, 0.1 * 0.2 * -2.0])
    with pytest.raises(ValueError, match="expectile"):
        SubgoalValueLoss(v, expectile=1.0)


def test_a_time_out_inside_z_trains_nothing_unless_bootstrapped() -> None:
    """Rows: a time-out inside ``z``; a time-out the step a subgoal was achieved; a termination. By default
    the first is skipped (its TD error 0); ``bootstrap_truncated=True`` trains on all three; without an
    ``"achieved"`` entry every truncated row is skipped."""
    v = TabularPotential(3, batch_shape=(3,))
    col = (3, 1)
    data = TensorDict(
        {
            "subgoal_index": torch.zeros(col, dtype=torch.long),
            "steps_to_next_obs": torch.ones(col, dtype=torch.long),
            "mask": torch.ones(col, dtype=torch.bool),
            "achieved": torch.tensor([[False], [True], [True]]),
            "next": {
                "subgoal_index": torch.tensor([[0], [1], [1]]),
                "reward": -torch.ones(col),
                "terminated": torch.tensor([[False], [False], [True]]),
                "done": torch.ones(col, dtype=torch.bool),
            },
        },
        batch_size=[3],
    )
    skipped = SubgoalValueLoss(v).make_value_estimator(gamma=0.9)(data)["td_error"]
    assert skipped.reshape(-1).tolist() == [0.0, -1.0, -1.0]
    every = SubgoalValueLoss(v, bootstrap_truncated=True).make_value_estimator(gamma=0.9)(data)["td_error"]
    assert every.reshape(-1).tolist() == [-1.0, -1.0, -1.0]
    unknown = SubgoalValueLoss(v).make_value_estimator(gamma=0.9)(data.exclude("achieved"))["td_error"]
    assert unknown.reshape(-1).tolist() == [0.0, 0.0, -1.0]


def one_transition(z: int, z_next: int, steps: int, reward: float, terminated: bool = False) -> TensorDict:
    col = (1, 1)
    return TensorDict(
        {
            "subgoal_index": torch.full(col, z),
            "steps_to_next_obs": torch.full(col, steps),
            "mask": torch.ones(col, dtype=torch.bool),
            "next": {
                "subgoal_index": torch.full(col, z_next),
                "reward": torch.full(col, reward),
                "terminated": torch.full(col, terminated),
                "done": torch.full(col, terminated),
            },
        },
        batch_size=[1],
    )


def test_an_achievement_reward_is_added_to_the_target_of_a_transition_that_reached_a_subgoal() -> None:
    """``r_h + c γ^(k−1) + γ^k V(z')`` where ``z' ≠ z``; a transition that stayed in ``z`` gets nothing."""
    v = TabularPotential(3)
    with torch.no_grad():
        v.table.copy_(torch.tensor([0.0, 0.5, 1.0]))
    loss = SubgoalValueLoss(v, expectile=0.5, achievement_reward=0.2).make_value_estimator(gamma=0.9)
    reached = loss(one_transition(0, 1, steps=3, reward=0.1))["td_error"].item()
    assert reached == pytest.approx(0.1 + 0.2 * 0.9**2 + 0.9**3 * 0.5)
    stayed = loss(one_transition(1, 1, steps=3, reward=0.1, terminated=True))["td_error"].item()
    assert stayed == pytest.approx(0.1 - 0.5)
    with pytest.raises(ValueError, match="achievement_reward must be finite"):
        SubgoalValueLoss(v, achievement_reward=float("nan"))


def test_counting_the_achievements_to_come_makes_the_value_fall_along_the_series() -> None:
    """With ``c`` per subgoal and no reward, an episode that achieves both subgoals and times out teaches
    ``V(z₀) ≈ c(γ^a + γ^(a+b))``, ``V(z₁) ≈ cγ^b``, ``V(z₂) = 0``: the count still to come is largest at the
    start, so shaped with it each achievement is charged (why the candidate is not the default)."""
    v = TabularPotential(3)
    update = ValueUpdate(0.5, SubgoalValueLoss(v, achievement_reward=1.0).make_value_estimator(gamma=0.9))
    for _ in range(60):
        update.step(one_transition(0, 1, steps=4, reward=0.0))
        update.step(one_transition(1, 2, steps=4, reward=0.0))
    values = v.table.detach().tolist()
    assert values[0] > values[1] > values[2] == 0.0
    assert values[1] == pytest.approx(0.9**3, rel=1e-3)


def test_a_prior_weight_averages_the_prior_counted_k_times_with_the_targets() -> None:
    """``prior_weight=k``: the ``n``-th update of an entry steps by ``max(α_v, 1/(k + n))``, so with the mean
    target ``V`` is ``(k · prior + Σ targets) / (k + n)`` until that falls to ``α_v``; the counts are kept
    per entry."""
    v = TabularPotential(3, init=[0.0, 0.6, 1.2])
    update = ValueUpdate(0.01, SubgoalValueLoss(v, expectile=0.5).make_value_estimator(gamma=0.9), prior_weight=2.0)
    targets = [0.0, 0.3, 0.9]
    for t in targets:
        update.step(one_transition(1, 1, steps=1, reward=t, terminated=True))
    assert v.table[1].item() == pytest.approx((2 * 0.6 + sum(targets)) / (2 + len(targets)))
    assert v.updates.tolist() == [0.0, 3.0, 0.0]
    assert v.table[2].item() == pytest.approx(1.2)  # an entry without transitions keeps its prior
    with pytest.raises(ValueError, match="prior_weight must be >= 0"):
        ValueUpdate(0.1, prior_weight=-1.0)


def test_a_prior_weight_given_without_a_loss_is_kept() -> None:
    from torchrl_subgoal.transform.setup import online_update

    update = online_update(ValueUpdate(0.1, prior_weight=3.0), TabularPotential(3), 0.9)
    assert update is not None and update.prior_weight == 3.0 and update.loss is not None
    with pytest.raises(ValueError, match="prior_weight counts a TabularPotential's updates, not NeuralPotential's"):
        online_update(ValueUpdate(0.1, prior_weight=3.0), NeuralPotential(torch.nn.Linear(2, 1)), 0.9)
