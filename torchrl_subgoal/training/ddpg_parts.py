"""DDPG from TorchRL parts, configured as the authors' pick-and-place runs.

* actor ``π(o)`` and critic ``Q(o, a)``: MLPs with ``hidden`` layers (3 × 256),
  as :class:`~torchrl.modules.Actor` and :class:`~torchrl.modules.ValueOperator`;
  both read the observation normalised by running statistics
  (:class:`RunningNorm`, clipped to ±5, as the authors' normaliser);
* :class:`~torchrl.objectives.DDPGLoss` with a TD(0) target clipped to
  ``[-clip_return, 0]`` (:class:`ClippedTD0Estimator`; the authors clip the
  target of a −1/0 reward to ``[−1/(1−γ), 0]``), plus an L2 penalty on the
  actor's actions (``action_l2``);
* :class:`~torchrl.objectives.SoftUpdate` with Polyak 0.95, once per cycle;
* exploration: Gaussian noise of s.d. 0.2, clipped to the action bounds, then with
  probability 0.3 a uniformly random action (:class:`GaussianOrRandom`, what TorchRL's
  ``AdditiveGaussianModule`` then ``EGreedyModule`` do, in one module without their
  per-step spec work);
* a TorchRL :class:`~torchrl.data.ReplayBuffer` of the DDPG keys only.

:class:`DDPGAgent` holds them all, for one learner or a batch of ``K`` (stacked networks,
per-learner normalisers and replay: :mod:`torchrl_subgoal.training.stack`), and exposes what a
training loop needs:
``policy`` (exploring) and ``greedy`` (for evaluation), ``extend`` (store a
collected batch and update the normaliser), ``update`` (one gradient step
of critic and actor) and ``soft_update``; its ``state_dict`` covers networks,
optimisers and normaliser (the replay buffer's contents are saved by the caller,
see :mod:`torchrl_subgoal.experiments.checkpoint`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModule, TensorDictSequential
from tensordict.utils import NestedKey
from torch import nn
from torchrl.data import Bounded
from torchrl.envs.utils import ExplorationType, exploration_type
from torchrl.modules import MLP, Actor, ValueOperator
from torchrl.objectives import DDPGLoss, SoftUpdate, TD3Loss
from torchrl.objectives.value import TD0Estimator

from torchrl_subgoal.training.stack import LearnerReplay, LearnerStack, learner_means
from torchrl_subgoal.training.subgoal_input import SUBGOAL_INDEX, SubgoalInput

__all__ = ["ClippedTD0Estimator", "DDPGAgent", "DDPGConfig", "GaussianOrRandom", "RunningNorm", "TD3Settings", "mlp"]

OBSERVATION = "observation"
NORMALIZED = "observation_normalized"
#: What the replay buffer keeps of a collected batch.
DDPG_KEYS = (
    OBSERVATION,
    "action",
    ("next", OBSERVATION),
    ("next", "reward"),
    ("next", "done"),
    ("next", "terminated"),
)


@dataclass(frozen=True)
class DDPGConfig:
    """DDPG hyper-parameters (defaults: facts.md and the authors' released configuration).

    Attributes:
        hidden: hidden layer sizes of actor and critic.
        actor_lr: Adam learning rate of the actor.
        critic_lr: Adam learning rate of the critic.
        gamma: discount.
        polyak: target ← polyak · target + (1 − polyak) · online.
        batch_size: transitions per gradient step.
        buffer_size: replay capacity.
        random_eps: probability of a uniformly random action.
        noise_eps: s.d. of the Gaussian action noise (actions lie in [−1, 1]).
        action_l2: weight of the actor's ``mean(π(o)²)`` penalty.
        clip_return: TD targets are clipped to ``[-clip_return, 0]`` (the return of a
            −1/0 reward lies there); ``None`` leaves them unclipped. Default ``1/(1−γ)``.
        clip_positive: clip targets above at 0 (the authors' ``clip_pos_returns``).
        norm_clip: normalised observations are clipped to ``±norm_clip``.
        norm_eps: the normaliser's smallest standard deviation.

    Examples:
        >>> config = DDPGConfig(hidden=(64, 64))
        >>> config.hidden, config.gamma, config.clip_return
        ((64, 64), 0.98, 50.0)
    """

    hidden: tuple[int, ...] = (256, 256, 256)
    actor_lr: float = 1e-3
    critic_lr: float = 1e-3
    gamma: float = 0.98
    polyak: float = 0.95
    batch_size: int = 256
    buffer_size: int = 1_000_000
    random_eps: float = 0.3
    noise_eps: float = 0.2
    action_l2: float = 1.0
    clip_return: float | None = 50.0
    clip_positive: bool = True
    norm_clip: float = 5.0
    norm_eps: float = 0.01


def mlp(in_features: int, out_features: int, hidden: Sequence[int]) -> MLP:
    """A ReLU MLP with ``hidden`` layers (TorchRL's :class:`~torchrl.modules.MLP`).

    The ReLUs work in place on their linear layer's output (which no backward pass reads): the same
    values and gradients, one fewer activation tensor per layer (a DDPG gradient step of batch 256 and
    256 hidden units about 5% faster on CPU).

    Examples:
        >>> import torch
        >>> net = mlp(3, 2, (8, 8))
        >>> net(torch.zeros(5, 3)).shape
        torch.Size([5, 2])
    """
    return MLP(
        in_features=in_features,
        out_features=out_features,
        num_cells=list(hidden),
        activation_class=nn.ReLU,
        activation_kwargs={"inplace": True},
    )


class RunningNorm(nn.Module):
    """``clip((x − mean) / max(std, eps), ±clip)`` with mean and s.d. of all data seen so far, one set of
    statistics per learner of a batch.

    The statistics are buffers (saved in ``state_dict``) changed only by :meth:`update`. With ``learners``
    ``K``, the inputs' first dim is learner-major (``K·M`` rows, or ``K`` rows of samples), each learner's
    rows normalised by, and added to, its own statistics.

    Args:
        size: features of ``x``.
        eps: the smallest standard deviation.
        clip: bound of the normalised values.
        learners: ``K``.

    Examples:
        >>> norm = RunningNorm(2)
        >>> norm.update(torch.tensor([[0.0, 1.0], [2.0, 1.0]]))
        >>> norm(torch.tensor([[2.0, 1.0]]))
        tensor([[1., 0.]])
        >>> two = RunningNorm(1, learners=2)
        >>> two.update(torch.tensor([[0.0], [2.0], [10.0], [30.0]]))  # learner 0: 0, 2; learner 1: 10, 30
        >>> two(torch.tensor([[1.0], [20.0]])).flatten().tolist(), float(two.learner(1).mean)
        ([0.0, 0.0], 20.0)
    """

    total: torch.Tensor
    total_sq: torch.Tensor
    count: torch.Tensor
    mean: torch.Tensor
    std: torch.Tensor

    def __init__(self, size: int, eps: float = 0.01, clip: float = 5.0, learners: int = 1) -> None:
        super().__init__()
        self.eps, self.clip, self.learners = float(eps), float(clip), int(learners)
        self.register_buffer("total", torch.zeros(learners, size, dtype=torch.float64))
        self.register_buffer("total_sq", torch.zeros(learners, size, dtype=torch.float64))
        self.register_buffer("count", torch.zeros(learners, 1, dtype=torch.float64))
        self.register_buffer("mean", torch.zeros(learners, size))
        self.register_buffer("std", torch.ones(learners, size))

    @torch.no_grad()
    def update(self, x: torch.Tensor) -> None:
        """Add a batch ``[K·rows, ..., size]`` (learner-major) to each learner's statistics."""
        own = x.reshape(self.learners, -1, x.shape[-1]).to(torch.float64)
        self.total += own.sum(1)
        self.total_sq += own.square().sum(1)
        self.count += own.shape[1]
        mean = self.total / self.count
        var = (self.total_sq / self.count - mean.square()).clamp_min(self.eps**2)
        self.mean.copy_(mean)
        self.std.copy_(var.sqrt())

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        own = x.reshape(self.learners, -1, x.shape[-1])
        return ((own - self.mean.unsqueeze(1)) / self.std.unsqueeze(1)).clamp(-self.clip, self.clip).reshape(x.shape)

    def learner(self, k: int) -> RunningNorm:
        """Learner ``k``'s statistics, as a normaliser of its own."""
        own = RunningNorm(self.mean.shape[-1], self.eps, self.clip).to(self.mean.device)
        for name, buffer in own.named_buffers():
            buffer.copy_(getattr(self, name)[k : k + 1])
        return own


class GaussianOrRandom(nn.Module):
    """Exploration around a deterministic action: ``clip(a + σ·N(0, 1))``, replaced with probability
    ``eps`` by a uniform random action; under a deterministic exploration type, ``a`` unchanged.

    The authors' exploration (and TorchRL's ``AdditiveGaussianModule`` followed by
    ``EGreedyModule``) in three tensor operations per step.

    Args:
        low: lower action bounds, ``[action_size]``.
        high: upper action bounds.
        sigma: s.d. of the Gaussian noise, in action units.
        eps: probability of a uniform random action.

    Examples:
        >>> explore = GaussianOrRandom(-torch.ones(2), torch.ones(2), sigma=0.2, eps=0.3)
        >>> actions = explore(torch.zeros(1000, 2))
        >>> bool((actions.abs() <= 1).all()), round(float((actions == 0).float().mean()), 1)
        (True, 0.0)
        >>> from torchrl.envs import ExplorationType, set_exploration_type
        >>> with set_exploration_type(ExplorationType.DETERMINISTIC):
        ...     explore(torch.zeros(1, 2)).tolist()
        [[0.0, 0.0]]
    """

    low: torch.Tensor
    high: torch.Tensor

    def __init__(self, low: torch.Tensor, high: torch.Tensor, sigma: float, eps: float) -> None:
        super().__init__()
        self.register_buffer("low", torch.as_tensor(low, dtype=torch.float32).clone())
        self.register_buffer("high", torch.as_tensor(high, dtype=torch.float32).clone())
        self.sigma, self.eps = float(sigma), float(eps)

    def forward(self, action: torch.Tensor) -> torch.Tensor:
        if exploration_type() not in (ExplorationType.RANDOM, None):
            return action
        noisy = torch.minimum(torch.maximum(action + self.sigma * torch.randn_like(action), self.low), self.high)
        uniform = self.low + (self.high - self.low) * torch.rand_like(action)
        random = torch.rand((*action.shape[:-1], 1), device=action.device) < self.eps
        return torch.where(random, uniform, noisy)


class ClippedTD0Estimator(TD0Estimator):
    """TorchRL's TD(0) estimator with the target clipped to ``[low, high]``.

    Args:
        low: lower bound of the target (``None``: none).
        high: upper bound of the target (``None``: none).
        **kwargs: :class:`~torchrl.objectives.value.TD0Estimator`'s arguments.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from tensordict.nn import TensorDictModule
        >>> value = TensorDictModule(torch.nn.Linear(2, 1), in_keys=["observation"], out_keys=["state_value"])
        >>> estimator = ClippedTD0Estimator(low=-1.0, high=0.0, gamma=0.9, value_network=value)
        >>> td = TensorDict({"observation": torch.zeros(4, 2), "next": {
        ...     "observation": torch.zeros(4, 2), "reward": torch.full((4, 1), -5.0),
        ...     "done": torch.zeros(4, 1, dtype=torch.bool), "terminated": torch.zeros(4, 1, dtype=torch.bool)}}, [4])
        >>> estimator.value_estimate(estimator(td)).flatten().tolist()  # -5 + 0.9 V(s') clipped to [-1, 0]
        [-1.0, -1.0, -1.0, -1.0]
    """

    def __init__(self, *, low: float | None, high: float | None, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.low, self.high = low, high

    def value_estimate(self, tensordict: TensorDictBase, *args: Any, **kwargs: Any) -> torch.Tensor:
        value = super().value_estimate(tensordict, *args, **kwargs)
        return value if self.low is None and self.high is None else value.clamp(self.low, self.high)


@dataclass(frozen=True)
class TD3Settings:
    """TD3's changes to DDPG (Fujimoto et al. 2018), through TorchRL's :class:`~torchrl.objectives.TD3Loss`:
    two critics whose smaller target value is the TD target, smoothed target actions, delayed actor
    (and target) updates. Defaults: TorchRL's TD3 example.

    Attributes:
        policy_delay: critic updates per actor and target update.
        target_noise: s.d. of the Gaussian noise added to the target policy's action.
        noise_clip: bound of that noise.

    Examples:
        >>> TD3Settings().policy_delay
        2
    """

    policy_delay: int = 2
    target_noise: float = 0.2
    noise_clip: float = 0.5


class DDPGAgent(nn.Module):
    """Actor, critic, their optimisers, target networks, exploration and replay buffer of ``K`` learners.

    One learner is a batch of one. With several (``seeds``), every network is a
    :class:`~torchrl_subgoal.training.stack.LearnerStack` of the learners' own (each
    started from its seed), the normaliser keeps each learner's statistics, the
    replay buffer has a learner dim (:class:`~torchrl_subgoal.training.stack.LearnerReplay`:
    each learner samples its own transitions), and each learner's losses are its own
    means over its own samples: what Adam, the target updates and the exploration do
    is each learner's alone. The acting inputs' first dim is the learners' env batch,
    learner-major.

    Args:
        observation_size: entries of the observation vector.
        action_spec: the env's (unbatched) bounded action spec.
        config: hyper-parameters.
        device: where networks and replay buffer live.

    Keyword Args:
        observation_key: the observation entry the networks read.
        subgoal_states: if positive, actor and critic also read ``"subgoal_index"`` (the abstract
            state ``z`` of the shaping transform, one-hot over this many states), concatenated to the
            normalised observation (:class:`~torchrl_subgoal.training.subgoal_input.SubgoalInput`).
        td3: TD3 instead of DDPG (``config.action_l2`` must then be 0).
        keys: more entries the replay buffer keeps (e.g. what re-shaping a sample reads).
        seeds: one per learner: torch is seeded with it before the learner's actor and critic are built
            (``None``: one learner, built from torch's current state).

    Examples:
        >>> from torchrl.data import Bounded
        >>> from tensordict import TensorDict
        >>> spec = Bounded(-1.0, 1.0, shape=(4,))
        >>> agent = DDPGAgent(25, spec, DDPGConfig(hidden=(32,), batch_size=8))
        >>> data = TensorDict({"observation": torch.randn(16, 25), "action": spec.rand((16,)),
        ...     "next": {"observation": torch.randn(16, 25), "reward": -torch.ones(16, 1),
        ...              "done": torch.zeros(16, 1, dtype=torch.bool),
        ...              "terminated": torch.zeros(16, 1, dtype=torch.bool)}}, [16])
        >>> agent.extend(data)
        >>> sorted(agent.update())
        ['loss_actor', 'loss_value']
        >>> td3 = DDPGAgent(25, spec, DDPGConfig(hidden=(32,), batch_size=8, action_l2=0.0), td3=TD3Settings())
        >>> td3.extend(data)
        >>> sorted(td3.update())
        ['loss_value']
        >>> two = DDPGAgent(25, spec, DDPGConfig(hidden=(32,), batch_size=8), seeds=[0, 1])
        >>> two.extend(data)  # rows 0-7 learner 0's, 8-15 learner 1's
        >>> two.update()["loss_value"].shape  # each learner's loss
        torch.Size([2])
    """

    def __init__(
        self,
        observation_size: int,
        action_spec: Bounded,
        config: DDPGConfig,
        device: str | torch.device = "cpu",
        *,
        observation_key: NestedKey = OBSERVATION,
        subgoal_states: int = 0,
        td3: TD3Settings | None = None,
        keys: Sequence[NestedKey] = (),
        seeds: Sequence[int] | None = None,
    ) -> None:
        super().__init__()
        if td3 is not None and config.action_l2:
            raise ValueError(f"action_l2 ({config.action_l2}) is DDPG's actor penalty; TD3 here has none: set it to 0")
        if td3 is not None and td3.policy_delay < 1:
            raise ValueError(f"policy_delay must be >= 1, got {td3.policy_delay}")
        self.config, self.td3 = config, td3
        self.device = torch.device(device)
        self.observation_key = observation_key
        self.learners = k = len(seeds) if seeds is not None else 1
        action_size = int(action_spec.shape[-1])
        z = [SUBGOAL_INDEX] if subgoal_states else []
        self.keys: tuple[NestedKey, ...] = tuple(
            dict.fromkeys(
                [
                    observation_key,
                    "action",
                    ("next", observation_key),
                    ("next", "reward"),
                    ("next", "done"),
                    ("next", "terminated"),
                    *z,
                    *(("next", key) for key in z),
                    *keys,
                ]
            )
        )
        self.norm = RunningNorm(observation_size, config.norm_eps, config.norm_clip, learners=k)
        normalize = TensorDictModule(self.norm, in_keys=[observation_key], out_keys=[NORMALIZED])
        actors, critics = [], []
        for seed in seeds if seeds is not None else [None]:
            if seed is not None:
                torch.manual_seed(seed)
            actor_net: nn.Module = nn.Sequential(
                mlp(observation_size + subgoal_states, action_size, config.hidden), nn.Tanh()
            )
            actors.append(SubgoalInput(subgoal_states, body=actor_net) if subgoal_states else actor_net)
            critics.append(
                _QNet(mlp(observation_size + action_size + subgoal_states, 1, config.hidden), subgoal_states)
            )
        self.actor = Actor(LearnerStack(actors), in_keys=[NORMALIZED, *z], spec=action_spec)
        self.critic = ValueOperator(LearnerStack(critics), in_keys=[NORMALIZED, "action", *z])
        self.greedy = TensorDictSequential(normalize, self.actor)
        # one module call per step: normaliser, actor network and exploration on the observation
        explore = GaussianOrRandom(action_spec.space.low, action_spec.space.high, config.noise_eps, config.random_eps)
        acting: nn.Module = (
            _Explore(self.norm, self.actor.module, explore)
            if subgoal_states
            else nn.Sequential(self.norm, self.actor.module, explore)
        )
        self.policy = TensorDictModule(acting, in_keys=[observation_key, *z], out_keys=["action"])
        high = 0.0 if config.clip_positive else None
        low = -config.clip_return if config.clip_return is not None else None
        self.loss: DDPGLoss | TD3Loss
        if td3 is None:
            self.loss = DDPGLoss(self.actor, self.critic, delay_actor=True, delay_value=True, reduction="none")
            estimator = ClippedTD0Estimator(
                low=low, high=high, gamma=config.gamma, value_network=self.loss.actor_critic
            )
            # through the property's setter: nn.Module.__setattr__ would register a module assigned
            # to `loss.value_estimator` under that name, and the property would still build its default
            type(self.loss).value_estimator.fset(self.loss, estimator)
            self.loss._forward_value_estimator_keys()
            critic_params = self.loss.value_network_params
        else:
            self.loss = TD3Loss(
                self.actor,
                self.critic,
                action_spec=action_spec,
                num_qvalue_nets=2,
                policy_noise=td3.target_noise,
                noise_clip=td3.noise_clip,
                loss_function="l2",
                delay_actor=True,
                delay_qvalue=True,
                reduction="none",
            )
            estimator = ClippedTD0Estimator(low=low, high=high, gamma=config.gamma, value_network=None)
            estimator.set_keys(value=self.loss.tensor_keys.state_action_value)
            self.loss.make_value_estimator(estimator)
            critic_params = self.loss.qvalue_network_params
        # SoftUpdate initialises the targets and registers itself with the loss; its step goes through
        # TensorDict ``.data`` views (0.3-0.5 ms a call here), so soft_update lerps the loss's own
        # target TensorDictParams in place: the same foreach kernel, bit for bit, a fifth of the time
        self.target_updater = SoftUpdate(self.loss, eps=config.polyak)
        critic_name = "value" if td3 is None else "qvalue"
        self._polyak_names = [(f"target_{n}_network_params", f"{n}_network_params") for n in ("actor", critic_name)]
        self._updates, self._actor_stepped = 0, False
        # fused Adam (one kernel for all of a network's parameters): a third of the default's time on CPU;
        # its state is per element, so each learner's own
        fused = self.device.type in ("cpu", "cuda")
        self.actor_optimizer = torch.optim.Adam(
            self.loss.actor_network_params.values(True, True), lr=config.actor_lr, fused=fused
        )
        self.critic_optimizer = torch.optim.Adam(critic_params.values(True, True), lr=config.critic_lr, fused=fused)
        self.replay = LearnerReplay(k, config.buffer_size, config.batch_size, self.keys, self.device)
        self.to(self.device)

    def extend(self, data: TensorDictBase) -> None:
        """Store a collected batch (first dim the learners' env batch, learner-major; any further dims) and
        add its observations to each learner's normaliser."""
        own = data.select(*self.keys).reshape(self.learners, -1).to(self.device)
        self.norm.update(own[self.observation_key])
        self.replay.extend(own)

    def update(self) -> dict[str, torch.Tensor]:
        """One Adam step of critic and actor on a replay sample; returns each learner's losses (:meth:`update_on`)."""
        return self.update_on(self.replay.sample())

    def update_on(self, batch: TensorDictBase) -> dict[str, torch.Tensor]:
        """One Adam step of critic and actor on ``batch`` (``[K, B]``: learner ``k``'s samples in row ``k``, e.g.
        a replay sample re-shaped); returns each learner's losses (``[K]``, detached).

        DDPG: the critic's loss is :class:`~torchrl.objectives.DDPGLoss`'s (its clipped TD(0)
        target through the target networks). The actor's loss is DDPGLoss's
        ``−mean Q(o, π(o))`` (the critic's parameters detached) plus the L2 penalty
        on the same ``π(o)``, computed here with one actor pass for both.
        TD3: a step of both critics (:class:`~torchrl.objectives.TD3Loss`), and of the actor every
        ``policy_delay`` updates (then ``"loss_actor"`` is returned too).
        """
        k = self.learners
        observation = self.norm(batch[self.observation_key])
        batch.set(NORMALIZED, observation)
        batch.set(("next", NORMALIZED), self.norm(batch["next", self.observation_key]))
        if self.td3 is not None:
            return self._td3_update(batch, self.td3)
        extra = (batch[SUBGOAL_INDEX],) if SUBGOAL_INDEX in self.actor.in_keys else ()
        loss_value = learner_means(self.loss.loss_value(batch)[0], k)
        action = self.actor.module(observation, *extra)
        critic: LearnerStack = self.critic.module
        q = critic.call(critic.params.detach(), observation, action, *extra)
        assert isinstance(q, torch.Tensor)
        loss_actor = -learner_means(q, k)
        if self.config.action_l2:
            loss_actor = loss_actor + self.config.action_l2 * learner_means(action.square(), k)
        # the actor's loss reads the critic through detached parameters and the critic's loss
        # reads no actor parameter: one backward pass gives each optimiser its own gradients
        self.critic_optimizer.zero_grad(set_to_none=True)
        self.actor_optimizer.zero_grad(set_to_none=True)
        (loss_value + loss_actor).sum().backward()
        self.critic_optimizer.step()
        self.actor_optimizer.step()
        return {"loss_value": loss_value.detach(), "loss_actor": loss_actor.detach()}

    def _td3_update(self, batch: TensorDictBase, td3: TD3Settings) -> dict[str, torch.Tensor]:
        assert isinstance(self.loss, TD3Loss)
        k = self.learners
        loss_value = learner_means(self.loss.value_loss(batch)[0], k)
        self.critic_optimizer.zero_grad(set_to_none=True)
        loss_value.sum().backward()
        self.critic_optimizer.step()
        self._updates += 1
        out = {"loss_value": loss_value.detach()}
        if self._updates % td3.policy_delay == 0:
            loss_actor = learner_means(self.loss.actor_loss(batch)[0], k)
            self.actor_optimizer.zero_grad(set_to_none=True)
            loss_actor.sum().backward()
            self.actor_optimizer.step()
            self._actor_stepped = True
            out["loss_actor"] = loss_actor.detach()
        return out

    def soft_update(self) -> None:
        """Move the target networks towards the online ones (Polyak averaging); TD3: only if the actor
        took a step since the last soft update (its targets move with the delayed actor updates)."""
        if self.td3 is not None and not self._actor_stepped:
            return
        self._actor_stepped = False
        with torch.no_grad():
            for target, source in self._polyak_names:
                getattr(self.loss, target).lerp_(getattr(self.loss, source), 1 - self.target_updater.eps)

    def training_state(self) -> dict[str, Any]:
        """Networks, targets, normaliser and optimiser states (not the replay buffer)."""
        modules = {k: v for k, v in self.state_dict().items() if not _alias(k)}
        return {
            "modules": modules,
            "actor_optimizer": self.actor_optimizer.state_dict(),
            "critic_optimizer": self.critic_optimizer.state_dict(),
        }

    def load_training_state(self, state: dict[str, Any]) -> None:
        """Inverse of :meth:`training_state`."""
        try:
            missing, unexpected = self.load_state_dict(
                {k: v for k, v in state["modules"].items() if not _alias(k)}, strict=False
            )
        except (RuntimeError, ValueError) as exc:
            raise ValueError(f"training state does not fit this agent: {exc}") from None
        if unexpected or any(not _alias(k) for k in missing):
            raise ValueError(f"training state does not fit this agent: missing {missing}, unexpected {unexpected}")
        self.actor_optimizer.load_state_dict(state["actor_optimizer"])
        self.critic_optimizer.load_state_dict(state["critic_optimizer"])


def _alias(key: str) -> bool:
    """State-dict entries that are not state of their own: the policies' views of the normaliser and
    actor (saved under ``norm.`` and ``actor.``) and the target estimator's lazily created gamma."""
    return key.startswith(("policy.", "greedy.")) or "_value_estimator." in key


class _QNet(nn.Module):
    """``Q(o, a)`` (or ``Q(o, a, z)``): the MLP over the concatenated observation, action (and one-hot ``z``)."""

    def __init__(self, net: nn.Module, subgoal_states: int = 0) -> None:
        super().__init__()
        self.net = net
        self.subgoal_states = subgoal_states

    def forward(
        self, observation: torch.Tensor, action: torch.Tensor, subgoal_index: torch.Tensor | None = None
    ) -> torch.Tensor:
        if subgoal_index is None:
            return self.net(torch.cat([observation, action], -1))
        z = nn.functional.one_hot(subgoal_index.reshape(action.shape[:-1]).long(), self.subgoal_states)
        return self.net(torch.cat([observation, action, z.to(action.dtype)], -1))


class _Explore(nn.Module):
    """The exploring policy over ``(o, z)``: normaliser, actor network, exploration."""

    def __init__(self, norm: nn.Module, actor: nn.Module, explore: nn.Module) -> None:
        super().__init__()
        self.norm, self.actor, self.explore = norm, actor, explore

    def forward(self, observation: torch.Tensor, subgoal_index: torch.Tensor) -> torch.Tensor:
        return self.explore(self.actor(self.norm(observation), subgoal_index))
