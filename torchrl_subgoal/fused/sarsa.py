"""Tabular SARSA with a softmax policy, batched: one Q table per learner."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np
import torch
from tensordict import TensorDictBase
from tensordict.utils import NestedKey

from torchrl_subgoal._kernels.random import AGENT_STREAM, learner_keys, new_streams
from torchrl_subgoal._kernels.steps import implements, learner_scratch, learner_step
from torchrl_subgoal.fused._kernels.sarsa import sarsa_learner_step, sarsa_step, softmax_sample
from torchrl_subgoal.fused.module import KernelLearner

__all__ = ["SARSA_PRESETS", "SarsaConfig", "SarsaKernelState", "SoftmaxSarsa"]


@dataclass(frozen=True)
class SarsaConfig:
    """Hyper-parameters of SARSA on four-rooms.

    Attributes:
        lr: learning rate ``α`` of the Q table.
        gamma: discount ``γ``.
        temperature: softmax temperature ``τ`` (``π(a|s) ∝ exp(Q(s,a)/τ)``).
        value_lr: learning rate ``α_v`` of the subgoal potential.

    Examples:
        >>> SarsaConfig(lr=0.1, gamma=0.99, temperature=0.1, value_lr=0.1).temperature
        0.1
    """

    lr: float
    gamma: float
    temperature: float
    value_lr: float


#: ``"paper"``: the values stated in the paper's text (α = 0.01, γ = 0.99); the
#: text gives no temperature or ``α_v``, so those follow the authors' code,
#: where the potential shares the agent's learning rate and τ = 0.01.
#: ``"released"``: the authors' released configuration (α = α_v = 0.25,
#: τ = 0.01, γ = 0.99). See facts.md / the four-rooms docs for the comparison.
SARSA_PRESETS: dict[str, SarsaConfig] = {
    "paper": SarsaConfig(lr=0.01, gamma=0.99, temperature=0.01, value_lr=0.01),
    "released": SarsaConfig(lr=0.25, gamma=0.99, temperature=0.01, value_lr=0.25),
}


class SarsaKernelState(NamedTuple):
    """A :class:`SoftmaxSarsa`'s tables and settings for compiled loops (arrays are views, updated in place).

    Examples:
        >>> agent = SoftmaxSarsa(2, 104, 4, SARSA_PRESETS["released"], seed=0, abstract_states=3)
        >>> state = agent.kernel_state()
        >>> state.q.shape, state.streams.shape, state.abstract_states
        ((2, 312, 4), (2, 4), 3)
    """

    q: np.ndarray  #: ``[N, S·Z, A]`` float32 Q table of every learner (a view of :attr:`SoftmaxSarsa.q`)
    streams: np.ndarray  #: ``[N, 4]`` uint64 random stream of every learner
    abstract_states: int  #: ``Z``: rows are ``s · Z + z`` when > 1
    lr: float  #: ``α``
    gamma: float  #: ``γ``
    inv_temperature: float  #: ``1 / τ``


class SoftmaxSarsa(KernelLearner):
    """SARSA(0) with a softmax (Boltzmann) policy for a batch of independent learners.

    Learner ``b`` owns ``Q[b]`` of shape ``[num_states, num_actions]``; the env
    batch (flattened) is the learner batch. Actions are drawn from
    ``softmax(Q/τ)`` with uniforms from each learner's own random stream
    (Philox keyed by its seed), so a learner's behaviour depends on its seed
    only, not on the batch it runs in (one fused kernel per step draws, updates
    and draws again). The update is
    ``Q(s,a) ← Q(s,a) + α (r + γ Q(s',a') (1 − terminated) − Q(s,a))`` with
    ``a' ~ π(·|s')``; at truncation it bootstraps from ``Q(s', a')``.

    An ``nn.Module``: the table ``q`` and the random ``streams`` are buffers,
    so ``state_dict()`` checkpoints a learner (a reloaded one continues as the
    original would) and ``.to(dtype=...)`` casts the table; it learns on the
    CPU (see :class:`~torchrl_subgoal.fused.module.KernelLearner`). Calling
    the module is :meth:`act`.

    Args:
        num_learners: learners (env batch size).
        num_states: discrete states (observation values).
        num_actions: actions.
        config: learning rate, discount, temperature.
        seed: one seed per learner (a sequence), or one integer from which
            learner ``b``'s seed is derived (see
            :func:`~torchrl_subgoal._kernels.random.learner_keys`), or a numpy
            generator that draws them. Learner ``b`` draws from its own stream.
        observation_key: the discrete observation.
        abstract_states: if > 1, the table is over ``(s, z)`` pairs, with ``z``
            read from ``abstract_key`` (the shaping transform's subgoal index).
            A history-dependent potential ``Φ(z)`` is then a function of the
            agent's state, which is what potential-based shaping needs to leave
            the optimal policy unchanged. With ``Q(s)`` alone (the paper's agent)
            there is no such guarantee; in four-rooms its greedy policy cycled
            across subgoals only with ``Φ = V`` and a zeroed terminal potential
            (docs/four_rooms.md, docs/shaping_defaults.md).
        abstract_key: where ``z`` is read.

    Examples:
        >>> import torch
        >>> from torchrl_subgoal.fused import SoftmaxSarsa, SARSA_PRESETS
        >>> from torchrl_subgoal.fused.loop import run_episodes
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> env = FourRoomsEnv(num_envs=8)
        >>> agent = SoftmaxSarsa(8, env.num_states, 4, SARSA_PRESETS["released"], seed=0)
        >>> records = run_episodes(env, agent, episodes=3)
        >>> records.steps.shape
        torch.Size([8, 3])
        >>> sorted(agent.state_dict())  # the table and each learner's random stream
        ['q', 'streams']
    """

    q: torch.Tensor
    streams: torch.Tensor
    _rows: torch.Tensor

    def __init__(
        self,
        num_learners: int,
        num_states: int,
        num_actions: int,
        config: SarsaConfig,
        *,
        seed: int | Sequence[int] | np.ndarray | np.random.Generator = 0,
        observation_key: NestedKey = "observation",
        abstract_states: int = 1,
        abstract_key: NestedKey = "subgoal_index",
    ) -> None:
        super().__init__()
        self.config = config
        self.num_actions = num_actions
        self.abstract_states = abstract_states
        self.abstract_key = abstract_key
        self.num_states = num_states * abstract_states
        # the kernels update both in place through numpy views (numpy_view)
        self.register_buffer("q", torch.zeros(num_learners, self.num_states, num_actions))
        streams = new_streams(learner_keys(seed, num_learners), AGENT_STREAM)
        self.register_buffer("streams", torch.from_numpy(streams))
        self.observation_key = observation_key
        self.register_buffer("_rows", torch.arange(num_learners), persistent=False)

    def kernel_state(self) -> SarsaKernelState:
        """The table, the random streams and the settings, as a compiled loop reads them (numpy views).

        Examples:
            >>> agent = SoftmaxSarsa(2, 5, 4, SARSA_PRESETS["released"], seed=0)
            >>> agent.kernel_state().q[0, 1, 2] = 1.0  # a view: the agent's table changes
            >>> float(agent.q[0, 1, 2])
            1.0
        """
        cfg = self.config
        return SarsaKernelState(
            self.numpy_view("q"),
            self.numpy_view("streams"),
            self.abstract_states,
            cfg.lr,
            cfg.gamma,
            1.0 / cfg.temperature,
        )

    def sample(self, state: torch.Tensor) -> torch.Tensor:
        """Softmax actions for each learner's table row ``[N]`` (see :meth:`state`)."""
        s = state.numpy().reshape(-1)
        action = torch.empty_like(state)
        softmax_sample(
            self.numpy_view("q"),
            s,
            1.0 / self.config.temperature,
            self.numpy_view("streams"),
            action.numpy().reshape(-1),
        )
        return action

    def greedy(self, state: torch.Tensor) -> torch.Tensor:
        """Greedy actions ``argmax_a Q(s, a)`` for each learner."""
        return self.q[self._rows, state].argmax(-1)

    def state(self, tensordict: TensorDictBase) -> torch.Tensor:
        """The table row of each learner: ``s``, or ``s · Z + z`` over ``(s, z)`` pairs."""
        s = tensordict.get(self.observation_key)
        if self.abstract_states == 1:
            return s
        return s.reshape(-1) * self.abstract_states + tensordict.get(self.abstract_key).reshape(-1)

    def act(self, tensordict: TensorDictBase) -> TensorDictBase:
        """Write a softmax ``"action"`` for every learner of ``tensordict`` (the first step)."""
        shape = tensordict.get(self.observation_key).shape
        tensordict.set("action", self.sample(self.state(tensordict)).reshape(shape))
        return tensordict

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        """Same as :meth:`act`."""
        return self.act(tensordict)

    def step(self, transition: TensorDictBase, next_root: TensorDictBase) -> None:
        """Learn from ``transition`` and write the next ``"action"`` to ``next_root`` (one fused kernel)."""
        cfg = self.config
        nxt = transition.get("next")
        n = self.q.shape[0]
        action = torch.empty(n, dtype=torch.long)
        sarsa_step(
            self.numpy_view("q"),
            _flat(self.state(transition)),
            _flat(transition.get("action")),
            _flat(nxt.get("reward")),
            _flat(self.state(nxt)),
            _flat(nxt.get("terminated")),
            _flat(nxt.get("done")),
            _flat(self.state(next_root)),
            self.numpy_view("streams"),
            cfg.lr,
            cfg.gamma,
            1.0 / cfg.temperature,
            action.numpy(),
        )
        next_root.set("action", action.view(transition.get("action").shape))


def _flat(t: torch.Tensor) -> np.ndarray:
    """A CPU tensor as a 1-D numpy array (a view when contiguous)."""
    return t.numpy().reshape(-1)


# The fused engine's learner step (torchrl_subgoal.fused._kernels.engine.fused_run): a row per state and abstract state.


@implements(learner_scratch, SarsaKernelState)
def _sarsa_scratch(learner: SarsaKernelState) -> np.ndarray:
    return np.empty(learner.q.shape[2])


@implements(learner_step, SarsaKernelState)
def _sarsa_fused_step(
    learner: SarsaKernelState,
    b: int,
    o: int,
    z: int,
    a: int,
    reward: float,
    o_next: int,
    z_next: int,
    terminated: bool,
    done: bool,
    o_root: int,
    z_root: int,
    scratch: np.ndarray,
) -> int:
    return sarsa_learner_step(learner, b, o, z, a, reward, o_next, z_next, terminated, done, o_root, z_root, scratch)
