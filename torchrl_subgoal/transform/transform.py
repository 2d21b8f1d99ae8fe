"""SubgoalPotentialTransform: potential-based shaping over a dynamic trajectory aggregation."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any, Literal

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase
from tensordict.utils import NestedKey
from torchrl.data import Composite, TensorSpec
from torchrl.envs.transforms import Transform

from torchrl_subgoal._kernels import NUMBA
from torchrl_subgoal.loss import ValueUpdate
from torchrl_subgoal.subgoals import StateAggregation, SubgoalSeries, SubgoalTables
from torchrl_subgoal.transform import compiled, keys, setup, stored
from torchrl_subgoal.transform.cache import ValueCache
from torchrl_subgoal.transform.compiled import ShapingKernelState, StepInputs, compiled_step
from torchrl_subgoal.transform.eager import torch_step
from torchrl_subgoal.transform.keys import EnvKeys, SubgoalKeys, at, read, write
from torchrl_subgoal.transform.setup import BatchSetup, Subgoals
from torchrl_subgoal.transform.shaping import StartPotential
from torchrl_subgoal.transform.transitions import empty_transition, rebuild

__all__ = ["SubgoalPotentialTransform"]

Backend = Literal["auto", "compiled", "torch"]


class SubgoalPotentialTransform(Transform):
    """Adds the shaping reward ``F = γ Φ(z') − Φ(z)`` of a subgoal series to any TorchRL env.

    Per env of the batch, the transform keeps the abstract state of dynamic trajectory aggregation (Okudo & Yamada
    2021) in the TensorDict, declared in the specs as observations and as carried state (names with the default
    ``prefix``; see :class:`SubgoalKeys`): ``"subgoal_index"`` ``z`` (the node of the series reached: 0 at reset,
    advanced when the next subgoal holds), ``"subgoal_return"`` ``r_h ← r_h + γ_v^k r`` and ``"subgoal_steps"`` ``k ← k
    + 1`` since ``z`` was entered, and, when the potential reads them, ``"subgoal_achieved"``, ``"subgoal_anchor"``
    (the observation at which ``z`` was entered) and ``"subgoal_learner"`` (the env's index in the batch).

    The reward, done and terminated entries are the parent env's, resolved as TorchRL's ``RewardSum`` and
    ``StepCounter`` resolve theirs (nested and multi-agent keys keep the abstract state in the reward's group, one row
    per episode). Every step adds ``F`` to the reward; the env's reward stays under ``"env_reward"``, a second reward
    entry. ``in_keys`` are the step's entries read, ``out_keys`` those written.

    A step that achieves a subgoal or ends the episode closes an SMDP transition ``(z, r_h, k, z', terminated)``;
    :meth:`transitions` rebuilds those of collected data for :class:`~torchrl_subgoal.SubgoalValueLoss`. Shaping uses
    the potential as it is now; with ``value_update`` the step first trains it online (the paper's algorithm).
    ``transform(data)`` shapes stored trajectories (a replay-buffer sample) without training. Policy invariance needs
    ``Φ`` to be a function of the agent's state: give the agent ``z`` too. A NaN or infinite reward, or a NaN in the
    observation, is a ``ValueError`` naming the entry. Append the transform to the *outer* env
    (``TransformedEnv(ParallelEnv(...), t)``), so that the potential trained is the one shaping (collector workers:
    :mod:`torchrl_subgoal.training`).

    Args:
        subgoals: a :class:`SubgoalSeries` shared by every env of the batch; a sequence of series, one per env
            (flattened batch order; equal series are compiled once); or a :class:`StateAggregation` ``z = g(s)``.
        potential: ``Φ``: :class:`TabularPotential`, :class:`NeuralPotential`, :class:`NaivePotential`, or any
            TensorDict module reading entries this transform keeps and writing one value.

    Keyword Args:
        gamma: the agent's discount ``γ`` in ``F = γ Φ(z') − Φ(z)``.
        observation_key: the observation the region predicates and an aggregation read, and the anchor snapshots.
        value_update: train the potential online: a :class:`~torchrl_subgoal.ValueUpdate` (the learning rate ``α_v``
            and, optionally, the configured :class:`~torchrl_subgoal.SubgoalValueLoss` it steps, whose ``γ_v``
            discounts ``r_h``; by default its optimistic target, docs/shaping_defaults.md), or the learning rate
            alone. ``None``: none, ``γ_v = γ``.
        zero_terminal_potential: ``Φ = 0`` at terminal states (strict policy invariance in episodic tasks); ``False``
            shapes with ``V(z')`` at the goal, as the authors' released code does.
        start_potential: the level of ``Φ``, set by the potential of the state the episode started in: ``"value"`` (``Φ
            = V``), ``"zero"`` (``Φ = V − V(z_0)``) or ``"nonpositive"`` (default, ``Φ = V − max(V(z_0), 0)``; see
            docs/shaping_defaults.md).
        transitions_key: if given, every step also writes its SMDP transition under ``("next", transitions_key)``
            (``"mask"`` tells the real ones).
        prefix: the names of the kept entries; two transforms on one env need different prefixes (the same one is
            refused).
        backend: ``"compiled"``: numba kernels (a tabular or naive potential on the CPU; anything else is a
            ``TypeError`` saying why); ``"torch"``: torch operations only (any potential, any device); ``"auto"``
            (default): compiled when possible (numba installed: the ``fast`` extra). Both agree.

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
        setup.check_options(gamma, start_potential, backend)
        self.subgoals, self.keys = Subgoals(subgoals), SubgoalKeys(prefix)
        setup.check_potential(potential, self.keys)
        self.potential = potential
        self.backend, self.transitions_key = backend, transitions_key
        self.value_update = setup.online_update(value_update, potential, gamma)
        self._parameters_list, self.value_optimizer = setup.trained_parameters(potential, self.value_update)
        self._settings = setup.settings(
            self.keys, potential, self.subgoals, gamma, self.value_update, observation_key, transitions_key,
            zero_terminal=zero_terminal_potential, start=start_potential,
        )  # fmt: skip
        self._env = EnvKeys.resolve(None)
        self._online: BatchSetup | None = None
        self._layout: tuple[int, bool] | None = None
        self._cache = ValueCache()

    # ------------------------------------------------------------------ what it keeps, reads and writes

    gamma = property(lambda self: self._settings.gamma, doc="The discount of the shaping term.")
    value_gamma = property(lambda self: self._settings.value_gamma, doc="The discount of the SMDP return.")
    observation_key = property(lambda self: self._settings.observation_key, doc="What the subgoals and anchor read.")
    zero_terminal_potential = property(lambda self: self._settings.zero_terminal, doc="``Φ = 0`` at terminal states.")
    start_potential = property(lambda self: self._settings.start, doc="The level of ``Φ``.")
    state_keys = property(
        lambda self: self._settings.kept,
        doc='The abstract-state entries kept (``"subgoal_*"``, in the reward\'s group).',
    )
    env_reward_key = property(lambda self: self._env.env_reward, doc="Where the unshaped reward is kept.")
    value_key = property(lambda self: self.potential.out_keys[-1], doc="The potential's value entry.")
    num_abstract_states = property(lambda self: self.subgoals.num_states, doc="Number of abstract states ``z``.")
    aggregation = property(lambda self: self.subgoals.aggregation, doc="The hand-given aggregation, if any.")

    @property
    def in_keys(self) -> list[NestedKey]:
        """The step's entries read: the reward, the done and terminated entries, the observation (when read)
        and an earlier shaping's env reward; the kept entries (:attr:`out_keys`) are read back at the root."""
        env = self._env
        read_obs = self._settings.reads_observation or self.keys.anchor in self.state_keys
        done = [env.done] if env.terminated == env.done else [env.done, env.terminated]
        return [
            env.reward,
            *([env.env_reward] if env.shaped_before else []),
            *done,
            *([self.observation_key] if read_obs else []),
        ]

    @in_keys.setter
    def in_keys(self, value: Any) -> None:  # Transform.__init__ sets None
        if value:
            raise AttributeError("SubgoalPotentialTransform's in_keys come from the parent env and observation_key")

    @property
    def out_keys(self) -> list[NestedKey]:
        """The step's entries written: the shaped reward, the env reward (unless an earlier shaping keeps it),
        the kept abstract state, and the transition entry with ``transitions_key``."""
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
        """Whether the potential is trained online: ``value_update`` was given and it is not frozen
        (freeze it with ``TabularPotential.freeze`` or ``transform.potential.requires_grad_(False)``)."""
        return self.value_update is not None and any(p.requires_grad for p in self._parameters_list)

    @property
    def abstraction(self) -> SubgoalTables | StateAggregation | None:
        """The abstraction compiled for the env's batch (``None`` before the first reset)."""
        return self._online.abstraction if self._online is not None else None

    # ------------------------------------------------------------------ set-up and specs

    def _batch(
        self, batch_shape: torch.Size, learner: torch.Tensor, n_learners: int, obs: torch.Tensor | None, online: bool
    ) -> BatchSetup:
        """Set up a batch whose rows belong to ``learner`` (``online``: the env's batch, in order)."""
        setup.check_table(self.potential, n_learners, self.num_abstract_states)
        setup.check_device(self.potential, obs)
        layout = self._layout  # the observation's entries and encoding: the env's spec's once known
        if layout is None:
            spec = None
            if self.parent is not None and (self._settings.reads_observation or self.keys.anchor in self.state_keys):
                spec = keys.observation(self.parent.full_observation_spec, self.observation_key, "observation_key")
            layout = setup.observation_layout(spec, obs, batch_shape, self.subgoals)
            if spec is not None:
                self._layout = layout
        abstraction = self.subgoals.compile(learner, batch_shape, n_learners, layout, self.observation_key)
        ancestors = setup.monotone_ancestors(self.potential, self.subgoals, learner, n_learners)
        batch = BatchSetup(
            batch_shape, abstraction, learner, compiled_search=self.backend != "torch" and NUMBA, ancestors=ancestors
        )
        if setup.compiles(self.backend, self.potential, self.value_update):
            batch.use_kernels(self.potential, self._settings, self.value_update, online)
        return batch

    def _online_batch(self, batch_shape: torch.Size, obs: torch.Tensor | None) -> BatchSetup:
        batch = self._online
        if batch is None or batch.batch_shape != batch_shape or batch.stale(self.potential):
            n = batch_shape.numel()
            batch = self._online = self._batch(batch_shape, torch.arange(n).reshape(*batch_shape, 1), n, obs, True)
        return batch

    def _apply(self, fn: Any, recurse: bool = True) -> Any:  # .to(), .cuda(), .share_memory()...
        applied, self._online = super()._apply(fn, recurse), None  # set up again at the next step
        self._parameters_list, self.value_optimizer = setup.trained_parameters(self.potential, self.value_update)
        return applied  # and train the parameters as they are now (a move may replace them)

    def _kept_specs(self) -> dict[str, TensorSpec]:
        self._env = EnvKeys.resolve(self.parent)
        s = self._settings
        return keys.kept_specs(self.parent, self._env, self.keys, s.kept, self.num_abstract_states, s.observation_key)

    def transform_observation_spec(self, observation_spec: TensorSpec) -> TensorSpec:
        assert isinstance(observation_spec, Composite)
        specs = self._kept_specs()
        if self._settings.reads_observation:
            keys.observation(observation_spec, self.observation_key, "observation_key")
        keys.declare(observation_spec, self.parent, self._env, specs, refuse_taken=True)
        if self.transitions_key is not None:
            inputs = {k: s for k, s in specs.items() if k in self._settings.inputs}
            observation_spec[self.transitions_key] = keys.transition_spec(inputs, specs[self.keys.index].shape[:-1])
        return observation_spec

    def transform_input_spec(self, input_spec: TensorSpec) -> TensorSpec:
        # the kept entries are carried from step to step: state, as RewardSum's and StepCounter's are
        assert isinstance(input_spec, Composite)
        state = input_spec["full_state_spec"]
        if state is None:
            state = Composite(shape=input_spec.shape, device=input_spec.device)
        keys.declare(state, self.parent, self._env, self._kept_specs(), refuse_taken=False)
        input_spec["full_state_spec"] = state
        return input_spec

    def transform_reward_spec(self, reward_spec: TensorSpec) -> TensorSpec:
        assert isinstance(reward_spec, Composite)
        self._env = EnvKeys.resolve(self.parent)
        keys.add_env_reward(reward_spec, self.parent, self._env)
        return reward_spec

    # ------------------------------------------------------------------ reset and step

    def _reset(self, tensordict: TensorDictBase, tensordict_reset: TensorDictBase) -> TensorDictBase:
        return self._start(tensordict_reset, native=False)  # every env's: TorchRL keeps the rest where not "_reset"

    def _reset_on_native_autoreset(
        self, tensordict: TensorDictBase, tensordict_reset: TensorDictBase
    ) -> TensorDictBase:
        return self._start(tensordict_reset, native=True)  # the env reset itself in its step: where "_reset" is set

    def _start(self, td: TensorDictBase, native: bool) -> TensorDictBase:
        """The kept entries at a reset: every row's, or (``native``) those of the rows ``"_reset"`` flags."""
        group, obs = self._env.group, read(td, self.observation_key)
        root = td.get(group) if group else td
        reset = root.get("_reset", None) if native else None
        if native and reset is None:
            return td
        batch = self._online_batch(root.batch_size, obs)
        state = setup.initial_state(batch, self._settings, obs)
        for name, value in state.items():
            write(
                root,
                name,
                value if reset is None else torch.where(reset.reshape(*batch.batch_shape, 1), value, root.get(name)),
            )
        if self.transitions_key is not None and not native:
            write(
                td, self.transitions_key, empty_transition(batch.batch_shape, state, self._settings.inputs, self.keys)
            )
        return td

    def _step(self, tensordict: TensorDictBase, next_tensordict: TensorDictBase) -> TensorDictBase:
        # every env step comes here: entries are read and written unchecked (their shapes are the specs')
        env, settings = self._env, self._settings
        root, nxt = (
            (tensordict.get(env.group), next_tensordict.get(env.group)) if env.group else (tensordict, next_tensordict)
        )
        current = {}
        for name in settings.kept:
            value = root._get_str(name, None)
            if value is None:
                raise KeyError(
                    f"SubgoalPotentialTransform: {name!r} is missing from the step's input: reset the "
                    "env through the transform (env.reset()) before stepping"
                )
            current[name] = value
        reward, done = read(next_tensordict, env.reward), read(next_tensordict, env.done)
        obs = read(next_tensordict, settings.observation_key) if settings.reads_observation else None
        step = StepInputs(
            obs,
            reward,
            read(next_tensordict, env.env_reward) if env.shaped_before else reward,
            done,
            done if env.terminated == env.done else read(next_tensordict, env.terminated),
            next_tensordict,
        )
        batch = self._online  # set up again for another batch shape, or when a table moved (to shared memory…)
        if batch is None or batch.batch_shape != nxt.batch_size or batch.stale(self.potential):
            batch = self._online_batch(nxt.batch_size, obs)
        out = self._advance(batch, current, step, self.value_update is not None and self.learning)
        for name in settings.kept:
            nxt._set_str(name, out[name], inplace=False, validated=True)
        write(next_tensordict, env.reward, out["reward"])
        if not env.shaped_before:
            write(next_tensordict, env.env_reward, reward)
        if self.transitions_key is not None:
            write(next_tensordict, self.transitions_key, out["transition"])
        return next_tensordict

    def _advance(self, batch: BatchSetup, current: dict[str, torch.Tensor], step: StepInputs, learn: bool) -> Any:
        """One step from ``current``: compiled when set up so (and on the CPU), else in torch."""
        learner = self.keys.learner
        if learner in self._settings.kept and learner not in current:
            current[learner] = batch.learner
        if batch.compiled and current[self.keys.index].device.type == "cpu":
            return compiled_step(batch, self._settings, current, step, learn)
        if step.obs is None and self._settings.reads_observation:
            raise KeyError(f"SubgoalPotentialTransform: the step has no {self.observation_key!r} entry")
        return torch_step(
            batch, self._settings, self.potential, self._cache, current, step, self.update_potential if learn else None
        )

    def update_potential(self, transitions: TensorDictBase) -> None:
        """The online update: one SGD step of ``value_update``'s loss on ``transitions`` (SMDP layout, masked).

        Examples:
            >>> from torchrl_subgoal import State, TabularPotential
            >>> from torchrl_subgoal.transform.transitions import transition
            >>> series = SubgoalSeries([State(1)])
            >>> t = SubgoalPotentialTransform(series, TabularPotential(2), gamma=0.9, value_update=0.5)
            >>> z, one = torch.zeros(1, 1, dtype=torch.long), torch.ones(1, 1, dtype=torch.bool)
            >>> t.update_potential(transition(torch.Size([1]), {"subgoal_index": z}, {"subgoal_index": z + 1},
            ...                               one.float(), z + 1, one, one, one, one))  # r_h = 1, then terminated
            >>> t.potential.table.tolist()  # V(0) += 0.5 · 2τ (1 + 0 − 0), τ = 0.9
            [0.8999999761581421, 0.0]
        """
        update = self.value_update
        assert update is not None and update.loss is not None and self.value_optimizer is not None
        with torch.enable_grad():
            self.value_optimizer.zero_grad(set_to_none=True)
            update.loss(transitions)["loss_value"].backward()
            self.value_optimizer.step()

    def transitions(self, data: TensorDictBase) -> TensorDictBase:
        """The real SMDP transitions closed in collected ``data`` (any batch shape), as ``[N]``.

        Rebuilt from the kept entries (nothing extra stored per step): a step closes a transition when ``z``
        changed or the episode ended. Rows keep the potential's inputs (with ``"subgoal_learner"``, a per-env
        table finds its row in a shuffled replay buffer), in the layout
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

        ``tensordict`` has shape ``[*B, T]`` with the time dimension named ``"time"`` (as
        :meth:`~torchrl.envs.EnvBase.rollout` returns) or last, and holds the root observation and the
        step's :attr:`in_keys` under ``"next"``. The abstract state starts from the stored entries of the
        first step when the data has them (a slice from the middle of an episode), else from the first
        observation as at a reset, and restarts after every ``done``. The reward shaped is the env reward
        (``"env_reward"`` when stored). The rows' learners matter only when learners have their own table
        or pattern: then each row's is read from ``"subgoal_learner"`` (or the rows are the env batch in
        order); otherwise any sample, shuffled or not, is shaped (an empty one is returned as it is).
        """

        def set_up(shape: torch.Size, learned: torch.Tensor | None, time: int, obs: torch.Tensor | None) -> BatchSetup:
            rows = self._online.rows if self._online else None
            learner, n = stored.learners_of(
                learned, shape, time, self.subgoals, self.potential, rows, self.keys.learner
            )
            return self._batch(shape, learner, n, obs, online=False)

        def advance(batch: BatchSetup, current: dict[str, torch.Tensor], step: StepInputs) -> Any:
            return self._advance(batch, current, step, learn=False)

        return stored.shape_stored(
            tensordict, self._env, self._settings, self.in_keys, self.transitions_key, set_up, advance
        )

    def kernel_state(self, tensordict: TensorDictBase) -> ShapingKernelState:
        """This transform for a compiled loop: its abstraction, its potential and each learner's abstract
        state as ``tensordict`` (a reset of the env through this transform) holds it, copied.

        Needs what the compiled step needs, and a subgoal series of regions (no conditions), a lookup or a
        region aggregation; anything else is a ``TypeError`` that says so.

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
        batch = setup.compiled_batch(self._online, self.backend, self.potential, self.value_update)
        root = tensordict.get(self._env.group) if self._env.group else tensordict
        state = (root.get(self.keys.index), root.get(self.keys.ret), root.get(self.keys.steps))
        return compiled.kernel_state(batch, state, self.learning, (self._layout or (1, False))[0])
