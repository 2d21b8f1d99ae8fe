"""The networks' input layers: features of an observation, the subgoal index joined, the hidden layers.

* :class:`FourierFeatures`, one-hot and float inputs (:func:`input_layer`);
* :func:`trunk`: the input layer (with the one-hot ``z`` joined when the learner sees it,
  :class:`~torchrl_subgoal.training.subgoal_input.SubgoalInput`) and the hidden layers;
* :func:`network`: a trunk and output layers as one module;
* :func:`subgoal_states` and :func:`subgoal_keys`: whether a learner's networks read ``z``, and what they read;
* :func:`q_network`: a Q-network over them (DQN's).
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import torch
from tensordict.utils import NestedKey
from torch import nn
from torchrl.data import Bounded, Categorical, OneHot, TensorSpec
from torchrl.envs import EnvBase
from torchrl.modules import QValueActor

from torchrl_subgoal.training.config import Features, LearnerConfig
from torchrl_subgoal.training.envs import Shaping
from torchrl_subgoal.training.subgoal_input import SUBGOAL_INDEX, SubgoalInput

__all__ = [
    "SUBGOAL_INDEX",
    "Features",
    "FourierFeatures",
    "input_layer",
    "network",
    "q_network",
    "subgoal_keys",
    "subgoal_states",
    "trunk",
]


class FourierFeatures(nn.Module):
    """``cos(π c · s̃)`` for every ``c ∈ {0..order}^D``, ``s̃ = clip((s − low) / (high − low), 0, 1)``.

    Args:
        low: lower bounds of the observation, ``[D]``.
        high: upper bounds, ``[D]``.
        order: the basis order (``(order + 1)^D`` features).

    Examples:
        >>> f = FourierFeatures(torch.zeros(2), torch.ones(2), order=1)
        >>> f(torch.tensor([[0.0, 1.0]])).round().tolist()
        [[1.0, -1.0, 1.0, -1.0]]
    """

    def __init__(self, low: torch.Tensor, high: torch.Tensor, order: int) -> None:
        super().__init__()
        low, high = torch.as_tensor(low, dtype=torch.float32), torch.as_tensor(high, dtype=torch.float32)
        dims = low.numel()
        grids = torch.meshgrid(*[torch.arange(order + 1, dtype=torch.float32)] * dims, indexing="ij")
        self.register_buffer("coefficients", torch.stack([g.reshape(-1) for g in grids], -1))  # [F, D]
        self.register_buffer("low", low.reshape(-1))
        self.register_buffer("scale", 1.0 / (high - low).reshape(-1))
        self.num_features = int(self.coefficients.shape[0])

    low: torch.Tensor
    scale: torch.Tensor
    coefficients: torch.Tensor

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        x = ((obs.float() - self.low) * self.scale).clamp(0.0, 1.0)
        return torch.cos(math.pi * x @ self.coefficients.T)


class _OneHot(nn.Module):
    def __init__(self, n: int) -> None:
        super().__init__()
        self.n = n

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return nn.functional.one_hot(obs.long(), self.n).float()


class _Float(nn.Module):
    """A vector observation as float32 (a float64 gymnasium observation, an integer one)."""

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return obs.float()


class _Chain(nn.Sequential):
    """``nn.Sequential`` whose first module takes every input (a network over ``(s, z)``)."""

    def forward(self, *inputs: torch.Tensor) -> torch.Tensor:
        modules = list(self)
        x = modules[0](*inputs)
        for module in modules[1:]:
            x = module(x)
        return x


def input_layer(spec: TensorSpec, features: Features, order: int) -> tuple[nn.Module, int]:
    """The features of an observation spec: a module and its output size.

    Args:
        spec: the observation's spec (unbatched or batched).
        features: ``"one_hot"`` (a categorical observation), ``"fourier"`` (a bounded one) or ``"mlp"``
            (the observation vector, as float32).
        order: the Fourier basis's order.

    Examples:
        >>> layer, size = input_layer(Categorical(104), "one_hot", 3)
        >>> size, layer(torch.tensor([2])).shape
        (104, torch.Size([1, 104]))
    """
    if features == "one_hot":
        if not isinstance(spec, Categorical | OneHot):
            raise ValueError(f"one_hot features need a categorical observation, got {type(spec).__name__}")
        n = int(spec.space.n)
        return (_OneHot(n) if isinstance(spec, Categorical) else nn.Flatten(-1)), n
    if features == "fourier":
        if not isinstance(spec, Bounded):
            raise ValueError(f"fourier features need a bounded observation, got {type(spec).__name__}")
        low, high = spec.space.low, spec.space.high
        while low.ndim > 1:
            low, high = low[0], high[0]
        basis = FourierFeatures(low, high, order)
        return basis, basis.num_features
    if features != "mlp":
        raise ValueError(f"features must be one_hot, fourier or mlp, got {features!r}")
    return (nn.Identity() if spec.dtype == torch.float32 else _Float()), (int(spec.shape[-1]) if spec.shape else 1)


def trunk(
    spec: TensorSpec,
    features: Features,
    hidden: Sequence[int],
    order: int,
    *,
    activation: type[nn.Module] = nn.Tanh,
    subgoal_states: int = 0,
) -> tuple[nn.Module, int]:
    """The input layers for an observation spec (with ``subgoal_states``, the one-hot ``z`` joined: with no
    hidden layer, their product, one linear function of the features per ``z`` (over one-hot features, a table
    over ``(s, z)``); with hidden layers, concatenated), then the hidden layers: a module over ``observation``
    (or ``(observation, z)``) and its output size.

    A shaped critic learns ``V(s) − Φ(s, z)``. Concatenated, ``z`` adds one constant per abstract state to a
    linear critic's output, which cancels a potential over ``z`` alone but not one that also varies within a
    segment (an interpolating table); the product cancels both (docs/shaping_defaults.md).

    Examples:
        >>> body, size = trunk(Bounded(0.0, 1.0, shape=(2,)), "fourier", (16,), 1, subgoal_states=3)
        >>> size, body(torch.rand(5, 2), torch.zeros(5, 1, dtype=torch.long)).shape
        (16, torch.Size([5, 16]))
        >>> trunk(Bounded(0.0, 1.0, shape=(2,)), "fourier", (), 1, subgoal_states=3)[1]  # 4 features per z
        12
    """
    first, size = input_layer(spec, features, order)
    product = not hidden
    if subgoal_states:
        size = SubgoalInput.size(size, subgoal_states, product=product)
    layers: list[nn.Module] = []
    for width in hidden:
        layers += [nn.Linear(size, width), activation()]
        size = width
    if subgoal_states:
        return SubgoalInput(subgoal_states, first, nn.Sequential(*layers), product=product), size
    return nn.Sequential(first, *layers), size


def network(body: nn.Module, *layers: nn.Module) -> nn.Module:
    """The ``layers`` after ``body(...)``, as one module; the body may read several inputs (``(s, z)``).

    Examples:
        >>> net = network(nn.Bilinear(2, 3, 4), nn.Tanh(), nn.Linear(4, 1))
        >>> net(torch.zeros(5, 2), torch.zeros(5, 3)).shape
        torch.Size([5, 1])
    """
    return _Chain(body, *layers)


def subgoal_states(config: LearnerConfig, shaping: Shaping | None) -> int:
    """Abstract states the networks' one-hot ``z`` input spans; 0 when they do not see ``z``.

    Args:
        config: ``config.sees_subgoal`` asks for the input (``None``, or ``"critic"`` for the value network
            alone: whenever there is shaping).
        shaping: the shaping whose transform keeps ``z`` (``"subgoal_index"``).

    Raises:
        ValueError: ``sees_subgoal=True`` without shaping (no transform keeps ``z``).

    Examples:
        >>> from torchrl_subgoal import Cell, SubgoalSeries, TabularPotential
        >>> from torchrl_subgoal.training import DQNConfig
        >>> shaping = Shaping(SubgoalSeries([Cell(3, 6), Cell(7, 9)]), TabularPotential(3))
        >>> subgoal_states(DQNConfig(), shaping), subgoal_states(DQNConfig(sees_subgoal=False), shaping)
        (3, 0)
    """
    if config.sees_subgoal is False or (config.sees_subgoal in (None, "critic") and shaping is None):
        return 0
    if shaping is None:
        raise ValueError("sees_subgoal needs shaping: the subgoal index z is kept by the shaping transform")
    return shaping.transform(shaping.potential, config.gamma, None).num_abstract_states


def subgoal_keys(observation_key: NestedKey, states: int) -> list[NestedKey]:
    """What a network reads: the observation, and ``z`` when it sees it (``states`` > 0).

    Examples:
        >>> subgoal_keys("observation", 3), subgoal_keys("observation", 0)
        (['observation', 'subgoal_index'], ['observation'])
    """
    return [observation_key, SUBGOAL_INDEX] if states else [observation_key]


def q_network(
    env: EnvBase,
    observation_key: NestedKey = "observation",
    *,
    features: Features = "mlp",
    hidden: Sequence[int] = (120, 84),
    fourier_order: int = 3,
    subgoal_states: int = 0,
) -> QValueActor:
    """A Q-network over ``observation_key`` for ``env``'s discrete actions: a ReLU MLP, one output per
    action, as TorchRL's ``QValueActor`` (writes ``"action_value"``, ``"chosen_action_value"`` and the
    greedy ``"action"``). With one-hot features and no hidden layer it is a Q-table: the output layer has
    no bias.

    Args:
        env: gives the observation and action specs.
        observation_key: the network's input.
        features: ``"one_hot"``, ``"fourier"`` or ``"mlp"`` (see :class:`DQNConfig`).
        hidden: hidden layer sizes.
        fourier_order: order of the Fourier basis.
        subgoal_states: if positive, the network also reads ``"subgoal_index"`` (one-hot ``z``).

    Examples:
        >>> from torchrl.envs import GymEnv
        >>> env = GymEnv("MountainCar-v0")
        >>> q = q_network(env, hidden=(16,))
        >>> td = q(env.reset())
        >>> td["action_value"].shape, td["action"].shape
        (torch.Size([3]), torch.Size([3]))
    """
    action_spec = env.full_action_spec_unbatched[env.action_key]
    if not isinstance(action_spec, Categorical | OneHot):
        raise ValueError(f"DQN needs discrete actions (Categorical or OneHot), got {type(action_spec).__name__}")
    spec = env.observation_spec[observation_key]
    body, size = trunk(spec, features, hidden, fourier_order, activation=nn.ReLU, subgoal_states=subgoal_states)
    # one-hot features and no hidden layer: a Q-table; a bias would give every state's value of an action a
    # shared term (four-rooms: greedy loops through rarely visited cells valued at that term)
    table = features == "one_hot" and not hidden
    net = network(body, nn.Linear(size, int(action_spec.space.n), bias=not table))
    return QValueActor(net, in_keys=subgoal_keys(observation_key, subgoal_states), spec=action_spec)
