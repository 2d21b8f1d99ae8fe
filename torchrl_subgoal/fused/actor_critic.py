"""One-step actor-critics over a Fourier basis, batched: one critic and actor per learner."""

from __future__ import annotations

import itertools
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal, NamedTuple

import numpy as np
import torch
from tensordict import TensorDictBase
from tensordict.utils import NestedKey

from torchrl_subgoal._kernels.random import AGENT_STREAM, learner_keys, new_streams
from torchrl_subgoal._kernels.steps import implements, learner_scratch, learner_step
from torchrl_subgoal.fused._kernels.actor_critic import (
    _feature_scratch,
    ac_act,
    ac_learner_step,
    ac_step,
    qac_step,
)
from torchrl_subgoal.fused.module import KernelLearner

__all__ = ["AC_PRESETS", "ActorCriticConfig", "ActorCriticKernelState", "FourierActorCritic", "fourier_coefficients"]


@dataclass(frozen=True)
class ActorCriticConfig:
    """Hyper-parameters of the PinBall actor-critic.

    Attributes:
        actor_lr: learning rate of the softmax actor.
        critic_lr: learning rate of the linear critic.
        gamma: discount.
        value_lr: ``α_v`` of the subgoal potential (the shaping methods).
        normalize_lr: divide both learning rates by ``‖φ(s)‖``.
        order: order of the Fourier basis (``(order + 1)^D`` features).
        critic: ``"state"``: a critic ``V(s)`` and an actor step scaled by the
            TD error (the paper's text); ``"action"``: a critic ``Q(s, a)`` per
            action learned by SARSA and an actor step scaled by ``Q(s, a)``
            (the authors' released agent).

    Examples:
        >>> config = ActorCriticConfig(actor_lr=0.01, critic_lr=0.01, gamma=0.99, value_lr=0.1)
        >>> config.order, config.critic, config.normalize_lr
        (3, 'state', False)
    """

    actor_lr: float
    critic_lr: float
    gamma: float
    value_lr: float
    normalize_lr: bool = False
    order: int = 3
    critic: Literal["state", "action"] = "state"


#: ``"paper"``: the paper's text, a TD-error actor-critic with α = 0.01 for
#: actor and critic, γ = 0.99; it gives no α_v, so the released 0.05 is used.
#: ``"released"``: the authors' released agent and configuration, a Q-based
#: actor-critic (``critic="action"``) with α = 0.001 divided by ‖φ(s)‖ and
#: α_v = 0.05. ``"released-td"``: the paper's TD-error actor-critic with the
#: released rates (the two differ by the agent only).
AC_PRESETS: dict[str, ActorCriticConfig] = {
    "paper": ActorCriticConfig(actor_lr=0.01, critic_lr=0.01, gamma=0.99, value_lr=0.05),
    "released": ActorCriticConfig(
        actor_lr=0.001, critic_lr=0.001, gamma=0.99, value_lr=0.05, normalize_lr=True, critic="action"
    ),
    "released-td": ActorCriticConfig(actor_lr=0.001, critic_lr=0.001, gamma=0.99, value_lr=0.05, normalize_lr=True),
}


def fourier_coefficients(order: int, dim: int) -> torch.Tensor:
    """Every ``c ∈ {0..order}^dim`` in lexicographic order, ``[(order+1)^dim, dim]`` (Konidaris et al. 2011).

    Examples:
        >>> fourier_coefficients(1, 2).tolist()
        [[0.0, 0.0], [0.0, 1.0], [1.0, 0.0], [1.0, 1.0]]
        >>> fourier_coefficients(3, 4).shape
        torch.Size([256, 4])
    """
    return torch.tensor(list(itertools.product(range(order + 1), repeat=dim)), dtype=torch.float64)


class ActorCriticKernelState(NamedTuple):
    """A :class:`FourierActorCritic`'s weights, scratch and settings for compiled loops (arrays updated in place).

    Examples:
        >>> agent = FourierActorCritic(2, [0.0] * 4, [1.0] * 4, 5, AC_PRESETS["released"], seed=0)
        >>> state = agent.kernel_state()
        >>> state.w.shape, state.theta.shape, state.q_critic  # the released agent's critic is Q(s, a)
        ((2, 1280), (2, 5, 256), True)
    """

    w: np.ndarray  #: ``[N, F]`` (or ``[N, A·F]`` for the ``"action"`` critic) critic weights
    theta: np.ndarray  #: ``[N, A, F]`` actor weights
    phi: np.ndarray  #: ``[N, F]`` features of each learner's current state
    probs: np.ndarray  #: ``[N, A]`` the policy at that state (scratch for the ``"action"`` critic)
    streams: np.ndarray  #: ``[N, 4]`` uint64 random stream of every learner
    low: np.ndarray  #: ``[D]`` lower bounds of the observation
    inv_range: np.ndarray  #: ``[D]`` ``1 / (high − low)``
    order: int  #: order of the Fourier basis
    half: int  #: dimensions in the first half of the feature product
    actor_lr: float  #: actor learning rate
    critic_lr: float  #: critic learning rate
    gamma: float  #: discount
    normalize: bool  #: divide both rates by ``‖φ(s)‖``
    q_critic: bool  #: the ``"action"`` critic ``Q(s, a)`` (else ``V(s)``)


