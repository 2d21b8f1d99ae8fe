"""SubgoalPotentialTransform: potential-based shaping over a dynamic trajectory aggregation."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np
import torch
from tensordict import TensorDict, TensorDictBase
from tensordict.utils import NestedKey
from torchrl.data import Binary, Bounded, Composite, OneHot, TensorSpec, Unbounded
from torchrl.envs.transforms import Transform

from torchrl_subgoal import _kernels
from torchrl_subgoal.loss import SubgoalValueLoss
from torchrl_subgoal.potentials import (
    ACHIEVED,
    ANCHOR,
    INDEX,
    NaivePotential,
    Potential,
    TabularPotential,
)
from torchrl_subgoal.subgoals import StateAggregation, SubgoalSeries, SubgoalTables

__all__ = ["SubgoalPotentialTransform"]

RETURN = "subgoal_return"
STEPS = "subgoal_steps"


class SubgoalPotentialTransform(Transform):
    """Adds the shaping reward ``F = γ Φ(z') − Φ(z)`` of a subgoal series to any TorchRL env.

    The transform keeps, per env of the batch, the abstract state of dynamic
    trajectory aggregation (Okudo & Yamada 2021) in the TensorDict:

    * ``"subgoal_index"`` ``z`` — the node of the subgoal series reached
      (``0`` at reset; advanced when the next subgoal's predicate holds);
    * ``"subgoal_achieved"`` — ``z`` was entered on this step (only when the
      potential reads it, e.g. :class:`~torchrl_subgoal.NaivePotential`);
    * ``"subgoal_return"`` ``r_h ← r_h + γ_v^k r`` and ``"subgoal_steps"``
      ``k ← k + 1`` since ``z`` was entered;
    * ``"subgoal_anchor"`` — the observation at which ``z`` was entered (only
      when the potential reads it, e.g. :class:`~torchrl_subgoal.NeuralPotential`).

    Every step it adds ``F`` to the reward; the environment's reward stays
    under ``"env_reward"``, declared as a second reward entry (so use
    ``env.reward_keys``: ``env.reward_key`` expects a single one). When a
    subgoal is achieved or the episode ends it writes one SMDP transition
    ``(z, r_h, k, z', terminated)`` under ``("next", "smdp")`` in the layout
    :class:`~torchrl_subgoal.SubgoalValueLoss` and TorchRL's TD(0) estimator
    read (``mask`` tells which entries are real). At truncation the transition
    bootstraps from ``V(z')``.

    The potential is used *as it is now* (a dynamic potential). With
    ``value_lr`` set, the transform also trains the potential online by SGD on
    :class:`~torchrl_subgoal.SubgoalValueLoss` before computing ``F``, which
    is the paper's algorithm (update ``V``, then shape with it); otherwise train
    it yourself from ``data["next", "smdp"]`` with the same loss. Freeze a
    trained potential with ``transform.potential.requires_grad_(False)``.

    Policy invariance (Ng et al. 1999) needs ``Φ`` to be a function of the
    *agent's* state. ``z`` depends on the episode's history, so an agent that
    sees only ``s`` (as in the paper) may learn a greedy policy that cycles
    across a subgoal; give the agent ``z`` too (e.g. ``SoftmaxSarsa(...,
    abstract_states=n)``) for the exact guarantee once ``Φ`` is fixed.

    A NaN or infinite reward, or a NaN in the observation, raises ``ValueError``
    naming the entry and the env (it would make the potential NaN for good);
    ``±inf`` in an observation compares as a number. Both the compiled and the
    torch path behave so.

    Append it to the *outer* env (``TransformedEnv(ParallelEnv(...), t)``) so
    that the potential being trained is the one used for shaping.

    Args:
        subgoals: a :class:`SubgoalSeries` shared by every env of the batch; a
            sequence of series, one per env (flattened batch order) or indexed
            by ``pattern_index``; or a :class:`StateAggregation` ``z = g(s)``
            (the SARSA-RS baseline).
        potential: ``Φ`` — :class:`TabularPotential`, :class:`NeuralPotential`
            or :class:`NaivePotential`.

    Keyword Args:
        gamma: the agent's discount ``γ`` in ``F = γ Φ(z') − Φ(z)``.
        observation_key: the observation the predicates read.
        reward_key: the reward to shape.
        pattern_index: with a sequence of series, the pattern of each env
            (shape of the env batch).
        value_lr: if set, learning rate ``α_v`` of the online SGD update of the
            potential (the paper's tabular update).
        value_gamma: ``γ_v`` of the abstract value function and of ``r_h``;
            defaults to ``gamma``.
        zero_terminal_potential: ``Φ = 0`` at terminal states, which keeps the
            optimal policy exactly invariant in episodic tasks (Grzes 2017).
            Defaults to ``True``; ``False`` shapes with ``V(z')`` at the goal
            as the authors' released code does.
        env_reward_key: where the unshaped reward is kept.
        transitions_key: where the SMDP transitions are written in ``"next"``.
        write_transitions: whether to write them. Defaults to ``True`` when
            you train the potential yourself (``value_lr=None``) and ``False``
            when the transform trains it online, where nothing else needs them
            (skipping them saves a nested TensorDict per step).

    Examples:
        >>> import torch
        >>> from torchrl.envs import TransformedEnv
        >>> from torchrl_subgoal import SubgoalPotentialTransform, SubgoalSeries, TabularPotential
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> from torchrl_subgoal.subgoals import Cell
        >>> base = FourRoomsEnv(num_envs=4)
        >>> series = SubgoalSeries([Cell(3, 6), Cell(7, 9)])
        >>> potential = TabularPotential(series.num_abstract_states, batch_shape=base.batch_size)
        >>> env = TransformedEnv(base, SubgoalPotentialTransform(
        ...     series, potential, gamma=0.99, observation_key="cell", value_lr=0.25))
        >>> data = env.rollout(5)
        >>> data["next", "subgoal_index"].shape
        torch.Size([4, 5, 1])
        >>> data["next", "subgoal_steps"][0, :, 0].tolist()  # k: steps since z was entered
        [1, 2, 3, 4, 5]
    """

    def __init__(
        self,
        subgoals: SubgoalSeries | Sequence[SubgoalSeries] | StateAggregation,
        potential: Potential,
        *,
        gamma: float,
        observation_key: NestedKey = "observation",
        reward_key: NestedKey = "reward",
        pattern_index: torch.Tensor | None = None,
        value_lr: float | None = None,
        value_gamma: float | None = None,
        zero_terminal_potential: bool = True,
        env_reward_key: NestedKey = "env_reward",
        transitions_key: NestedKey = "smdp",
        write_transitions: bool | None = None,
    ) -> None:
        super().__init__(in_keys=[observation_key, reward_key], out_keys=[reward_key, env_reward_key])
        if not 0.0 <= gamma <= 1.0:
            raise ValueError(f"gamma must lie in [0, 1], got {gamma}")
        value_gamma = gamma if value_gamma is None else value_gamma
        if not 0.0 <= value_gamma <= 1.0:
            raise ValueError(f"value_gamma must lie in [0, 1], got {value_gamma}")
        if value_lr is not None and not value_lr > 0:
            raise ValueError(f"value_lr must be positive, got {value_lr}")
        if isinstance(subgoals, SubgoalSeries):
            patterns: list[SubgoalSeries] | None = [subgoals]
            self.aggregation: StateAggregation | None = None
        elif isinstance(subgoals, StateAggregation):
            patterns, self.aggregation = None, subgoals
        else:
            patterns, self.aggregation = list(subgoals), None
            if not patterns or not all(isinstance(p, SubgoalSeries) for p in patterns):
                raise TypeError("subgoals must be a SubgoalSeries, a sequence of them or a StateAggregation")
        if pattern_index is not None and patterns is None:
            raise ValueError("pattern_index needs a sequence of subgoal series")
        self.patterns = patterns
        self.pattern_index = pattern_index
        self.potential = potential
        self.gamma = float(gamma)
        self.value_gamma = float(value_gamma)
        self.observation_key = observation_key
        self.reward_key = reward_key
        self.env_reward_key = env_reward_key
        if write_transitions is None:
            write_transitions = value_lr is None
        self.transitions_key: NestedKey | None = transitions_key if write_transitions else None
        self.zero_terminal_potential = zero_terminal_potential
        extra = tuple(k for k in (ACHIEVED, ANCHOR) if k in potential.in_keys)
        self._state_keys: tuple[str, ...] = (INDEX, RETURN, STEPS, *extra)
        self._parameters_list = list(potential.parameters())
        self.value_loss: SubgoalValueLoss | None = None
        self.value_optimizer: torch.optim.Optimizer | None = None
        if value_lr is not None:
            self.value_loss = SubgoalValueLoss(potential, gamma=self.value_gamma)
            self.value_optimizer = torch.optim.SGD(potential.parameters(), lr=value_lr)
        self._value_lr = float(value_lr) if value_lr is not None else 0.0
        self._has_value_lr = value_lr is not None
        self._abstraction: SubgoalTables | StateAggregation | None = None
        self._fused_potential = self._fused_constants()
        # plain references for the hot path (module attributes go through nn.Module.__getattr__)
        self._table: torch.Tensor | None = potential.table if isinstance(potential, TabularPotential) else None
        self._table_ptr = self._table.data_ptr() if self._table is not None else 0
        self._in_keys = potential.in_keys

    # ------------------------------------------------------------------ set-up

    @property
    def learning(self) -> bool:
        """Whether the potential is trained online: ``value_lr`` was given and it is not frozen.

        Freeze it the usual torch way, ``transform.potential.requires_grad_(False)``.
        """
        return self._has_value_lr and any(p.requires_grad for p in self._parameters_list)

    @property
    def num_abstract_states(self) -> int:
        """Number of abstract states ``z`` (the terminal one excluded)."""
        if self.aggregation is not None:
            return self.aggregation.num_states
        assert self.patterns is not None
        return max(len(p) for p in self.patterns) + 1

    def _observation_layout(self, observation_spec: TensorSpec | None, obs: torch.Tensor | None,
                            batch_shape: torch.Size) -> tuple[int, bool]:
        """(entries per observation, one-hot?) from the spec, else from a tensor."""
        if observation_spec is not None:
            shape = observation_spec.shape[len(batch_shape):]
            return (int(shape.numel()) if len(shape) else 1), isinstance(observation_spec, OneHot)
        assert obs is not None
        shape = obs.shape[len(batch_shape):]
        return (int(shape.numel()) if len(shape) else 1), False

    def _setup(self, batch_shape: torch.Size, obs: torch.Tensor) -> SubgoalTables | StateAggregation:
        """Compile the subgoal tables for this batch (once) and check the potential fits."""
        if self._abstraction is not None:
            return self._abstraction
        self._check_potential(batch_shape)
        if self.aggregation is not None:
            self._abstraction = self.aggregation
            return self._abstraction
        spec = None
        parent = self.parent
        if parent is not None:
            obs_spec = parent.full_observation_spec
            if self.observation_key not in obs_spec.keys(True, True):
                raise KeyError(
                    f"{type(self).__name__}: observation_key {self.observation_key!r} is not an "
                    f"observation of the env; available: {sorted(map(str, obs_spec.keys(True, True)))}"
                )
            spec = obs_spec[self.observation_key]
        size, one_hot = self._observation_layout(spec, obs, batch_shape)
        assert self.patterns is not None
        n = batch_shape.numel()
        if self.pattern_index is not None:
            index = self.pattern_index.long().reshape(batch_shape) if self.pattern_index.numel() == n else None
            if index is None:
                raise ValueError(f"pattern_index has {self.pattern_index.numel()} entries for {n} envs")
            if int(index.min()) < 0 or int(index.max()) >= len(self.patterns):
                raise ValueError(f"pattern_index values must lie in [0, {len(self.patterns)})")
        elif len(self.patterns) == 1:
            index = torch.zeros(batch_shape, dtype=torch.long)
        elif len(self.patterns) == n:
            index = torch.arange(n).reshape(batch_shape)
        else:
            raise ValueError(
                f"{len(self.patterns)} subgoal series for a batch of {n} envs: give one series, "
                "one per env, or pattern_index"
            )
        self._abstraction = SubgoalTables(
            self.patterns, index, size, one_hot=one_hot, observation_key=str(self.observation_key)
        )
        return self._abstraction

    def _check_potential(self, batch_shape: torch.Size) -> None:
        pot = self.potential
        if isinstance(pot, TabularPotential):
            if pot.batch_shape and pot.batch_shape != batch_shape:
                raise ValueError(
                    f"TabularPotential has batch_shape {tuple(pot.batch_shape)} but the env batch is "
                    f"{tuple(batch_shape)}: use one table per env or a shared one (batch_shape=())"
                )
            if pot.num_states < self.num_abstract_states:
                raise ValueError(
                    f"TabularPotential has {pot.num_states} states; the abstraction has "
                    f"{self.num_abstract_states}"
                )

    # ------------------------------------------------------------------ specs

    @property
    def state_keys(self) -> tuple[str, ...]:
        """Abstract-state entries kept in the TensorDict (``"subgoal_*"``)."""
        return self._state_keys

    def _state_specs(self, batch_shape: torch.Size, anchor_size: int) -> dict[str, TensorSpec]:
        shape = (*batch_shape, 1)
        specs: dict[str, TensorSpec] = {
            INDEX: Bounded(0, self.num_abstract_states - 1, shape=shape, dtype=torch.long),
            RETURN: Unbounded(shape=shape, dtype=torch.float32),
            STEPS: Unbounded(shape=shape, dtype=torch.long),
            ACHIEVED: Binary(n=1, shape=shape, dtype=torch.bool),
            ANCHOR: Unbounded(shape=(*batch_shape, anchor_size), dtype=torch.float32),
        }
        return {k: specs[k] for k in self.state_keys}

    def _anchor_size(self, observation_spec: Composite) -> int:
        if self.observation_key not in observation_spec.keys(True, True):
            raise KeyError(
                f"{type(self).__name__}: observation_key {self.observation_key!r} is not an observation "
                f"of the env; available: {sorted(map(str, observation_spec.keys(True, True)))}"
            )
        size, _ = self._observation_layout(
            observation_spec[self.observation_key], None, observation_spec.shape
        )
        return size

    def transform_observation_spec(self, observation_spec: TensorSpec) -> TensorSpec:
        assert isinstance(observation_spec, Composite)
        batch_shape = observation_spec.shape
        states = self._state_specs(batch_shape, self._anchor_size(observation_spec))
        for key, spec in states.items():
            observation_spec[key] = spec
        if self.transitions_key is not None:
            observation_spec[self.transitions_key] = self._transition_spec(states, batch_shape)
        return observation_spec

    def transform_reward_spec(self, reward_spec: TensorSpec) -> TensorSpec:
        # The unshaped reward is a second reward entry (as RNDTransform's intrinsic
        # reward): it lives in "next" only, so it costs nothing in step_mdp and resets.
        assert isinstance(reward_spec, Composite)
        if self.reward_key not in reward_spec.keys(True, True):
            raise KeyError(
                f"{type(self).__name__}: reward_key {self.reward_key!r} is not a reward of the env; "
                f"available: {sorted(map(str, reward_spec.keys(True, True)))}"
            )
        reward_spec[self.env_reward_key] = reward_spec[self.reward_key].clone()
        return reward_spec

    def _transition_spec(self, states: dict[str, TensorSpec], batch_shape: torch.Size) -> Composite:
        shape = (*batch_shape, 1)
        inputs = {k: states[k] for k in self.potential.in_keys}
        flag = Binary(n=1, shape=shape, dtype=torch.bool)
        nxt = Composite(
            **{k: s.clone() for k, s in inputs.items()},
            reward=Unbounded(shape=shape, dtype=torch.float32),
            done=flag.clone(),
            terminated=flag.clone(),
            shape=batch_shape,
        )
        return Composite(
            **{k: s.clone() for k, s in inputs.items()},
            steps_to_next_obs=Unbounded(shape=shape, dtype=torch.long),
            mask=flag.clone(),
            next=nxt,
            shape=batch_shape,
        )

    # ------------------------------------------------------------------ reset and step

    def _flat_obs(self, obs: torch.Tensor, batch_shape: torch.Size) -> torch.Tensor:
        return obs.reshape(*batch_shape, -1).to(torch.float32)

    def _initial_state(self, obs: torch.Tensor, batch_shape: torch.Size) -> dict[str, torch.Tensor]:
        abstraction = self._setup(batch_shape, obs)
        shape = (*batch_shape, 1)
        state = {
            INDEX: abstraction.initial(obs, batch_shape),
            RETURN: torch.zeros(shape),
            STEPS: torch.zeros(shape, dtype=torch.long),
            ACHIEVED: torch.zeros(shape, dtype=torch.bool),
        }
        if ANCHOR in self.state_keys:
            state[ANCHOR] = self._flat_obs(obs, batch_shape)
        return {k: state[k] for k in self.state_keys}

    def _reset(self, tensordict: TensorDictBase, tensordict_reset: TensorDictBase) -> TensorDictBase:
        # Values for every env; TorchRL keeps the old ones where "_reset" is False.
        batch_shape = tensordict_reset.batch_size
        state = self._initial_state(tensordict_reset.get(self.observation_key), batch_shape)
        outputs: dict[str, Any] = dict(state)
        if self.transitions_key is not None:
            zero = torch.zeros((*batch_shape, 1))
            false = torch.zeros((*batch_shape, 1), dtype=torch.bool)
            inputs = {k: state[k] for k in self.potential.in_keys}
            outputs[self.transitions_key] = _transition(
                batch_shape, inputs, inputs, zero, state[STEPS], false, false, false
            )
        _write(tensordict_reset, outputs)
        return tensordict_reset

    def _step(self, tensordict: TensorDictBase, next_tensordict: TensorDictBase) -> TensorDictBase:
        batch_shape = next_tensordict.batch_size
        obs = next_tensordict.get(self.observation_key)
        done = next_tensordict.get("done")
        current = {k: tensordict.get(k) for k in self.state_keys}
        out = self.shape(
            self._setup(batch_shape, obs),
            current,
            obs,
            next_tensordict.get(self.reward_key),
            done,
            next_tensordict.get("terminated", done),
            batch_shape,
        )
        _write(next_tensordict, out)
        return next_tensordict

    def shape(
        self,
        abstraction: SubgoalTables | StateAggregation,
        current: dict[str, torch.Tensor],
        obs: torch.Tensor,
        reward: torch.Tensor,
        done: torch.Tensor,
        terminated: torch.Tensor,
        batch_shape: torch.Size,
    ) -> dict[str, Any]:
        """One step of aggregation and shaping; returns the entries of the next TensorDict.

        Raises:
            ValueError: a reward is NaN or infinite, or the observation holds a NaN
                (either would make the potential NaN for good); nothing is updated.
        """
        _check_finite(reward, obs, self.reward_key, self.observation_key)
        if self._fused_potential is not None and obs.device.type == "cpu":
            return self._shape_fused(abstraction, current, obs, reward, done, terminated, batch_shape)
        z_next = abstraction.advance(current[INDEX], obs)
        return self._shape_eager(current, z_next, obs, reward, done, terminated, batch_shape)

    def _fused_constants(self) -> tuple[np.ndarray, bool, float] | None:
        """The potential as the fused kernel reads it, or ``None`` if it cannot (neural, not CPU)."""
        pot = self.potential
        if isinstance(pot, NaivePotential):
            return _NO_TABLE, False, pot.eta
        if isinstance(pot, TabularPotential) and pot.table.device.type == "cpu":
            table = pot.table.detach().numpy().reshape(-1, pot.num_states)
            return table, table.shape[0] == 1 and not pot.batch_shape, 0.0
        return None

    def _shape_fused(
        self,
        abstraction: SubgoalTables | StateAggregation,
        current: dict[str, torch.Tensor],
        obs: torch.Tensor,
        reward: torch.Tensor,
        done: torch.Tensor,
        terminated: torch.Tensor,
        batch_shape: torch.Size,
    ) -> dict[str, Any]:
        assert self._fused_potential is not None
        table, shared, eta = self._fused_potential
        if self._table is not None and self._table.data_ptr() != self._table_ptr:
            self._fused_potential = self._fused_constants()  # the table was replaced (e.g. moved)
            self._table_ptr = self._table.data_ptr()
            assert self._fused_potential is not None
            table, shared, eta = self._fused_potential
        z, r_h, k = current[INDEX], current[RETURN], current[STEPS]
        key = self.transitions_key
        z_next, rh_out, k_out, shaped = _empty_like(z), _empty_like(r_h), _empty_like(k), _empty_like(reward)
        extra: tuple[np.ndarray, ...]
        if key is not None:  # the kernel also fills the SMDP transition's r_h, k and mask
            rh_acc, k_acc, emit = _empty_like(r_h), _empty_like(k), _empty_like(done)
            extra = (rh_acc[1], k_acc[1], emit[1])
        else:
            extra = _NO_TRANSITION
        lr = self._value_lr if self.learning else 0.0
        shaping = (_col(current.get(ACHIEVED, z)), _col(r_h), _col(k), _col(reward), _col(done), _col(terminated),
                   table, shared, eta, self.gamma, self.value_gamma, lr, self.zero_terminal_potential)
        if isinstance(abstraction, SubgoalTables):
            t = abstraction._np
            _kernels.advance_and_shape(
                _col(z), obs.numpy().reshape(z_next[1].shape[0], -1), t["pattern"], t["lo"], t["hi"], t["centre"],
                t["weight"],
                t["radius2"], t["succ"], *shaping, z_next[1], rh_out[1], k_out[1], shaped[1], *extra,
            )
        else:
            z_next = (abstraction.advance(z, obs), np.empty(0))
            _kernels.shape_step(_col(z), _col(z_next[0]), *shaping, rh_out[1], k_out[1], shaped[1], *extra)
        out: dict[str, Any] = {
            INDEX: z_next[0], RETURN: rh_out[0], STEPS: k_out[0],
            self.env_reward_key: reward, self.reward_key: shaped[0],
        }
        if ACHIEVED in self._state_keys:
            out[ACHIEVED] = z_next[0] != z
        if key is not None:
            inputs = {name: current[name] for name in self._in_keys}
            next_inputs = {name: out[name] for name in self._in_keys}
            out[key] = _transition(batch_shape, inputs, next_inputs, rh_acc[0], k_acc[0], emit[0], done, terminated)
        return out

    def _shape_eager(
        self,
        current: dict[str, torch.Tensor],
        z_next: torch.Tensor,
        obs: torch.Tensor,
        reward: torch.Tensor,
        done: torch.Tensor,
        terminated: torch.Tensor,
        batch_shape: torch.Size,
    ) -> dict[str, Any]:
        z, r_h, k = current[INDEX], current[RETURN], current[STEPS]
        achieved = z_next != z
        r_h = r_h + reward * self.value_gamma**k
        k = k + 1
        emit = achieved | done
        nxt = {INDEX: z_next, ACHIEVED: achieved}
        if ANCHOR in current:
            nxt[ANCHOR] = torch.where(achieved, self._flat_obs(obs, batch_shape), current[ANCHOR])
        inputs = [current[key] for key in self.potential.in_keys]
        next_inputs = [nxt[key] for key in self.potential.in_keys]
        if self.learning and bool(emit.any()):
            self.update_potential(inputs, next_inputs, r_h, k, terminated, emit)
        with torch.no_grad():
            phi = self.potential(*inputs)
            phi_next = self.potential(*next_inputs)
        if self.zero_terminal_potential:
            phi_next = phi_next.masked_fill(terminated, 0.0)
        shaping = self.gamma * phi_next - phi
        out: dict[str, Any] = {k: nxt[k] for k in self.state_keys if k in nxt}
        out[RETURN] = r_h.masked_fill(emit, 0.0)
        out[STEPS] = k.masked_fill(emit, 0)
        out[self.env_reward_key] = reward
        out[self.reward_key] = reward + shaping.to(reward.dtype)
        if self.transitions_key is not None:
            out[self.transitions_key] = _transition(
                batch_shape,
                dict(zip(self.potential.in_keys, inputs, strict=True)),
                dict(zip(self.potential.in_keys, next_inputs, strict=True)),
                r_h, k, emit, done, terminated,
            )
        return out

    def update_potential(
        self,
        inputs: list[torch.Tensor],
        next_inputs: list[torch.Tensor],
        r_h: torch.Tensor,
        k: torch.Tensor,
        terminated: torch.Tensor,
        mask: torch.Tensor,
    ) -> None:
        """One SGD step of the potential on this step's SMDP transitions (the online update)."""
        assert self.value_loss is not None and self.value_optimizer is not None
        with torch.enable_grad():
            self.value_optimizer.zero_grad(set_to_none=True)
            loss, _ = self.value_loss.smdp_loss(inputs, next_inputs, r_h, k, terminated, mask)
            loss.backward()
            self.value_optimizer.step()

    # ------------------------------------------------------------------ offline use

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        """Shape a stored trajectory (e.g. from a replay buffer) along its time dimension.

        ``tensordict`` has shape ``[*B, T]`` with the time dimension named
        ``"time"`` (as :meth:`~torchrl.envs.EnvBase.rollout` returns) or last,
        and holds the root observation and the ``("next", ...)`` observation,
        reward, done and terminated entries. The abstract state starts from the
        first root observation and restarts after every ``done``. The potential
        is used but not trained here.
        """
        names = tensordict.names
        time_dim = names.index("time") if "time" in names else tensordict.batch_dims - 1
        steps = tensordict.unbind(time_dim)
        batch_shape = steps[0].batch_size
        current = self._initial_state(steps[0].get(self.observation_key), batch_shape)
        abstraction = self._setup(batch_shape, steps[0].get(self.observation_key))
        loss, self.value_loss = self.value_loss, None
        outs = []
        try:
            for step in steps:
                nxt = step.get("next")
                obs, done = nxt.get(self.observation_key), nxt.get("done")
                out = self.shape(
                    abstraction, current, obs, nxt.get(self.reward_key), done,
                    nxt.get("terminated", done), batch_shape,
                )
                outs.append(out)
                restart = self._initial_state(obs, batch_shape)
                current = {k: torch.where(_expand(done, out[k]), restart[k], out[k]) for k in current}
        finally:
            self.value_loss = loss
        for key, first in outs[0].items():
            values = [o[key] for o in outs]
            stacked = (
                torch.stack(values, time_dim) if isinstance(first, torch.Tensor)
                else TensorDict.stack(values, time_dim)
            )
            tensordict.set(("next", key), stacked)
        return tensordict


_NO_TABLE = np.zeros((0, 1), dtype=np.float32)
_NO_TRANSITION = tuple(np.zeros((0, 1), dtype=d) for d in (np.float32, np.int64, np.bool_))


def _check_finite(reward: torch.Tensor, obs: torch.Tensor, reward_key: NestedKey, obs_key: NestedKey) -> None:
    """Refuse a NaN or infinite reward and a NaN observation, naming the entry and the env.

    One reduction per tensor when all is well (a NaN or inf anywhere makes the sum
    non-finite); the search for the culprit runs only then.
    """
    for tensor, key, bad in ((reward, reward_key, "NaN or infinite"), (obs, obs_key, "NaN")):
        if not tensor.is_floating_point():
            continue
        fast = tensor.device.type == "cpu" and tensor.dtype in (torch.float32, torch.float64)
        total = tensor.detach().numpy().sum() if fast else tensor.sum()  # numpy: fewer µs
        if math.isfinite(float(total)):  # an overflow to inf only costs the search below
            continue
        wrong = ~torch.isfinite(tensor) if tensor is reward else torch.isnan(tensor)
        if bool(wrong.any()):
            first = tuple(int(i) for i in wrong.nonzero()[0])
            raise ValueError(
                f"SubgoalPotentialTransform: {key!r} is {bad} at index {first} (value "
                f"{tensor[first].item()}): it would make the potential NaN for good; fix the env, or "
                "replace such values before this transform"
            )


def _col(t: torch.Tensor) -> np.ndarray:
    """A ``[*B, 1]`` CPU tensor as an ``[n, 1]`` numpy view (a copy if not contiguous)."""
    a = t.numpy()
    return a if a.ndim == 2 else a.reshape(-1, 1)


def _empty_like(t: torch.Tensor) -> tuple[torch.Tensor, np.ndarray]:
    """A new tensor shaped like ``t`` and its ``[n, 1]`` numpy view, for kernel outputs."""
    a: np.ndarray = np.empty((max(1, t.numel()), 1), dtype=_NUMPY_DTYPES[t.dtype])
    out = torch.from_numpy(a)
    return (out if out.shape == t.shape else out.view(t.shape)), a


_NUMPY_DTYPES = {torch.float32: np.float32, torch.float64: np.float64, torch.int64: np.int64, torch.bool: np.bool_}


def _write(tensordict: TensorDictBase, entries: dict[str, Any]) -> None:
    """``tensordict.update(entries)`` for entries this transform built itself.

    Every tensor here was made by the transform with the batch's shape on the
    CPU (or comes from the same TensorDict), so TensorDict's per-key validation
    is redundant; at 10^3 learners it costs more than the shaping arithmetic.
    Plain TensorDicts skip it (``_set_str`` of tensordict 0.14); others update.
    """
    if type(tensordict) is TensorDict and not tensordict.is_locked:
        for key, value in entries.items():
            tensordict._set_str(key, value, inplace=False, validated=True)
    else:
        tensordict.update(entries)


def _transition(
    batch_shape: torch.Size,
    inputs: dict[str, torch.Tensor],
    next_inputs: dict[str, torch.Tensor],
    r_h: torch.Tensor,
    k: torch.Tensor,
    mask: torch.Tensor,
    done: torch.Tensor,
    terminated: torch.Tensor,
) -> TensorDict:
    """An SMDP transition in the layout of TorchRL's value estimators."""
    nxt = TensorDict({**next_inputs, "reward": r_h, "done": done, "terminated": terminated}, batch_size=batch_shape)
    return TensorDict({**inputs, "steps_to_next_obs": k, "mask": mask, "next": nxt}, batch_size=batch_shape)


def _expand(mask: torch.Tensor, like: torch.Tensor) -> torch.Tensor:
    """A ``[*B, 1]`` mask broadcast to ``like``'s trailing feature size."""
    return mask.expand_as(like) if mask.shape != like.shape else mask
