"""SubgoalPotentialTransform: potential-based shaping over a dynamic trajectory aggregation."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Literal

import torch
from tensordict import TensorDict, TensorDictBase
from tensordict.nn import TensorDictModuleBase
from tensordict.utils import NestedKey
from torchrl.data import Composite, OneHot, TensorSpec
from torchrl.envs.transforms import Transform

from torchrl_subgoal.loss import SubgoalValueLoss, ValueUpdate
from torchrl_subgoal.potentials import NaivePotential, TabularPotential
from torchrl_subgoal.subgoals import StateAggregation, SubgoalSeries, SubgoalTables
from torchrl_subgoal.transform import compiled, keys, stored
from torchrl_subgoal.transform.cache import ValueCache
from torchrl_subgoal.transform.compiled import ShapingKernelState, StepInputs, compiled_step
from torchrl_subgoal.transform.eager import torch_step
from torchrl_subgoal.transform.keys import EnvKeys, SubgoalKeys, at, read, write
from torchrl_subgoal.transform.setup import BatchSetup, Settings, Subgoals, compiled_potential
from torchrl_subgoal.transform.shaping import START_MODES, StartPotential
from torchrl_subgoal.transform.transitions import rebuild, transition

__all__ = ["SubgoalPotentialTransform"]

Backend = Literal["auto", "compiled", "torch"]


class SubgoalPotentialTransform(Transform):
    """Adds the shaping reward ``F = γ Φ(z') − Φ(z)`` of a subgoal series to any TorchRL env.

    The transform keeps, per env of the batch, the abstract state of dynamic
    trajectory aggregation (Okudo & Yamada 2021) in the TensorDict (names with
    the default ``prefix="subgoal"``; see :class:`SubgoalKeys`), declared in the
    env's specs as observations and as carried state (``full_state_spec``):

    * ``"subgoal_index"`` ``z`` — the node of the subgoal series reached
      (``0`` at reset; advanced when the next subgoal's predicate holds);
    * ``"subgoal_return"`` ``r_h ← r_h + γ_v^k r`` and ``"subgoal_steps"``
      ``k ← k + 1`` since ``z`` was entered;
    * only when the potential reads them: ``"subgoal_achieved"``,
      ``"subgoal_anchor"`` (the observation at which ``z`` was entered) and
      ``"subgoal_learner"`` (the env's index in the batch).

    The reward, done and terminated entries are the parent env's, resolved as
    TorchRL's ``RewardSum`` and ``StepCounter`` resolve theirs: nested and
    multi-agent keys keep the abstract state in the reward's group (one row per
    episode: the reward must have the done entry's shape). Every step adds ``F``
    to the reward; the env's reward stays under ``"env_reward"`` beside it,
    declared as a second reward entry. ``in_keys`` are the step's entries read,
    ``out_keys`` those written.

    When a subgoal is achieved or the episode ends, the step closes one SMDP
    transition ``(z, r_h, k, z', terminated)``: :meth:`transitions` rebuilds
    those of collected data (any batch shape) from the kept entries, in the
    layout :class:`~torchrl_subgoal.SubgoalValueLoss` reads. At truncation the
    transition bootstraps from ``V(z')``.

    **Shaping and learning are separate.** The shaping uses the potential *as
    it is now* (a dynamic potential). With ``value_update`` the env step first
    trains it online on this step's transitions (the paper's algorithm);
    otherwise train it yourself from :meth:`transitions` with the same loss.
    Freeze a trained potential with ``transform.potential.requires_grad_(False)``.

    **Stored data.** ``transform(data)`` (e.g. a replay-buffer sample
    ``[*B, T]``) recomputes the abstract state and the shaping along the time
    dimension from the stored entries, without training. A row's learner matters
    only when learners have their own table or pattern: then it is read from
    ``"subgoal_learner"`` (or the rows are the env batch in order).

    Policy invariance (Ng et al. 1999) needs ``Φ`` to be a function of the
    *agent's* state: give the agent ``z`` too for the exact guarantee once ``Φ``
    is fixed. A NaN or infinite reward, or a NaN in the observation, raises
    ``ValueError`` naming the entry. Append the transform to the *outer* env
    (``TransformedEnv(ParallelEnv(...), t)``) so that the potential trained is
    the one shaping; see :mod:`torchrl_subgoal.training` for collector workers.

    Args:
        subgoals: a :class:`SubgoalSeries` shared by every env of the batch; a
            sequence of series, one per env (flattened batch order; equal series
            are compiled once); or a :class:`StateAggregation` ``z = g(s)``.
        potential: ``Φ`` — :class:`TabularPotential`, :class:`NeuralPotential`,
            :class:`NaivePotential`, or any TensorDict module reading entries
            this transform keeps and writing one value entry.

    Keyword Args:
        gamma: the agent's discount ``γ`` in ``F = γ Φ(z') − Φ(z)``.
        observation_key: the observation the region predicates and an
            aggregation read, and the anchor snapshots.
        value_update: train the potential online: a :class:`~torchrl_subgoal.ValueUpdate`
            (its learning rate ``α_v`` and, optionally, the
            :class:`~torchrl_subgoal.SubgoalValueLoss` stepped, whose ``γ_v``
            discounts ``r_h``), or the learning rate alone. ``None`` (default):
            no online update, and ``γ_v = γ``.
        zero_terminal_potential: ``Φ = 0`` at terminal states (strict policy
            invariance in episodic tasks). ``False`` shapes with ``V(z')`` at
            the goal as the authors' released code does.
        start_potential: the level of ``Φ``, set by the potential of the state
            the episode started in: ``"value"`` (``Φ = V``), ``"zero"``
            (``Φ = V − V(z_0)``) or ``"nonpositive"`` (the default,
            ``Φ = V − max(V(z_0), 0)``; see ``docs/shaping_defaults.md``).
        transitions_key: if given, every step also writes its SMDP transition
            entry under ``("next", transitions_key)`` (``"mask"`` tells the real
            ones); :meth:`transitions` needs none.
        prefix: the names of the kept entries (see :class:`SubgoalKeys`); the
            potential reads entries of the same prefix. Two transforms on one
            env need different prefixes (the same one is refused).
        backend: ``"compiled"``: the numba kernels (a tabular or naive potential
            on the CPU; anything else is a ``TypeError`` that says why);
            ``"torch"``: torch operations only (any potential and device);
            ``"auto"`` (default): compiled when possible. Both agree.

    Examples:
        >>> from torchrl.envs import TransformedEnv
        >>> from torchrl_subgoal import Cell, SubgoalPotentialTransform, SubgoalSeries, TabularPotential
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> series = SubgoalSeries([Cell(3, 6), Cell(7, 9)])
        >>> potential = TabularPotential(series.num_abstract_states, batch_shape=(4,))
        >>> env = TransformedEnv(FourRoomsEnv(num_envs=4), SubgoalPotentialTransform(
        ...     series, potential, gamma=0.99, observation_key="cell", value_update=0.25))
        >>> data = env.rollout(5)
        >>> data["next", "subgoal_steps"][0, :, 0].tolist()  # k: steps since z was entered
        [1, 2, 3, 4, 5]
        >>> shaped = env.transform(data.clone())  # stored data: the same shaping, no training
        >>> bool((shaped["next", "subgoal_index"] == data["next", "subgoal_index"]).all())
        True
    """

    def __init__(
        self,
        subgoals: SubgoalSeries | Sequence[SubgoalSeries] | StateAggregation,
        potential: TensorDictModuleBase,
        *,
        gamma: float,
        observation_key: NestedKey = "observation",
        value_update: ValueUpdate | float | None = None,
        zero_terminal_potential: bool = True,
        start_potential: StartPotential = "nonpositive",
        transitions_key: NestedKey | None = None,
        prefix: str = "subgoal",
        backend: Backend = "auto",
    ) -> None:
        super().__init__()
        if not 0.0 <= gamma <= 1.0:
            raise ValueError(f"gamma must lie in [0, 1], got {gamma}")
        if start_potential not in START_MODES:
            raise ValueError(f"start_potential must be one of {sorted(START_MODES)}, got {start_potential!r}")
        if backend not in ("auto", "compiled", "torch"):
            raise ValueError(f"backend must be 'auto', 'compiled' or 'torch', got {backend!r}")
        self.subgoals = Subgoals(subgoals)
        self.keys = SubgoalKeys(prefix)
        self.potential = potential
        self._check_potential_keys()
        self.backend = backend
        self.transitions_key = transitions_key
        self.value_update = _value_update(value_update, potential, gamma)
        self.value_optimizer = torch.optim.SGD(potential.parameters(), self.value_update.lr) if self.value_update else None
        self._parameters_list = list(potential.parameters())
        value_gamma = float(gamma) if self.value_update is None or value_update_loss_default(value_update) \
            else self.value_update.loss.gamma  # type: ignore[union-attr]
        self._settings = Settings(self.keys, self._kept(start_potential), float(gamma), value_gamma,
                                  zero_terminal_potential, start_potential, observation_key,
                                  self.subgoals.reads_observation, transitions_key is not None, tuple(potential.in_keys))
        self._env = EnvKeys.resolve(None)
        self._online: BatchSetup | None = None
        self._layout: tuple[int, bool] | None = None
        self._cache = ValueCache()

    def _kept(self, start: StartPotential) -> tuple[str, ...]:
        keys, reads = self.keys, self.potential.in_keys
        extra = tuple(k for k in keys.optional if k in reads)
        # Φ(z_0) needs the potential's input at reset, unless it is z = 0 (every subgoal series starts there)
        if start != "value" and not isinstance(self.potential, NaivePotential) and (
                keys.anchor in reads or (self.subgoals.aggregation is not None and keys.index in reads)):
            extra = (*extra, keys.start)
        return (keys.index, keys.ret, keys.steps, *extra)

    def _check_potential_keys(self) -> None:
        pot = self.potential
        if not isinstance(pot, TensorDictModuleBase) or not pot.out_keys:
            raise TypeError(
                "the potential must be a TensorDict module whose (last) output entry is the value (a Potential, or e.g. "
                f"TensorDictModule(net, in_keys=[{self.keys.anchor!r}], out_keys=['subgoal_value'])), "
                f"got {type(pot).__name__}")
        provided = (self.keys.index, *self.keys.optional)
        unknown = [k for k in pot.in_keys if k not in provided]
        if unknown:
            raise ValueError(f"the potential reads {unknown}, which this transform does not keep; it keeps "
                             f"{list(provided)} (prefix {self.keys.prefix!r}): build the potential with those keys")

    # ------------------------------------------------------------------ what it reads and writes

    @property
    def gamma(self) -> float:
        """``γ`` of the shaping term."""
        return self._settings.gamma

    @property
    def value_gamma(self) -> float:
        """``γ_v`` of the SMDP return (the online update's loss's, else ``γ``)."""
        return self._settings.value_gamma

    @property
    def observation_key(self) -> NestedKey:
        """The observation the region predicates read and the anchor snapshots."""
        return self._settings.observation_key

    @property
    def zero_terminal_potential(self) -> bool:
        """Whether ``Φ = 0`` at terminal states."""
        return self._settings.zero_terminal

    @property
    def start_potential(self) -> StartPotential:
        """The level of ``Φ`` (see the class's ``start_potential``)."""
        return self._settings.start

    @property
    def state_keys(self) -> tuple[str, ...]:
        """Abstract-state entries kept in the TensorDict (``"subgoal_*"``, in the reward's group)."""
        return self._settings.kept

    @property
    def value_key(self) -> NestedKey:
        """The potential's value entry (its last output entry)."""
        return self.potential.out_keys[-1]

    @property
    def env_reward_key(self) -> NestedKey:
        """Where the unshaped reward is kept (``"env_reward"`` beside the reward)."""
        return self._env.env_reward

    @property
    def in_keys(self) -> list[NestedKey]:
        """The step's entries read: the reward, the done and terminated entries, the observation (when
        read) and an earlier shaping's env reward. The kept entries (:attr:`out_keys`) are read back at the root."""
        env = self._env
        read_obs = self._settings.reads_observation or self.keys.anchor in self.state_keys
        extra = [env.env_reward] if env.shaped_before else []
        done = [env.done] if env.terminated == env.done else [env.done, env.terminated]
        return [env.reward, *extra, *done, *([self.observation_key] if read_obs else [])]

    @in_keys.setter
    def in_keys(self, value: Any) -> None:
        if value:
            raise AttributeError("SubgoalPotentialTransform's in_keys come from the parent env and observation_key")

    @property
    def out_keys(self) -> list[NestedKey]:
        """The step's entries written: the shaped reward, the env reward (unless an earlier shaping keeps
        it) and the kept abstract state (and the transition entry with ``transitions_key``)."""
        env = self._env
        written = [env.reward, *([] if env.shaped_before else [env.env_reward])]
        written += [at(env.group, name) for name in self.state_keys]
        return written + ([self.transitions_key] if self.transitions_key is not None else [])

    @out_keys.setter
    def out_keys(self, value: Any) -> None:
        if value:
            raise AttributeError("SubgoalPotentialTransform's out_keys come from the parent env and the prefix")

    @property
    def learning(self) -> bool:
        """Whether the potential is trained online: ``value_update`` was given and it is not frozen."""
        return self.value_update is not None and any(p.requires_grad for p in self._parameters_list)

    @property
    def num_abstract_states(self) -> int:
        """Number of abstract states ``z`` (the terminal one excluded)."""
        return self.subgoals.num_states

    @property
    def aggregation(self) -> StateAggregation | None:
        """The hand-given aggregation (``None``: subgoal series)."""
        return self.subgoals.aggregation

    @property
    def abstraction(self) -> SubgoalTables | StateAggregation | None:
        """The abstraction compiled for the env's batch (``None`` before the first reset)."""
        return self._online.abstraction if self._online is not None else None

    # ------------------------------------------------------------------ set-up and specs

    def _resolve(self) -> None:
        self._env = EnvKeys.resolve(self.parent)

    def _observation_layout(self, obs: torch.Tensor | None, batch_shape: torch.Size) -> tuple[int, bool]:
        """(entries per observation, one-hot?): from the env's spec once known, else from the data (a
        :class:`State` predicate then reads an observation of more than one entry as one-hot)."""
        if self._layout is not None:
            return self._layout
        if not self._settings.reads_observation and self.keys.anchor not in self.state_keys:
            return 0, False
        parent = self.parent
        if parent is not None:
            spec = _observation(parent.full_observation_spec, self.observation_key, "observation_key")
            shape = spec.shape[len(batch_shape):]
            self._layout = (shape.numel() if len(shape) else 1), isinstance(spec, OneHot)
            return self._layout
        if obs is None:
            return 0, False
        size = obs.shape[len(batch_shape):].numel() if obs.dim() > len(batch_shape) else 1
        return size, self.subgoals.one_hot_states and size > 1

    def _batch(self, batch_shape: torch.Size, learner: torch.Tensor, n_learners: int, obs: torch.Tensor | None,
               online: bool) -> BatchSetup:
        """Set up a batch whose rows belong to ``learner`` (``online``: the env's batch, in order)."""
        pot = self.potential
        if isinstance(pot, TabularPotential) and pot.batch_shape and pot.learners != n_learners:
            raise ValueError(f"TabularPotential has batch_shape {tuple(pot.batch_shape)} but the env batch has "
                             f"{n_learners} envs: use one table per env or a shared one (batch_shape=())")
        if isinstance(pot, TabularPotential) and pot.num_states < self.num_abstract_states:
            raise ValueError(f"TabularPotential has {pot.num_states} states; the abstraction has "
                             f"{self.num_abstract_states}")
        layout = self._observation_layout(obs, batch_shape)
        setup = BatchSetup(batch_shape, self.subgoals.compile(learner, batch_shape, n_learners, layout,
                                                              self.observation_key), learner,
                           compiled_search=self.backend != "torch")
        why = "backend='torch'" if self.backend == "torch" else compiled_potential(
            pot, self.value_update.loss if self.value_update is not None else None)
        if why is None:
            setup.use_kernels(pot, self._settings, self.value_update.lr if self.value_update else 0.0, online)
        elif self.backend == "compiled":
            raise TypeError(f"SubgoalPotentialTransform(backend='compiled'): {why}; use backend='torch' or 'auto'")
        return setup

    def _online_batch(self, batch_shape: torch.Size, obs: torch.Tensor | None) -> BatchSetup:
        setup = self._online
        if setup is None or setup.batch_shape != batch_shape or setup.moved:
            n = batch_shape.numel()
            setup = self._online = self._batch(batch_shape, torch.arange(n).reshape(*batch_shape, 1), n, obs, True)
        return setup

    def transform_observation_spec(self, observation_spec: TensorSpec) -> TensorSpec:
        assert isinstance(observation_spec, Composite)
        self._resolve()
        if self._settings.reads_observation:
            _observation(observation_spec, self.observation_key, "observation_key")
        for key, spec in self._state_specs(observation_spec).items():
            if key in observation_spec.keys(True, True):
                raise ValueError(f"SubgoalPotentialTransform: {key!r} is kept already by another transform on this "
                                 f"env; give this one another prefix (prefix='room') and its potential matching keys")
            observation_spec[key] = spec
        if self.transitions_key is not None:
            inputs = {k: s for k, s in self._state_specs(observation_spec, relative=True).items()
                      if k in self._settings.inputs}
            observation_spec[self.transitions_key] = keys.transition_spec(inputs, self._group_shape(observation_spec))
        return observation_spec

    def transform_input_spec(self, input_spec: TensorSpec) -> TensorSpec:
        # the kept entries are carried from step to step: state, as RewardSum's and StepCounter's are
        assert isinstance(input_spec, Composite)
        self._resolve()
        state = input_spec["full_state_spec"]
        if state is None:
            state = Composite(shape=input_spec.shape, device=input_spec.device)
        for key, spec in self._state_specs(self.parent.full_observation_spec).items():  # type: ignore[union-attr]
            state[key] = spec
        input_spec["full_state_spec"] = state
        return input_spec

    def transform_reward_spec(self, reward_spec: TensorSpec) -> TensorSpec:
        assert isinstance(reward_spec, Composite)
        self._resolve()
        env = self._env
        done = self.parent.full_done_spec[env.done]  # type: ignore[union-attr]
        if reward_spec[env.reward].shape != done.shape:
            raise ValueError(f"SubgoalPotentialTransform: the reward {env.reward!r} has shape "
                             f"{tuple(reward_spec[env.reward].shape)} but episodes end by {env.done!r} of shape "
                             f"{tuple(done.shape)}: one reward per episode row is needed (combine the rewards first)")
        if not env.shaped_before:
            reward_spec[env.env_reward] = reward_spec[env.reward].clone()
        return reward_spec

    def _group_shape(self, observation_spec: Composite) -> torch.Size:
        done = self.parent.full_done_spec[self._env.done]  # type: ignore[union-attr]
        return done.shape[:-1]

    def _state_specs(self, observation_spec: Composite, relative: bool = False) -> dict[NestedKey, TensorSpec]:
        shape = self._group_shape(observation_spec)
        anchor = _observation(observation_spec, self.observation_key, "observation_key") \
            if self.keys.anchor in self.state_keys else None
        specs = keys.state_specs(self.keys, self.state_keys, self.num_abstract_states, shape, anchor)
        return specs if relative else {at(self._env.group, k): s for k, s in specs.items()}  # type: ignore[misc]

    # ------------------------------------------------------------------ reset and step

    def _initial_state(self, setup: BatchSetup, td: TensorDictBase) -> dict[str, torch.Tensor]:
        """The abstract state at a reset observation (``td`` holds the reset entries)."""
        batch_shape, k = setup.batch_shape, self.keys
        col = (*batch_shape, 1)
        obs = read(td, self.observation_key)
        state = {k.index: setup.abstraction.initial(obs, batch_shape), k.ret: torch.zeros(col),
                 k.steps: torch.zeros(col, dtype=torch.long)}
        kept = self.state_keys
        if k.achieved in kept:
            state[k.achieved] = torch.zeros(col, dtype=torch.bool)
        if k.anchor in kept:
            state[k.anchor] = obs.reshape(*batch_shape, -1).to(torch.float32)
        if k.learner in kept:
            state[k.learner] = setup.learner
        if k.start in kept:
            state[k.start] = state[k.anchor if k.anchor in kept else k.index]
        return state

    def _reset(self, tensordict: TensorDictBase, tensordict_reset: TensorDictBase) -> TensorDictBase:
        # values for every env: TorchRL keeps the old ones where "_reset" is False
        group = self._env.group
        root = tensordict_reset.get(group) if group else tensordict_reset
        setup = self._online_batch(root.batch_size, read(tensordict_reset, self.observation_key))
        state = self._initial_state(setup, tensordict_reset)
        for name, value in state.items():
            write(root, name, value)
        if self.transitions_key is not None:
            zero, false = torch.zeros_like(state[self.keys.ret]), torch.zeros_like(state[self.keys.index], dtype=torch.bool)
            inputs = {k: state[k] for k in self._settings.inputs}
            write(tensordict_reset, self.transitions_key, transition(setup.batch_shape, inputs, inputs, zero,
                                                                     state[self.keys.steps], false, false, false))
        return tensordict_reset

    def _reset_on_native_autoreset(self, tensordict: TensorDictBase, tensordict_reset: TensorDictBase) -> TensorDictBase:
        # the env reset itself during the step: start the abstract state again where "_reset" is set
        group = self._env.group
        root = tensordict_reset.get(group) if group else tensordict_reset
        reset = root.get("_reset", None)
        if reset is None:
            return tensordict_reset
        setup = self._online_batch(root.batch_size, read(tensordict_reset, self.observation_key))
        for name, value in self._initial_state(setup, tensordict_reset).items():
            current = root.get(name)
            write(root, name, torch.where(reset.reshape(*reset.shape[:root.batch_dims], 1).expand_as(current)
                                          if current.dim() > reset.dim() else reset, value, current))
        return tensordict_reset

    def _step(self, tensordict: TensorDictBase, next_tensordict: TensorDictBase) -> TensorDictBase:
        env = self._env
        root, nxt = (tensordict.get(env.group), next_tensordict.get(env.group)) if env.group \
            else (tensordict, next_tensordict)
        current = {}
        for name in self._settings.kept:
            value = read(root, name)
            if value is None:
                raise KeyError(f"SubgoalPotentialTransform: {name!r} is missing from the step's input: reset the "
                               "env through the transform (env.reset()) before stepping")
            current[name] = value
        reward = read(next_tensordict, env.reward)
        done = read(next_tensordict, env.done)
        obs = read(next_tensordict, self._settings.observation_key) if self._settings.reads_observation else None
        step = StepInputs(obs, reward, read(next_tensordict, env.env_reward) if env.shaped_before else reward, done,
                          done if env.terminated == env.done else read(next_tensordict, env.terminated),
                          next_tensordict)
        out = self._advance(self._online_batch(nxt.batch_size, obs), current, step, self.learning)
        for name in self._settings.kept:
            write(nxt, name, out[name])
        write(next_tensordict, env.reward, out["reward"])
        if not env.shaped_before:
            write(next_tensordict, env.env_reward, reward)
        if self.transitions_key is not None:
            write(next_tensordict, self.transitions_key, out["transition"])
        return next_tensordict

    def _advance(self, setup: BatchSetup, current: dict[str, torch.Tensor], step: StepInputs, learn: bool) -> Any:
        """One step from ``current``: compiled when set up so (and on the CPU), else in torch."""
        learner = self.keys.learner
        if learner in self._settings.kept and learner not in current:
            current[learner] = setup.learner
        if setup.compiled and current[self.keys.index].device.type == "cpu":
            return compiled_step(setup, self._settings, current, step, learn)
        if step.obs is None and self._settings.reads_observation:
            raise KeyError(f"SubgoalPotentialTransform: the step has no {self.observation_key!r} entry")
        return torch_step(setup, self._settings, self.potential, self._cache, current, step,
                          self.update_potential if learn else None)

    def update_potential(self, transitions: TensorDictBase) -> None:
        """The online update: one SGD step of the potential on ``transitions`` (SMDP layout, masked).

        Examples:
            >>> from torchrl_subgoal import State
            >>> t = SubgoalPotentialTransform(SubgoalSeries([State(1)]), TabularPotential(2), gamma=0.9,
            ...                               value_update=0.5)
            >>> one = torch.ones(1, 1)
            >>> t.update_potential(transition(torch.Size([1]), {"subgoal_index": 0 * one.long()},
            ...                               {"subgoal_index": one.long()}, one, one.long(), one.bool(),
            ...                               one.bool(), one.bool()))
            >>> t.potential.table.tolist()  # V(0) += 0.5 (1 + 0.9 · 0 − 0): the episode terminated
            [0.5, 0.0]
        """
        update = self.value_update
        assert update is not None and update.loss is not None and self.value_optimizer is not None
        with torch.enable_grad():
            self.value_optimizer.zero_grad(set_to_none=True)
            update.loss(transitions)["loss_value"].backward()
            self.value_optimizer.step()

    def transitions(self, data: TensorDictBase) -> TensorDictBase:
        """The real SMDP transitions closed in collected ``data`` (any batch shape), as ``[N]``.

        Rebuilt from the entries the transform keeps (nothing extra stored per step): a step closes a
        transition when ``z`` changed or the episode ended. Rows keep the potential's inputs (with
        ``"subgoal_learner"``, a per-env table finds its row in a shuffled replay buffer), in the layout
        :class:`~torchrl_subgoal.SubgoalValueLoss` reads.

        Examples:
            >>> from torchrl.envs import TransformedEnv
            >>> from torchrl_subgoal import Cell, SubgoalSeries, TabularPotential
            >>> from torchrl_subgoal.envs import FourRoomsEnv
            >>> t = SubgoalPotentialTransform(SubgoalSeries([Cell(1, 2)]), TabularPotential(2), gamma=0.9,
            ...                               observation_key="cell")
            >>> data = TransformedEnv(FourRoomsEnv(4, max_steps=10), t).rollout(30, break_when_any_done=False)
            >>> real = t.transitions(data)
            >>> real.batch_dims, int(real["steps_to_next_obs"].max()) <= 10
            (1, True)
        """
        return rebuild(data, self.keys, self._env, list(self._settings.inputs), self.value_gamma)

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        """Shape stored trajectories (e.g. a replay-buffer sample) along their time dimension, without training.

        ``tensordict`` has shape ``[*B, T]`` with the time dimension named
        ``"time"`` (as :meth:`~torchrl.envs.EnvBase.rollout` returns) or last,
        and holds the root observation and the step's :attr:`in_keys` under
        ``"next"``. The abstract state starts from the stored entries of the
        first step when the data has them (a slice from the middle of an
        episode), else from the first observation as at a reset, and restarts
        after every ``done``. The reward shaped is the env reward
        (``"env_reward"`` when stored). The potential is used as it is now.
        """
        time = stored.time_dim(tensordict)
        env, k = self._env, self.keys
        nxt = tensordict.get("next", None)
        stored_reward = nxt is not None and read(nxt, env.env_reward) is not None  # then the one shaped
        missing = [("next", key) for key in self.in_keys if key != env.env_reward and not (key == env.reward and stored_reward)
                   and (nxt is None or read(nxt, key) is None)]
        if missing:
            raise KeyError(f"SubgoalPotentialTransform: the stored data has no {missing}; store the steps' entries "
                           f"the transform reads (in_keys)")
        steps = tensordict.unbind(time)
        first = steps[0].get(env.group) if env.group else steps[0]
        batch_shape = first.batch_size
        learned = (tensordict.get(env.group) if env.group else tensordict).get(k.learner, None)
        learner, n_learners = stored.learners_of(learned, batch_shape, time, self.subgoals, self.potential,
                                                 self._online.batch_shape.numel() if self._online else None, k.learner)
        setup = self._batch(batch_shape, learner, n_learners, read(steps[0], self.observation_key), online=False)
        if all(read(first, name) is not None for name in self.state_keys):
            current = {name: read(first, name) for name in self.state_keys}
            if k.learner in current:
                current[k.learner] = learner
        else:
            current = self._initial_state(setup, steps[0])
        outs = []
        for t, step_td in enumerate(steps):
            step_next = step_td.get("next")
            reward = read(step_next, env.env_reward)
            reward = read(step_next, env.reward) if reward is None else reward
            done = read(step_next, env.done)
            terminated = read(step_next, env.terminated)
            obs = read(step_next, self.observation_key) if self._settings.reads_observation else None
            step = StepInputs(obs, reward, reward, done, done if terminated is None else terminated, step_next)
            out = self._advance(setup, current, step, learn=False)
            out[env.env_reward] = reward
            outs.append(out)
            if t + 1 < len(steps):
                restart = self._initial_state(setup, steps[t + 1])
                ended = done.reshape(*batch_shape, 1)
                current = {name: torch.where(ended, restart[name], out[name]) for name in current}
        for name, first_out in outs[0].items():
            values = [o[name] for o in outs]
            value = torch.stack(values, time) if isinstance(first_out, torch.Tensor) else TensorDict.stack(values, time)
            key = env.reward if name == "reward" else self.transitions_key if name == "transition" else \
                name if name == env.env_reward else at(env.group, name)
            tensordict.set(("next", *key) if isinstance(key, tuple) else ("next", key), value)
        return tensordict

    def kernel_state(self, tensordict: TensorDictBase) -> ShapingKernelState:
        """This transform for a compiled loop: its abstraction, its potential and each learner's abstract
        state as ``tensordict`` (a reset of the env through this transform) holds it, copied.

        Needs the CPU, a subgoal series (regions only, no conditions), a lookup or a region aggregation, and
        a tabular or naive potential; anything else is a ``TypeError`` that says so.

        Examples:
            >>> from torchrl.envs import TransformedEnv
            >>> from torchrl_subgoal import State, TabularPotential
            >>> from torchrl_subgoal.envs import FourRoomsEnv
            >>> shaping = SubgoalPotentialTransform(SubgoalSeries([State(3), State(7)]), TabularPotential(3, [2]),
            ...                                     gamma=0.9, value_update=0.1)
            >>> env = TransformedEnv(FourRoomsEnv(num_envs=2), shaping)
            >>> state = shaping.kernel_state(env.reset())
            >>> state.potential.table.shape, state.potential.value_lr
            ((2, 3), 0.1)
        """
        setup = self._online
        if setup is None:
            raise TypeError("kernel_state needs the env reset through the transform first (env.reset())")
        if not setup.compiled:
            why = compiled_potential(self.potential, self.value_update.loss if self.value_update else None)
            raise TypeError(f"a compiled loop shapes as the compiled step does, which cannot here: {why or 'backend'}")
        root = tensordict.get(self._env.group) if self._env.group else tensordict
        state = (root.get(self.keys.index), root.get(self.keys.ret), root.get(self.keys.steps))
        return compiled.kernel_state(setup, state, self.learning,  # type: ignore[arg-type]
                                     self._observation_layout(None, setup.batch_shape)[0])


def _observation(spec: Composite, key: NestedKey, what: str) -> TensorSpec:
    if key not in spec.keys(True, True):
        raise KeyError(f"SubgoalPotentialTransform: {what} {key!r} is not an observation of the env; "
                       f"available: {sorted(map(str, spec.keys(True, True)))}")
    return spec[key]


def value_update_loss_default(value_update: ValueUpdate | float | None) -> bool:
    """Whether the online update steps the default loss (``γ_v = γ``)."""
    return not isinstance(value_update, ValueUpdate) or value_update.loss is None


def _value_update(value_update: ValueUpdate | float | None, potential: TensorDictModuleBase,
                  gamma: float) -> ValueUpdate | None:
    """``value_update`` as a :class:`ValueUpdate` whose loss trains ``potential`` (``None``: none)."""
    if value_update is None:
        return None
    update = value_update if isinstance(value_update, ValueUpdate) else ValueUpdate(float(value_update))
    if not list(potential.parameters()):
        raise ValueError(f"value_update: {type(potential).__name__} has no parameters to train")
    if update.loss is None:
        return ValueUpdate(update.lr, SubgoalValueLoss(potential, reduction="sum").make_value_estimator(gamma=gamma))
    if update.loss.potential is not potential:
        raise ValueError("value_update: its loss trains another potential than the transform's")
    return update