class FourierActorCritic(KernelLearner):
    """Linear actor-critic with a Fourier basis for a batch of independent learners.

    Features ``φ_c(s) = cos(π c·s̃)`` for every ``c ∈ {0..order}^D`` on the state
    scaled to the unit cube with ``low``/``high`` (256 features for PinBall's
    4-d state at order 3); actor ``π(a|s) ∝ exp(θ_a·φ(s))``. Two critics
    (``config.critic``):

    * ``"state"`` (the paper's text): ``V(s) = w·φ(s)``; each step
      ``δ = r + γ V(s') (1 − terminated) − V(s)``, ``w += α_c δ φ(s)``,
      ``θ += α_a δ ∇ log π(a|s)``; the next action is drawn after the update.
    * ``"action"`` (the authors' released agent): ``Q(s, a) = w_a·φ(s)``; each
      step draws ``a' ~ π(·|s')`` first, then ``θ += α_a Q(s, a) ∇ log π(a|s)``
      and ``w_a += α_c δ φ(s)`` with ``δ = r + γ Q(s', a') (1 − terminated) − Q(s, a)``.

    With ``normalize_lr`` both rates are divided by ``‖φ(s)‖``. Each learner
    draws from its own random stream (Philox keyed by its seed): one uniform
    per step (with the ``"action"`` critic one more for the reset state when
    an episode ends). One fused kernel per step.

    An ``nn.Module``: the critic's weights ``w``, the actor's ``theta``, each
    learner's current features ``phi`` and policy ``probs`` and its random
    ``streams`` are buffers (float64, the streams uint64), so ``state_dict()``
    checkpoints a learner (a reloaded one continues as the original would)
    and ``.to(dtype=...)`` casts the tables; it learns on the CPU (see
    :class:`~torchrl_subgoal.fused.module.KernelLearner`). Calling the module
    is :meth:`act`.

    Args:
        num_learners: learners (env batch size).
        low: lower bounds of the observation entries.
        high: upper bounds.
        num_actions: actions.
        config: learning rates, discount, basis order.
        seed: one seed per learner, or one integer they are derived from, or a
            numpy generator that draws them (as in :class:`SoftmaxSarsa`); each
            learner draws from its own stream.
        observation_key: the observation.

    Examples:
        >>> from torchrl_subgoal.fused import AC_PRESETS, FourierActorCritic, run_episodes
        >>> from torchrl_subgoal.envs import PinBallEnv
        >>> env = PinBallEnv(4, seed=0, max_steps=50)
        >>> spec = env.observation_spec["observation"]
        >>> agent = FourierActorCritic(4, spec.low[0], spec.high[0], 5, AC_PRESETS["released"], seed=0)
        >>> run_episodes(env, agent, 2).steps.shape
        torch.Size([4, 2])
        >>> agent.q_values(env.reset()["observation"]).shape  # the released agent: Q(s, ·)
        torch.Size([4, 5])
        >>> list(agent.state_dict())
        ['w', 'theta', 'phi', 'probs', 'streams']
    """

    w: torch.Tensor
    theta: torch.Tensor
    phi: torch.Tensor
    probs: torch.Tensor
    streams: torch.Tensor

    def __init__(
        self,
        num_learners: int,
        low: Sequence[float] | torch.Tensor,
        high: Sequence[float] | torch.Tensor,
        num_actions: int,
        config: ActorCriticConfig,
        *,
        seed: int | Sequence[int] | np.ndarray | np.random.Generator = 0,
        observation_key: NestedKey = "observation",
    ) -> None:
        super().__init__()
        self.config = config
        self.low = np.asarray(torch.as_tensor(low, dtype=torch.float64))
        high_ = np.asarray(torch.as_tensor(high, dtype=torch.float64))
        if self.low.shape != high_.shape or self.low.ndim != 1 or not (high_ > self.low).all():
            raise ValueError("low and high must be 1-D, the same size, with high > low")
        self.inv_range = 1.0 / (high_ - self.low)
        dim = self.low.shape[0]
        self.half_dim = dim // 2  # not `half`: nn.Module.half() casts to float16
        self.num_features = (config.order + 1) ** dim
        self.num_actions = num_actions
        q_critic = config.critic == "action"
        # the kernels update these in place through numpy views (numpy_view)
        # the Q critic is [B, A·F]: row-major per action, one layout for both critics in the fused kernels
        f64 = torch.float64
        self.register_buffer(
            "w", torch.zeros(num_learners, self.num_features * (num_actions if q_critic else 1), dtype=f64)
        )
        self.register_buffer("theta", torch.zeros(num_learners, num_actions, self.num_features, dtype=f64))
        self.register_buffer("phi", torch.zeros(num_learners, self.num_features, dtype=f64))  # φ of the current state
        self.register_buffer("probs", torch.full((num_learners, num_actions), 1.0 / num_actions, dtype=f64))  # π(·|s)
        streams = new_streams(learner_keys(seed, num_learners), AGENT_STREAM)
        self.register_buffer("streams", torch.from_numpy(streams))
        self.observation_key = observation_key
        self._step_kernel = qac_step if q_critic else ac_step

    def kernel_state(self) -> ActorCriticKernelState:
        """The weights, features, random streams and settings, as a compiled loop reads them (numpy views).

        Examples:
            >>> agent = FourierActorCritic(2, [0.0] * 4, [1.0] * 4, 5, AC_PRESETS["paper"], seed=0)
            >>> state = agent.kernel_state()
            >>> state.w.shape, state.order, state.q_critic
            ((2, 256), 3, False)
        """
        cfg = self.config
        view = self.numpy_view
        return ActorCriticKernelState(
            view("w"),
            view("theta"),
            view("phi"),
            view("probs"),
            view("streams"),
            self.low,
            self.inv_range,
            cfg.order,
            self.half_dim,
            cfg.actor_lr,
            cfg.critic_lr,
            cfg.gamma,
            cfg.normalize_lr,
            cfg.critic == "action",
        )

    def features(self, observation: torch.Tensor) -> torch.Tensor:
        """``φ(s)`` of a batch of observations ``[N, D]`` (the kernel's features, for inspection)."""
        obs = observation.detach().cpu().numpy().astype(np.float64).reshape(-1, self.low.shape[0])
        n = obs.shape[0]
        out = np.empty((n, self.num_features))
        theta = np.zeros((n, 1, self.num_features))
        ac_act(
            theta,
            out,
            np.empty((n, 1)),
            obs,
            self.low,
            self.inv_range,
            self.config.order,
            self.half_dim,
            np.zeros((0, 4), np.uint64),
            np.empty(n, np.int64),
        )
        return torch.from_numpy(out)

    def q_values(self, observation: torch.Tensor) -> torch.Tensor:
        """``Q(s, ·)`` of each learner at its observation ``[N, D]`` (the ``"action"`` critic), ``[N, A]``."""
        if self.config.critic != "action":
            raise ValueError("q_values needs the action-value critic (ActorCriticConfig.critic='action')")
        phi = self.features(observation).numpy()
        w = self.w.cpu().numpy().reshape(self.w.shape[0], self.num_actions, self.num_features)
        return torch.from_numpy(np.einsum("baf,bf->ba", w, phi))

    def _obs(self, tensordict: TensorDictBase) -> np.ndarray:
        return tensordict.get(self.observation_key).numpy().astype(np.float64).reshape(self.w.shape[0], -1)

    def act(self, tensordict: TensorDictBase) -> TensorDictBase:
        """Write ``"action"`` ``~ π(·|s)`` for every learner (the first step); keeps ``φ(s)`` and ``π(·|s)``."""
        n = self.w.shape[0]
        action = np.empty(n, np.int64)
        view = self.numpy_view
        ac_act(
            view("theta"),
            view("phi"),
            view("probs"),
            self._obs(tensordict),
            self.low,
            self.inv_range,
            self.config.order,
            self.half_dim,
            view("streams"),
            action,
        )
        tensordict.set("action", torch.from_numpy(action))
        return tensordict

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        """Same as :meth:`act`."""
        return self.act(tensordict)

    def step(self, transition: TensorDictBase, next_root: TensorDictBase) -> None:
        """Learn from ``transition`` and write the next ``"action"`` to ``next_root`` (one fused kernel)."""
        cfg = self.config
        view = self.numpy_view
        nxt = transition.get("next")
        n = self.w.shape[0]
        action = np.empty(n, np.int64)
        self._step_kernel(
            view("w"),
            view("theta"),
            view("phi"),
            view("probs"),
            transition.get("action").numpy().reshape(n),
            nxt.get("reward").numpy().reshape(n),
            self._obs(nxt),
            nxt.get("terminated").numpy().reshape(n),
            nxt.get("done").numpy().reshape(n),
            self._obs(next_root),
            self.low,
            self.inv_range,
            cfg.order,
            self.half_dim,
            view("streams"),
            cfg.actor_lr,
            cfg.critic_lr,
            cfg.gamma,
            cfg.normalize_lr,
            action,
        )
        next_root.set("action", torch.from_numpy(action))


# The fused engine's learner step (torchrl_subgoal.fused._kernels.engine.fused_run): features of the observation array.


@implements(learner_scratch, ActorCriticKernelState)
def _ac_scratch(learner: ActorCriticKernelState) -> tuple[tuple[np.ndarray, ...], np.ndarray]:
    return _feature_scratch(learner.order, learner.half, learner.low.shape[0], learner.theta.shape[2])


@implements(learner_step, ActorCriticKernelState)
def _ac_fused_step(
    learner: ActorCriticKernelState,
    b: int,
    o: np.ndarray,
    z: int,
    a: int,
    reward: float,
    o_next: np.ndarray,
    z_next: int,
    terminated: bool,
    done: bool,
    o_root: np.ndarray,
    z_root: int,
    scratch: tuple[tuple[np.ndarray, ...], np.ndarray],
) -> int:
    features, phi_next = scratch
    return ac_learner_step(learner, b, a, reward, o_next, terminated, done, o_root, features, phi_next)
