"""SubgoalPotentialTransform: potential-based shaping over a dynamic trajectory aggregation."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase
from tensordict.utils import NestedKey
from torchrl.data import Composite, TensorSpec
from torchrl.envs.transforms import Transform

from torchrl_subgoal.loss import ValueUpdate
from torchrl_subgoal.subgoals import StateAggregation, SubgoalSeries, SubgoalTables
from torchrl_subgoal.transform import keys, setup, stored
from torchrl_subgoal.transform.backends import Backend, batch_for
from torchrl_subgoal.transform.keys import EnvKeys, StepInputs, SubgoalKeys, read_step, write_step
from torchrl_subgoal.transform.setup import BatchSetup, Subgoals
from torchrl_subgoal.transform.shaping import StartPotential
from torchrl_subgoal.transform.transitions import rebuild

__all__ = ["SubgoalPotentialTransform"]


class SubgoalPotentialTransform(Transform):
    """Adds the shaping reward ``F = γ Φ(z') − Φ(z)`` of a subgoal series to any TorchRL env.

    Per env of the batch it keeps the abstract state of dynamic trajectory aggregation (Okudo & Yamada 2021),
    declared in the specs as observations and carried state (:class:`SubgoalKeys`; docs/torchrl.md lists them):
    ``z`` (the node of the series reached, advanced when the next subgoal holds), the SMDP return ``r_h`` and the
    steps ``k`` since ``z`` was entered, and what the potential reads. The reward, done and terminated entries are
    the parent env's, resolved as ``RewardSum`` and ``StepCounter`` resolve theirs (nested and multi-agent keys
    keep the state in the reward's group). Every step adds ``F`` to the reward and keeps the env's under
    ``"env_reward"``; with ``value_update`` it first trains the potential online on the SMDP transitions the step
    closes (the paper's algorithm). :meth:`transitions` rebuilds those of collected data for
    :class:`~torchrl_subgoal.SubgoalValueLoss`; ``transform(data)`` shapes stored trajectories without training.
    Policy invariance needs ``Φ`` to be a function of the agent's state: give the agent ``z`` too. A NaN or
    infinite reward, or a NaN observation, is a ``ValueError`` naming the entry. Append the transform to the
    *outer* env (``TransformedEnv(ParallelEnv(...), t)``), so that the potential trained is the one shaping.

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
        keys: the names of the entries written (:class:`SubgoalKeys`: the kept entries' prefix, which two
            transforms on one env need different, and where every step also writes its SMDP transition, if
            anywhere).

    :meth:`use_backend` picks how a step is shaped: ``"compiled"`` (numba kernels: a tabular or naive potential on
    the CPU; anything else is a ``TypeError`` saying why), ``"torch"`` (torch operations only: any potential, any
    device) or ``"auto"`` (the default: compiled when possible, numba being installed with the ``fast`` extra).
    Both agree.

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
        keys: SubgoalKeys | None = None,
    ) -> None:
        super().__init__()
        setup.check_options(gamma, start_potential)
        self.subgoals, self.keys = Subgoals(subgoals), keys if keys is not None else SubgoalKeys()
        setup.check_potential(potential, self.keys)
        self.potential = potential
        self._backend: Backend = "auto"  # see use_backend
        self.value_update = setup.online_update(value_update, potential, gamma)
        self._trained = list(potential.parameters())  # what the online update steps (read every step)
        self._settings = setup.settings(self.keys, potential, self.subgoals, gamma, self.value_update, observation_key,
                                        zero_terminal=zero_terminal_potential, start=start_potential)  # fmt: skip
        self._env = EnvKeys.resolve(None)
        self._online: BatchSetup | None = None
        self._layout: tuple[int, bool] | None = None

    # ------------------------------------------------------------------ what it keeps, reads and writes

    gamma = property(lambda self: self._settings.gamma, doc="The discount of the shaping term.")
    value_gamma = property(lambda self: self._settings.value_gamma, doc="The discount of the SMDP return.")
    observation_key = property(lambda self: self._settings.observation_key, doc="What the subgoals and anchor read.")
    zero_terminal_potential = property(lambda self: self._settings.zero_terminal, doc="``Φ = 0`` at terminal states.")
    start_potential = property(lambda self: self._settings.start, doc="The level of ``Φ``.")
    state_keys = property(lambda self: self._settings.kept, doc="The abstract-state entries kept (``subgoal_*``).")
    transitions_key = property(lambda self: self.keys.transitions, doc="Where each step's SMDP transition goes.")
    env_reward_key = property(lambda self: self._env.env_reward, doc="Where the unshaped reward is kept.")
    value_key = property(lambda self: self.potential.out_keys[-1], doc="The potential's value entry.")
    num_abstract_states = property(lambda self: self.subgoals.num_states, doc="Number of abstract states ``z``.")
    aggregation = property(lambda self: self.subgoals.aggregation, doc="The hand-given aggregation, if any.")

    @property
    def backend(self) -> Backend:
        """How a step is shaped: ``"auto"`` (default), ``"compiled"`` or ``"torch"`` (see the class)."""
        return self._backend

    def use_backend(self, backend: Backend) -> SubgoalPotentialTransform:
        """Shape with ``backend`` (see the class) from the next step on; returns the transform."""
        setup.check_backend(backend)
        self._backend, self._online = backend, None  # set up again at the next step
        return self

    @property
    def in_keys(self) -> list[NestedKey]:
        """The step's entries read: the reward, the done and terminated entries, the observation (when read)
        and an earlier shaping's env reward; the kept entries (:attr:`out_keys`) are read back at the root."""
        return keys.step_in_keys(self._env, self.observation_key if self._reads_observation else None)

    @in_keys.setter
    def in_keys(self, value: Any) -> None:  # Transform.__init__ sets None
        if value:
            raise AttributeError("SubgoalPotentialTransform's in_keys come from the parent env and observation_key")

    @property
    def out_keys(self) -> list[NestedKey]:
        """The step's entries written: the shaped reward, the env reward (unless an earlier shaping keeps it),
        the kept abstract state, and the transition entry with ``keys.transitions``."""
        return keys.step_out_keys(self._env, self.state_keys, self.transitions_key)

    @out_keys.setter
    def out_keys(self, value: Any) -> None:
        if value:
            raise AttributeError("SubgoalPotentialTransform's out_keys come from the parent env and the keys")

    @property
    def learning(self) -> bool:
        """Whether the potential is trained online: ``value_update`` was given and it is not frozen
        (freeze it with ``TabularPotential.freeze`` or ``transform.potential.requires_grad_(False)``)."""
        return self.value_update is not None and any(p.requires_grad for p in self._trained)

    @property
    def abstraction(self) -> SubgoalTables | StateAggregation | None:
        """The abstraction compiled for the env's batch (``None`` before the first reset)."""
        return self._online.abstraction if self._online is not None else None

    @property
    def env_batch(self) -> BatchSetup | None:
        """How the env's batch is set up (``None`` before the first reset): its :attr:`abstraction`, each
        row's learner, and the backend shaping it (with the potential as the kernels read it, compiled)."""
        return self._online

    @property
    def _reads_observation(self) -> bool:
        return self._settings.reads_observation or self.keys.anchor in self.state_keys

    # ------------------------------------------------------------------ set-up and specs

    def _batch(
        self, batch_shape: torch.Size, learner: torch.Tensor, n_learners: int, obs: torch.Tensor | None, online: bool
    ) -> BatchSetup:
        """Set up a batch whose rows belong to ``learner`` (``online``: the env's batch, in order)."""
        layout = self._layout  # the observation's entries and encoding: the env's spec's once known
        if layout is None:
            spec = keys.observation_of(self.parent, self.observation_key) if self._reads_observation else None
            layout = setup.observation_layout(spec, obs, batch_shape, self.subgoals)
            self._layout = layout if spec is not None else None
        return batch_for(self.subgoals, self.potential, self._settings, self.value_update, self.backend,
                         learner, n_learners, layout, obs, online)  # fmt: skip

    def _online_batch(self, batch_shape: torch.Size, obs: torch.Tensor | None) -> BatchSetup:
        batch = self._online  # set up again for another batch shape, or when a table moved (to shared memory…)
        if batch is None or batch.batch_shape != batch_shape or batch.stale(self.potential):
            n = batch_shape.numel()
            batch = self._online = self._batch(batch_shape, torch.arange(n).reshape(*batch_shape, 1), n, obs, True)
        return batch

    def _apply(self, fn: Any, recurse: bool = True) -> Any:  # .to(), .cuda(), .share_memory()...
        applied, self._online = super()._apply(fn, recurse), None  # set up again at the next step
        self._trained = list(self.potential.parameters())  # a move may replace them
        return applied

    def _kept_specs(self) -> dict[str, TensorSpec]:
        self._env = EnvKeys.resolve(self.parent)
        s = self._settings
        return keys.kept_specs(self.parent, self._env, self.keys, s.kept, self.num_abstract_states, s.observation_key)

    def transform_observation_spec(self, observation_spec: TensorSpec) -> TensorSpec:
        assert isinstance(observation_spec, Composite)
        s = self._settings
        read = s.observation_key if s.reads_observation else None
        specs = self._kept_specs()  # resolves the env keys first
        keys.declare_observations(observation_spec, self.parent, self._env, specs, read, s)
        return observation_spec

    def transform_input_spec(self, input_spec: TensorSpec) -> TensorSpec:
        # the kept entries are carried from step to step: state, as RewardSum's and StepCounter's are
        assert isinstance(input_spec, Composite)
        specs = self._kept_specs()  # resolves the env keys first
        keys.declare_state(input_spec, self.parent, self._env, specs)
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
        root = td.get(self._env.group) if self._env.group else td
        reset = root.get("_reset", None) if native else None
        if not native or reset is not None:
            obs = keys.read(td, self.observation_key)
            batch = self._online_batch(root.batch_size, obs)
            setup.write_start(td, root, reset, batch, self._settings, obs)
        return td

    def _step(self, tensordict: TensorDictBase, next_tensordict: TensorDictBase) -> TensorDictBase:
        # every env step comes here: entries are read and written unchecked (their shapes are the specs')
        env, settings = self._env, self._settings
        obs_key = settings.observation_key if settings.reads_observation else None
        before = settings.interpolate  # an interpolating potential reads the observation the step started from
        current, step, shape = read_step(tensordict, next_tensordict, env, settings.kept, obs_key, before)
        batch = self._online  # set up again for another batch shape, or when a table moved (to shared memory…)
        if batch is None or batch.batch_shape != shape or batch.stale(self.potential):
            batch = self._online_batch(shape, step.obs)
        out = batch.backend.step(batch, current, step, self.value_update is not None and self.learning)
        return write_step(next_tensordict, env, settings.kept, out, step.reward, self.transitions_key)

    def transitions(self, data: TensorDictBase) -> TensorDictBase:
        """The real SMDP transitions closed in collected ``data`` (any batch shape), as ``[N]``.

        Rebuilt from the kept entries: a step closes a transition when ``z`` changed or the episode ended. Rows
        keep the potential's inputs (with ``"subgoal_learner"``, a per-env table finds its row in a shuffled replay
        buffer), in the layout :class:`~torchrl_subgoal.SubgoalValueLoss` reads.

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
        """Shape stored trajectories ``[*B, T]`` (e.g. a replay-buffer sample) along their time dimension (named
        ``"time"``, as :meth:`~torchrl.envs.EnvBase.rollout` returns, or the last), without training: see
        :func:`~torchrl_subgoal.transform.stored.shape_stored` for what the data must hold and where the abstract
        state starts. Rows find their learner's table or pattern by ``"subgoal_learner"`` when learners have their
        own (else by the env batch's order); an empty sample is returned as it is.
        """

        def set_up(shape: torch.Size, learned: torch.Tensor | None, time: int, obs: torch.Tensor | None) -> BatchSetup:
            rows = self._online.rows if self._online else None
            learner, n = stored.learners_of(
                learned, shape, time, self.subgoals, self.potential, rows, self.keys.learner
            )
            return self._batch(shape, learner, n, obs, online=False)

        def advance(batch: BatchSetup, current: dict[str, torch.Tensor], step: StepInputs) -> Any:
            return batch.backend.step(batch, current, step, False)

        return stored.shape_stored(
            tensordict, self._env, self._settings, self.in_keys, self.transitions_key, set_up, advance
        )
