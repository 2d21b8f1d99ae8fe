"""SubgoalPotentialTransform: potential-based shaping over a dynamic trajectory aggregation."""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, Literal, NamedTuple

import numpy as np
import torch
from tensordict import TensorDict, TensorDictBase
from tensordict.nn import TensorDictModuleBase
from tensordict.utils import NestedKey
from torchrl.data import Binary, Bounded, Composite, OneHot, TensorSpec, Unbounded
from torchrl.envs.transforms import Transform

from torchrl_subgoal._kernels.shaping import (
    LOOKUP_SHAPING,
    NO_SHAPING,
    REGION_SHAPING,
    START_NONPOSITIVE,
    START_VALUE,
    START_ZERO,
    advance_and_shape,
    shape_step,
)
from torchrl_subgoal.loss import SubgoalValueLoss
from torchrl_subgoal.potentials import NaivePotential, TabularPotential, check_value
from torchrl_subgoal.subgoals import (
    RegionTables,
    State,
    StateAggregation,
    SubgoalSeries,
    SubgoalTables,
)

__all__ = ["AbstractStates", "PotentialKernelState", "ShapingKernelState", "SubgoalKeys", "SubgoalPotentialTransform"]

RETURN = "subgoal_return"
STEPS = "subgoal_steps"

StartPotential = Literal["value", "zero", "nonpositive"]
_START_MODES = {"value": START_VALUE, "zero": START_ZERO,
                "nonpositive": START_NONPOSITIVE}


@dataclass(frozen=True)
class SubgoalKeys:
    """Names of the abstract-state entries one transform keeps: ``f"{prefix}_{role}"``.

    Give a second transform on the same env another prefix (and its potential
    the matching keys) so that the two do not share entries.

    Examples:
        >>> SubgoalKeys("room").index
        'room_index'
    """

    prefix: str = "subgoal"

    @functools.cached_property
    def index(self) -> str:
        """``z``, the node of the subgoal series reached."""
        return f"{self.prefix}_index"

    @functools.cached_property
    def ret(self) -> str:
        """``r_h``, the discounted reward since ``z`` was entered."""
        return f"{self.prefix}_return"

    @functools.cached_property
    def steps(self) -> str:
        """``k``, the steps since ``z`` was entered."""
        return f"{self.prefix}_steps"

    @functools.cached_property
    def achieved(self) -> str:
        """Whether ``z`` was entered on this step."""
        return f"{self.prefix}_achieved"

    @functools.cached_property
    def anchor(self) -> str:
        """The observation at which ``z`` was entered."""
        return f"{self.prefix}_anchor"

    @functools.cached_property
    def learner(self) -> str:
        """Which env of the batch the row belongs to (its learner)."""
        return f"{self.prefix}_learner"

    @functools.cached_property
    def start(self) -> str:
        """The potential's input at reset (``z_0`` of an aggregation, ``o_0`` of a neural potential)."""
        return f"{self.prefix}_start"

    @functools.cached_property
    def optional(self) -> tuple[str, ...]:
        """The entries kept only when the potential reads them."""
        return (self.achieved, self.anchor, self.learner)


class PotentialKernelState(NamedTuple):
    """A tabular or naive potential and the transform's settings, as the compiled shaping step reads them
    (:func:`~torchrl_subgoal._kernels.shaping._shape_learner`).

    Examples:
        >>> from torchrl_subgoal import NaivePotential, SubgoalPotentialTransform
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> from torchrl.envs import TransformedEnv
        >>> shaping = SubgoalPotentialTransform(SubgoalSeries([State(3)]), NaivePotential(eta=2.0), gamma=0.9)
        >>> env = TransformedEnv(FourRoomsEnv(num_envs=2), shaping)
        >>> potential = shaping.kernel_state(env.reset()).potential
        >>> potential.table.shape, potential.eta, potential.gamma  # the naive potential has no table
        ((0, 1), 2.0, 0.9)
    """

    table: np.ndarray  #: ``[B or 1, Z]`` float32 view of the potential's table (updated in place); ``[0, 1]``: naive
    eta: float  #: the naive potential's ``η`` (``Φ = η`` once a subgoal is achieved)
    gamma: float  #: ``γ`` of the shaping term
    value_gamma: float  #: ``γ_v`` of the SMDP return
    value_lr: float  #: ``α_v`` of the online update (0: none)
    zero_terminal: bool  #: ``Φ = 0`` at a terminal state
    start_mode: int  #: ``START_VALUE``, ``START_ZERO`` or ``START_NONPOSITIVE``


class AbstractStates(NamedTuple):
    """Every learner's abstract-state entries as ``[N, 1]`` arrays (a compiled loop updates them in place).

    Examples:
        >>> AbstractStates.zeros(2).z.shape
        (2, 1)
    """

    z: np.ndarray  #: int64 abstract state of every learner
    achieved: np.ndarray  #: bool: the last step changed it
    r_h: np.ndarray  #: float32 discounted return since it was entered
    k: np.ndarray  #: int64 steps since it was entered
    z_start: np.ndarray  #: int64 abstract state the episode started in

    @classmethod
    def zeros(cls, n: int) -> AbstractStates:
        """Every learner in ``z = 0`` at the start of an episode."""
        return cls(np.zeros((n, 1), np.int64), np.zeros((n, 1), np.bool_), np.zeros((n, 1), np.float32),
                   np.zeros((n, 1), np.int64), np.zeros((n, 1), np.int64))


class ShapingKernelState(NamedTuple):
    """The shaping transform for a compiled loop: its abstraction, its potential and every learner's
    abstract state (``[N, 1]`` arrays, updated in place), from :meth:`SubgoalPotentialTransform.kernel_state`.

    A loop advances a learner with :func:`~torchrl_subgoal._kernels.regions.region_search` (or ``lookup``),
    shapes its reward with :func:`~torchrl_subgoal._kernels.shaping.shaping_step` and carries its state over (or resets it to
    :func:`~torchrl_subgoal._kernels.shaping.shaping_start`'s) with :func:`~torchrl_subgoal._kernels.shaping.shaping_carry`.

    Examples:
        >>> state = ShapingKernelState.unshaped(3)
        >>> state.kind == NO_SHAPING, state.learners.z.shape
        (True, (3, 1))
    """

    kind: int  #: ``NO_SHAPING``, ``REGION_SHAPING`` (subgoal series, region aggregation) or ``LOOKUP_SHAPING``
    regions: RegionTables  #: the regions (``REGION_SHAPING``)
    lookup: np.ndarray  #: ``[S]`` abstract state of every state number (``LOOKUP_SHAPING``)
    potential: PotentialKernelState
    learners: AbstractStates  #: every learner's abstract state

    @classmethod
    def unshaped(cls, n: int) -> ShapingKernelState:
        """No shaping, for ``n`` learners (a bare env)."""
        empty3 = np.zeros((1, 1, 1), np.float32)
        regions = RegionTables(np.zeros(0, np.int64), empty3, empty3, empty3, empty3, np.zeros((1, 1), np.float32),
                               np.zeros((1, 1, 1), np.bool_), 1)
        potential = PotentialKernelState(_NO_TABLE, 0.0, 0.0, 0.0, 0.0, False, START_VALUE)
        return cls(NO_SHAPING, regions, np.zeros(1, np.int64), potential, AbstractStates.zeros(n))


@dataclass
class _Setup:
    """What shaping a batch of a given shape needs: the compiled abstraction, each row's learner,
    and the potential as the fused kernels read it (``table`` rows align with the batch's rows)."""

    batch_shape: torch.Size
    abstraction: SubgoalTables | StateAggregation
    learner: torch.Tensor  # [*B, 1] long
    table: np.ndarray | None  # None: not fusable (neural potential, conditions, not CPU)
    shared: bool = False
    eta: float = 0.0
    regions: RegionTables | None = None  # a SubgoalTables' regions as the kernel reads them (looked up once)
    z_start: np.ndarray = field(default_factory=lambda: np.zeros((1, 1), np.int64))

    def __post_init__(self) -> None:
        abstraction = self.abstraction
        if isinstance(abstraction, SubgoalTables):
            self.regions = abstraction.kernel_state()
        # a subgoal series starts every episode in z = 0: the kernels' z_0 column, allocated once
        self.z_start = np.zeros((max(1, self.batch_shape.numel()), 1), np.int64)


class SubgoalPotentialTransform(Transform):
    """Adds the shaping reward ``F = γ Φ(z') − Φ(z)`` of a subgoal series to any TorchRL env.

    The transform keeps, per env of the batch, the abstract state of dynamic
    trajectory aggregation (Okudo & Yamada 2021) in the TensorDict (names with
    the default ``prefix="subgoal"``):

    * ``"subgoal_index"`` ``z`` — the node of the subgoal series reached
      (``0`` at reset; advanced when the next subgoal's predicate holds);
    * ``"subgoal_return"`` ``r_h ← r_h + γ_v^k r`` and ``"subgoal_steps"``
      ``k ← k + 1`` since ``z`` was entered;
    * only when the potential reads them: ``"subgoal_achieved"`` (``z`` was
      entered on this step, for :class:`~torchrl_subgoal.NaivePotential`),
      ``"subgoal_anchor"`` (the observation at which ``z`` was entered, for
      :class:`~torchrl_subgoal.NeuralPotential`) and ``"subgoal_learner"``
      (the env's index in the batch, for a per-env
      :class:`~torchrl_subgoal.TabularPotential`).

    Every step it adds ``F`` to the reward; the environment's reward stays
    under ``"env_reward"``, declared as a second reward entry (so use
    ``env.reward_keys``). When a subgoal is achieved or the episode ends, the
    step closes one SMDP transition ``(z, r_h, k, z', terminated)``:
    :meth:`transitions` returns those of collected data (any batch shape) in
    the layout :class:`~torchrl_subgoal.SubgoalValueLoss` and TorchRL's TD(0)
    estimator read, rebuilt from the kept entries — nothing extra is written
    per step (``write_transitions=True`` also writes every step's entry under
    ``("next", "smdp")``, with ``mask`` telling which are real). At truncation
    the transition bootstraps from ``V(z')``.

    **Shaping and learning are separate.** The shaping step is pure: it uses
    the potential *as it is now* (a dynamic potential) and never changes it.
    With ``value_lr`` set, the env step also trains the potential online, one
    SGD step of :class:`~torchrl_subgoal.SubgoalValueLoss` on this step's
    transitions *before* shaping (the paper's algorithm: update ``V``, then
    shape with it). Otherwise train it yourself from ``data["next", "smdp"]``
    with the same loss. Freeze a trained potential with
    ``transform.potential.requires_grad_(False)``.

    On the eager path (a neural potential, conditions, a device) the step does
    not evaluate ``Φ(z)`` again when ``z``'s entries and the potential's
    parameters and buffers equal those of the previous step's ``Φ(z')``
    (compared by value, so ``.data`` writes and shared-memory updates from other
    processes are seen), nor ``Φ(z_0)`` within an episode: the potential must be
    a deterministic function of its inputs and those tensors (no dropout).

    **Stored data.** Calling the transform on a TensorDict (``transform(data)``,
    e.g. a replay-buffer sample ``[*B, T]``) recomputes the abstract state and
    the shaping along the time dimension from the stored observations, for
    any batch shape, without training and without touching the env's set-up.
    A row's learner (its table and pattern) is read from ``"subgoal_learner"``
    when the data has it.

    Policy invariance (Ng et al. 1999) needs ``Φ`` to be a function of the
    *agent's* state. ``z`` depends on the episode's history, so an agent that
    sees only ``s`` (as in the paper) may learn a greedy policy that cycles
    across a subgoal; give the agent ``z`` too for the exact guarantee once
    ``Φ`` is fixed.

    A NaN or infinite reward, or a NaN in the observation, raises ``ValueError``
    naming the entry and the env (it would make the potential NaN for good);
    ``±inf`` in an observation compares as a number. Both the compiled and the
    torch path behave so.

    Append it to the *outer* env (``TransformedEnv(ParallelEnv(...), t)``) so
    that the potential being trained is the one used for shaping; for envs in
    collector worker processes see :mod:`torchrl_subgoal.training` (shared
    potentials).

    Args:
        subgoals: a :class:`SubgoalSeries` shared by every env of the batch; a
            sequence of series, one per env (flattened batch order) or indexed
            by ``pattern_index``; or a :class:`StateAggregation` ``z = g(s)``
            (the SARSA-RS baseline).
        potential: ``Φ`` — :class:`TabularPotential`, :class:`NeuralPotential`,
            :class:`NaivePotential`, or any TensorDict module reading entries
            this transform keeps and writing one value entry.

    Keyword Args:
        gamma: the agent's discount ``γ`` in ``F = γ Φ(z') − Φ(z)``.
        observation_key: the observation the built-in (region) predicates read.
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
        start_potential: the level of ``Φ``, set by the potential of the
            abstract state ``z_0`` the episode started in (``0`` for a subgoal
            series; for a :class:`StateAggregation` and for a potential reading
            the anchor the transform keeps the potential's input at reset under
            ``"subgoal_start"``). ``"value"``: ``Φ = V``; ``"zero"``:
            ``Φ = V − V(z_0)``; ``"nonpositive"`` (the default):
            ``Φ = V − max(V(z_0), 0)``, so ``Φ(z_0) = min(V(z_0), 0)``. With
            ``zero_terminal_potential`` a constant shift of ``Φ`` keeps the
            optimal policy, but it acts like shifting the learner's initial
            values (Wiewiora 2003): ``"nonpositive"`` keeps a zero-initialised
            learner's start values neither optimistic under step costs nor
            stripped of the goal's value under goal rewards (measured in
            ``docs/shaping_defaults.md``). A :class:`NaivePotential` has
            ``Φ(z_0) = 0`` already. ``V`` itself is trained unshifted.
        env_reward_key: where the unshaped reward is kept. If an earlier
            transform already keeps it there, ``r_h`` accumulates that entry
            and it is left alone.
        transitions_key: where the SMDP transitions are written in ``"next"``
            with ``write_transitions``.
        write_transitions: also write every step's SMDP transition entry (a
            nested TensorDict, padding on most steps). Defaults to ``False``:
            :meth:`transitions` rebuilds the real ones from the kept entries of
            collected data at no per-step cost.
        done_key: the env's done entry (``"next"`` of a step).
        terminated_key: the env's terminated entry (defaults to ``done`` when absent).
        prefix: the names of the kept entries (see :class:`SubgoalKeys`); the
            potential must read entries with the same prefix.
        anchor_key: the observation snapshotted as the anchor; defaults to
            ``observation_key``.

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
        reward_key: NestedKey = "reward",
        pattern_index: torch.Tensor | None = None,
        value_lr: float | None = None,
        value_gamma: float | None = None,
        zero_terminal_potential: bool = True,
        start_potential: StartPotential = "nonpositive",
        env_reward_key: NestedKey = "env_reward",
        transitions_key: NestedKey = "smdp",
        write_transitions: bool | None = None,
        done_key: NestedKey = "done",
        terminated_key: NestedKey = "terminated",
        prefix: str = "subgoal",
        anchor_key: NestedKey | None = None,
    ) -> None:
        anchor_key = observation_key if anchor_key is None else anchor_key
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
        if pattern_index is not None and patterns is not None and pattern_index.numel() and (
            int(pattern_index.min()) < 0 or int(pattern_index.max()) >= len(patterns)
        ):
            raise ValueError(f"pattern_index values must lie in [0, {len(patterns)})")
        self.patterns = patterns
        self.pattern_index = pattern_index
        self.keys = SubgoalKeys(prefix)
        self.potential = potential
        self._check_potential_keys()
        self.gamma = float(gamma)
        self.value_gamma = float(value_gamma)
        self.observation_key = observation_key
        self.anchor_key = anchor_key
        self.reward_key = reward_key
        self.env_reward_key = env_reward_key
        self.done_key = done_key
        self.terminated_key = terminated_key
        if write_transitions is None:
            write_transitions = False
        self.transitions_key: NestedKey | None = transitions_key if write_transitions else None
        self.zero_terminal_potential = zero_terminal_potential
        if start_potential not in _START_MODES:
            raise ValueError(f"start_potential must be one of {sorted(_START_MODES)}, got {start_potential!r}")
        self.start_potential = start_potential
        self._start_mode = _START_MODES[start_potential]
        keys = self.keys
        extra = tuple(k for k in keys.optional if k in self.potential.in_keys)
        # Φ(z_0) needs the potential's input at reset, unless it is z = 0 (every subgoal series starts there)
        reads = self.potential.in_keys
        if start_potential != "value" and not isinstance(self.potential, NaivePotential) and (
            keys.anchor in reads or (self.aggregation is not None and keys.index in reads)
        ):
            extra = (*extra, keys.start)
        self._state_keys: tuple[str, ...] = (keys.index, keys.ret, keys.steps, *extra)
        # which optional entries are kept, looked up once (every env step reads them)
        self._keeps_achieved, self._keeps_anchor, self._keeps_learner, self._keeps_start = (
            k in self._state_keys for k in (keys.achieved, keys.anchor, keys.learner, keys.start))
        self._phi_cache = _ValueCache()
        self._parameters_list = list(potential.parameters())
        self.value_loss: SubgoalValueLoss | None = None
        self.value_optimizer: torch.optim.Optimizer | None = None
        if value_lr is not None:
            self.value_loss = SubgoalValueLoss(potential, gamma=self.value_gamma)
            self.value_optimizer = torch.optim.SGD(potential.parameters(), lr=value_lr)
        self._value_lr = float(value_lr) if value_lr is not None else 0.0
        self._has_value_lr = value_lr is not None
        self._online: _Setup | None = None
        self._layout: tuple[int, bool] | None = None
        # the last fused step's z', r_h', k' outputs: (tensor, its numpy view, its data pointer) each
        self._last_outputs: tuple[tuple[torch.Tensor, np.ndarray, int], ...] = ()
        self._table_ptr = 0

    # ------------------------------------------------------------------ set-up

    def _check_potential_keys(self) -> None:
        pot = self.potential
        if not isinstance(pot, TensorDictModuleBase) or not pot.out_keys:
            raise TypeError(
                "the potential must be a TensorDict module whose (last) output entry is the value (a Potential, or e.g. "
                f"TensorDictModule(net, in_keys=[{self.keys.anchor!r}], out_keys=['subgoal_value'])), "
                f"got {type(pot).__name__}"
            )
        provided = (self.keys.index, *self.keys.optional)
        unknown = [k for k in pot.in_keys if k not in provided]
        if unknown:
            raise ValueError(
                f"the potential reads {unknown}, which this transform does not keep; it keeps "
                f"{list(provided)} (prefix {self.keys.prefix!r}): build the potential with those keys"
            )

    @property
    def value_key(self) -> NestedKey:
        """The potential's value entry (its last output entry)."""
        return self.potential.out_keys[-1]

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

    @property
    def abstraction(self) -> SubgoalTables | StateAggregation | None:
        """The abstraction compiled for the env's batch (``None`` before the first reset)."""
        return self._online.abstraction if self._online is not None else None

    @property
    def _uses_observation(self) -> bool:
        """Whether ``observation_key`` is read (an aggregation or a region predicate); cached."""
        uses = self.__dict__.get("_uses_observation_cache")
        if uses is None:
            uses = self.aggregation is not None or any(
                pred.compiled for p in self.patterns or () for pred in p.predicates
            )
            self.__dict__["_uses_observation_cache"] = uses
        return uses

    def _observation_spec(self, key: NestedKey) -> TensorSpec | None:
        parent = self.parent
        if parent is None:
            return None
        obs_spec = parent.full_observation_spec
        if key not in obs_spec.keys(True, True):
            raise KeyError(
                f"{type(self).__name__}: {key!r} is not an observation of the env (observation_key or "
                f"anchor_key); available: {sorted(map(str, obs_spec.keys(True, True)))}"
            )
        return obs_spec[key]

    def _observation_layout(self, obs: torch.Tensor | None, batch_shape: torch.Size) -> tuple[int, bool]:
        """(entries per observation, one-hot?): from the env's spec once known, else from the data.

        Without a spec a :class:`State` predicate reads an observation of more
        than one entry as one-hot (a categorical state is a single entry).
        """
        if self._layout is not None:
            return self._layout
        spec = self._observation_spec(self.observation_key)
        if spec is not None:
            shape = spec.shape[len(batch_shape):]
            self._layout = (int(shape.numel()) if len(shape) else 1), isinstance(spec, OneHot)
            return self._layout
        if obs is None:
            return 0, False
        shape = obs.shape[len(batch_shape):]
        size = int(shape.numel()) if len(shape) else 1
        states = self.patterns is not None and any(
            isinstance(pred, State) for p in self.patterns for pred in p.predicates
        )
        return size, states and size > 1

    def _patterns_of_learners(self, n_learners: int) -> torch.Tensor:
        """The pattern each learner (env of the online batch, flattened) follows."""
        assert self.patterns is not None
        if self.pattern_index is not None:
            if self.pattern_index.numel() != n_learners:
                raise ValueError(f"pattern_index has {self.pattern_index.numel()} entries for {n_learners} envs")
            return self.pattern_index.reshape(-1).long()
        if len(self.patterns) == 1:
            return torch.zeros(n_learners, dtype=torch.long)
        if len(self.patterns) == n_learners:
            return torch.arange(n_learners)
        raise ValueError(
            f"{len(self.patterns)} subgoal series for a batch of {n_learners} envs: give one series, "
            "one per env, or pattern_index"
        )

    def kernel_state(self, tensordict: TensorDictBase) -> ShapingKernelState:
        """This transform for a compiled loop: its abstraction, its potential and each learner's abstract
        state as ``tensordict`` (a reset of the env through this transform) holds it, copied.

        Needs the CPU, a subgoal series (regions only, no conditions), a lookup or a region aggregation, and
        a tabular or naive potential; anything else is a ``TypeError`` that says so.

        Examples:
            >>> from torchrl_subgoal import TabularPotential
            >>> from torchrl_subgoal.envs import FourRoomsEnv
            >>> from torchrl.envs import TransformedEnv
            >>> shaping = SubgoalPotentialTransform(SubgoalSeries([State(3), State(7)]), TabularPotential(3, [2]),
            ...                                     gamma=0.9, value_lr=0.1)
            >>> env = TransformedEnv(FourRoomsEnv(num_envs=2), shaping)
            >>> state = shaping.kernel_state(env.reset())
            >>> state.kind == REGION_SHAPING, state.potential.table.shape, state.potential.value_lr
            (True, (2, 3), 0.1)
        """
        abstraction = self.abstraction
        if abstraction is None:
            raise TypeError("kernel_state needs the env reset through the transform first (env.reset())")
        n = self._online.batch_shape.numel() if self._online is not None else 0
        lookup = np.zeros(1, np.int64)
        regions = ShapingKernelState.unshaped(0).regions
        if isinstance(abstraction, SubgoalTables):
            if not abstraction.fusable:
                raise TypeError("a compiled loop advances subgoal regions, not conditions")
            kind, regions = REGION_SHAPING, abstraction.kernel_state()
        elif isinstance(abstraction.mapping, torch.Tensor):
            kind, lookup = LOOKUP_SHAPING, abstraction.mapping.numpy()
        elif abstraction.regions is not None:
            kind, regions = REGION_SHAPING, abstraction.regions
        else:
            raise TypeError("a compiled loop needs a subgoal series, a lookup or a region aggregation, "
                            "not a function aggregation")
        pot = self.potential
        table, eta = _NO_TABLE, 0.0
        if isinstance(pot, TabularPotential):
            if pot.table.device.type != "cpu":
                raise TypeError(f"a compiled loop reads the potential's table on the CPU, not {pot.table.device}")
            table = pot.table.detach().numpy().reshape(-1, pot.num_states)
        elif isinstance(pot, NaivePotential):
            eta = pot.eta
        else:
            raise TypeError(f"a compiled loop shapes with tabular or naive potentials, not {type(pot).__name__}")
        potential = PotentialKernelState(table, eta, self.gamma, self.value_gamma,
                                         self._value_lr if self.learning else 0.0, self.zero_terminal_potential,
                                         self._start_mode)
        keys = self.keys
        z, r_h, k = (tensordict.get(name).reshape(n, 1).numpy().copy() for name in (keys.index, keys.ret, keys.steps))
        # both envs of the fused engine start every episode in the same place
        return ShapingKernelState(kind, regions, lookup, potential,
                                  AbstractStates(z, np.zeros((n, 1), np.bool_), r_h, k, z.copy()))

    def _check_potential(self, n_learners: int) -> None:
        pot = self.potential
        if isinstance(pot, TabularPotential):
            if pot.batch_shape and pot.learners != n_learners:
                raise ValueError(
                    f"TabularPotential has batch_shape {tuple(pot.batch_shape)} but the env batch has "
                    f"{n_learners} envs: use one table per env or a shared one (batch_shape=())"
                )
            if pot.num_states < self.num_abstract_states:
                raise ValueError(
                    f"TabularPotential has {pot.num_states} states; the abstraction has "
                    f"{self.num_abstract_states}"
                )

    def _compile(
        self, batch_shape: torch.Size, learner: torch.Tensor, obs: torch.Tensor | None, n_learners: int
    ) -> _Setup:
        """Compile the abstraction for a batch whose rows belong to ``learner`` (``[*B, 1]``)."""
        self._check_potential(n_learners)
        abstraction: SubgoalTables | StateAggregation
        if self.aggregation is not None:
            abstraction = self.aggregation
        else:
            size, one_hot = self._observation_layout(obs, batch_shape)
            patterns = self._patterns_of_learners(n_learners)[learner.reshape(-1)].reshape(batch_shape)
            assert self.patterns is not None
            abstraction = SubgoalTables(
                self.patterns, patterns, size, one_hot=one_hot, observation_key=str(self.observation_key)
            )
        return _Setup(batch_shape, abstraction, learner, None)

    def _fused_potential(self, setup: _Setup, online: bool) -> None:
        """Fill ``setup.table`` with the potential as the kernels read it, when they can."""
        pot = self.potential
        setup.table = None
        if not setup.abstraction.fusable:
            return
        if isinstance(pot, NaivePotential):
            setup.table, setup.eta = _NO_TABLE, pot.eta
        elif isinstance(pot, TabularPotential) and pot.table.device.type == "cpu":
            table = pot.table.detach().numpy().reshape(pot.learners, pot.num_states)
            setup.shared = not pot.batch_shape
            if not setup.shared and not online:  # rows of stored data: each row's learner's table (a copy)
                table = np.ascontiguousarray(table[setup.learner.reshape(-1).numpy()])
            setup.table = table
            if online:
                self._table_ptr = pot.table.data_ptr()

    def _online_setup(self, batch_shape: torch.Size, obs: torch.Tensor | None) -> _Setup:
        """The env batch's set-up: compiled at the first reset, kept for every step."""
        setup = self._online
        if setup is None or setup.batch_shape != batch_shape:
            n = batch_shape.numel()
            learner = torch.arange(n).reshape(*batch_shape, 1)
            setup = self._online = self._compile(batch_shape, learner, obs, n)
            self._fused_potential(setup, online=True)
        elif isinstance(self.potential, TabularPotential) and self.potential.table.data_ptr() != self._table_ptr:
            self._fused_potential(setup, online=True)  # the table moved (to shared memory, a device…)
        return setup

    # ------------------------------------------------------------------ specs

    @property
    def state_keys(self) -> tuple[str, ...]:
        """Abstract-state entries kept in the TensorDict (``"subgoal_*"``)."""
        return self._state_keys

    def _state_specs(self, batch_shape: torch.Size, observation_spec: Composite) -> dict[str, TensorSpec]:
        shape = (*batch_shape, 1)
        keys = self.keys
        specs: dict[str, TensorSpec] = {
            keys.index: Bounded(0, self.num_abstract_states - 1, shape=shape, dtype=torch.long),
            keys.ret: Unbounded(shape=shape, dtype=torch.float32),
            keys.steps: Unbounded(shape=shape, dtype=torch.long),
        }
        if keys.achieved in self.state_keys:
            specs[keys.achieved] = Binary(n=1, shape=shape, dtype=torch.bool)
        if keys.learner in self.state_keys:
            specs[keys.learner] = Bounded(0, max(batch_shape.numel() - 1, 0), shape=shape, dtype=torch.long)
        if keys.anchor in self.state_keys:
            if self.anchor_key not in observation_spec.keys(True, True):
                raise KeyError(
                    f"{type(self).__name__}: anchor_key {self.anchor_key!r} is not an observation of the env; "
                    f"available: {sorted(map(str, observation_spec.keys(True, True)))}"
                )
            anchor = observation_spec[self.anchor_key].shape[len(batch_shape):]
            size = int(anchor.numel()) if len(anchor) else 1
            specs[keys.anchor] = Unbounded(shape=(*batch_shape, size), dtype=torch.float32)
        if keys.start in self.state_keys:  # what the potential reads at reset: the anchor or z_0
            specs[keys.start] = specs[keys.anchor if keys.anchor in self.state_keys else keys.index].clone()
        return specs

    def transform_observation_spec(self, observation_spec: TensorSpec) -> TensorSpec:
        assert isinstance(observation_spec, Composite)
        batch_shape = observation_spec.shape
        if self._uses_observation and self.observation_key not in observation_spec.keys(True, True):
            raise KeyError(
                f"{type(self).__name__}: observation_key {self.observation_key!r} is not an observation "
                f"of the env; available: {sorted(map(str, observation_spec.keys(True, True)))}"
            )
        states = self._state_specs(batch_shape, observation_spec)
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
        if self.env_reward_key not in reward_spec.keys(True, True):
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

    def _initial_state(self, setup: _Setup, root: TensorDictBase) -> dict[str, torch.Tensor]:
        """The abstract state at a reset observation (``root`` holds the reset entries)."""
        batch_shape = setup.batch_shape
        shape = (*batch_shape, 1)
        keys = self.keys
        obs = root.get(self.observation_key, None) if self._uses_observation else None
        state = {
            keys.index: setup.abstraction.initial(obs, batch_shape),
            keys.ret: torch.zeros(shape),
            keys.steps: torch.zeros(shape, dtype=torch.long),
        }
        if keys.achieved in self.state_keys:
            state[keys.achieved] = torch.zeros(shape, dtype=torch.bool)
        if keys.anchor in self.state_keys:
            state[keys.anchor] = self._flat_obs(root.get(self.anchor_key), batch_shape)
        if keys.learner in self.state_keys:
            state[keys.learner] = setup.learner
        if keys.start in self.state_keys:
            state[keys.start] = state[keys.anchor if keys.anchor in self.state_keys else keys.index]
        return state

    def _reset(self, tensordict: TensorDictBase, tensordict_reset: TensorDictBase) -> TensorDictBase:
        # Values for every env; TorchRL keeps the old ones where "_reset" is False.
        batch_shape = tensordict_reset.batch_size
        obs = tensordict_reset.get(self.observation_key, None) if self._uses_observation else None
        setup = self._online_setup(batch_shape, obs)
        state = self._initial_state(setup, tensordict_reset)
        outputs: dict[str, Any] = dict(state)
        if self.transitions_key is not None:
            zero = torch.zeros((*batch_shape, 1))
            false = torch.zeros((*batch_shape, 1), dtype=torch.bool)
            inputs = {k: state[k] for k in self.potential.in_keys}
            outputs[self.transitions_key] = _transition(
                batch_shape, inputs, inputs, zero, state[self.keys.steps], false, false, false
            )
        tensordict_reset.update(outputs)
        return tensordict_reset

    def _step(self, tensordict: TensorDictBase, next_tensordict: TensorDictBase) -> TensorDictBase:
        batch_shape = next_tensordict.batch_size
        obs = next_tensordict.get(self.observation_key, None) if self._uses_observation else None
        setup = self._online_setup(batch_shape, obs)
        current = {}
        for key in self.state_keys:
            value = tensordict.get(key, None)
            if value is None:
                raise KeyError(f"{type(self).__name__}: {key!r} is missing from the step's input: reset the env "
                               "through the transform (env.reset()) before stepping")
            current[key] = value
        out = self._advance(setup, current, next_tensordict, obs, learn=self.learning)
        for key, value in out.items():  # entry by entry: cheaper than update() for a handful of entries
            next_tensordict.set(key, value)
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
        """One env step of aggregation and shaping on tensors (what ``_step`` does on TensorDicts).

        ``current`` holds the abstract-state entries before the step; ``abstraction``
        is compiled for ``batch_shape`` (rows in env order). With ``value_lr`` the
        online update runs first. Returns the entries of the next TensorDict.

        Raises:
            ValueError: a reward is NaN or infinite, or the observation holds a NaN
                (either would make the potential NaN for good); nothing is updated.
        """
        n = batch_shape.numel()
        setup = _Setup(batch_shape, abstraction, torch.arange(n).reshape(*batch_shape, 1), None)
        self._fused_potential(setup, online=True)
        nxt = TensorDict({self.observation_key: obs, self.reward_key: reward, self.done_key: done,
                          self.terminated_key: terminated}, batch_size=batch_shape)
        return self._advance(setup, dict(current), nxt, obs, learn=self.learning)

    def _rewards(self, nxt: TensorDictBase) -> tuple[torch.Tensor, torch.Tensor]:
        """(the reward to shape, the env reward that ``r_h`` accumulates)."""
        reward = nxt.get(self.reward_key)
        env_reward = nxt.get(self.env_reward_key, None)
        return reward, (reward if env_reward is None else env_reward)

    def _advance(
        self, setup: _Setup, current: dict[str, torch.Tensor], nxt: TensorDictBase, obs: torch.Tensor | None,
        *, learn: bool,
    ) -> dict[str, Any]:
        """One step of aggregation and shaping from ``current`` with the step's ``nxt`` entries (``obs``:
        its ``observation_key`` entry, when read); with ``learn``, the online update of the potential
        first. Returns the next entries."""
        if self._uses_observation and obs is None:
            raise KeyError(f"{type(self).__name__}: the step has no {self.observation_key!r} entry")
        reward, env_reward = self._rewards(nxt)
        done = nxt.get(self.done_key)
        terminated = nxt.get(self.terminated_key, done)
        z = current[self.keys.index]
        if self._keeps_learner:
            current.setdefault(self.keys.learner, setup.learner)
        if setup.table is not None and (obs is None or obs.device.type == "cpu") and z.device.type == "cpu":
            if not (setup.regions is not None and reward is env_reward):  # else the kernel checks (and calls this if wrong)
                _check_finite(reward, obs, self.reward_key, self.observation_key)
            return self._advance_fused(setup, current, obs, reward, env_reward, done, terminated, learn)
        _check_finite(reward, obs, self.reward_key, self.observation_key)
        z_next = setup.abstraction.advance(z, obs, nxt)
        return self._shape_eager(setup, current, z_next, nxt, reward, env_reward, done, terminated, learn)

    def _advance_fused(
        self,
        setup: _Setup,
        current: dict[str, torch.Tensor],
        obs: torch.Tensor | None,
        reward: torch.Tensor,
        env_reward: torch.Tensor,
        done: torch.Tensor,
        terminated: torch.Tensor,
        learn: bool,
    ) -> dict[str, Any]:
        assert setup.table is not None and obs is not None
        keys = self.keys
        n = setup.batch_shape.numel()
        if not setup.shared and setup.table.shape[0] not in (0, n):
            raise ValueError(f"the potential has {setup.table.shape[0]} tables for a batch of {n} rows")
        z, r_h, k = current[keys.index], current[keys.ret], current[keys.steps]
        key = self.transitions_key
        z_next, rh_out, k_out, shaped = _empty_like(z), _empty_like(r_h), _empty_like(k), _empty_like(reward)
        extra: tuple[np.ndarray, ...]
        if key is not None:  # the kernel also fills the SMDP transition's r_h, k and mask
            rh_acc, k_acc, emit = _empty_like(r_h), _empty_like(k), _empty_like(done)
            extra = (rh_acc[1], k_acc[1], emit[1])
        else:
            extra = _NO_TRANSITION
        potential = PotentialKernelState(setup.table, setup.eta, self.gamma, self.value_gamma,
                                         self._value_lr if learn else 0.0, self.zero_terminal_potential,
                                         self._start_mode)
        # the step's z, r_h and k are usually last step's outputs (TorchRL moves them from "next" to the root):
        # their numpy views are kept, which saves the tensor-to-numpy crossings
        # (in line: this runs every step) a view is reused only while its tensor is on the same memory
        kept = self._last_outputs
        if kept:
            (zt, za, zp), (rt, ra, rp), (kt, ka, kp) = kept
            z_col = za if zt is z and z.data_ptr() == zp else _col(z, n, keys.index)
            rh_col = ra if rt is r_h and r_h.data_ptr() == rp else _col(r_h, n, keys.ret)
            k_col = ka if kt is k and k.data_ptr() == kp else _col(k, n, keys.steps)
        else:
            z_col, rh_col, k_col = _col(z, n, keys.index), _col(r_h, n, keys.ret), _col(k, n, keys.steps)
        reward_col = _col(env_reward, n, "env reward")
        start = _col(current[keys.start], n, keys.start) if keys.start in current else setup.z_start
        shaping = (
            _col(current[keys.achieved], n, keys.achieved) if keys.achieved in current else z_col,
            rh_col, k_col, reward_col, _col(done, n, "done"), _col(terminated, n, "terminated"), start,
        )
        if setup.regions is not None:
            rows = setup.abstraction.rows(obs).numpy()  # type: ignore[union-attr]
            if not advance_and_shape(setup.regions, potential, setup.shared, z_col, rows, *shaping,
                                              z_next[1], rh_out[1], k_out[1], shaped[1], *extra):
                _check_finite(reward, obs, self.reward_key, self.observation_key)  # raises, naming the entry
                raise ValueError(f"SubgoalPotentialTransform: {self.reward_key!r} is not finite or "
                                 f"{self.observation_key!r} holds a NaN")
        else:
            z_next = (setup.abstraction.advance(z, obs), np.empty(0))
            shape_step(potential, setup.shared, z_col, _col(z_next[0], n, "z'"), *shaping, rh_out[1],
                                k_out[1], shaped[1], *extra)
        if reward is not env_reward:  # a second transform: shape the (already shaped) reward, accumulate r
            shaped[1][:] += _col(reward, n, "reward") - reward_col
        out: dict[str, Any] = {
            keys.index: z_next[0], keys.ret: rh_out[0], keys.steps: k_out[0], self.reward_key: shaped[0],
        }
        if setup.regions is not None:
            self._last_outputs = ((z_next[0], z_next[1], z_next[0].data_ptr()), (rh_out[0], rh_out[1], rh_out[0].data_ptr()),
                                  (k_out[0], k_out[1], k_out[0].data_ptr()))
        if reward is env_reward:
            out[self.env_reward_key] = reward
        if self._keeps_achieved:
            out[keys.achieved] = z_next[0] != z
        if self._keeps_learner:
            out[keys.learner] = current[keys.learner]
        if self._keeps_start:
            out[keys.start] = current[keys.start]
        if key is not None:
            in_keys = self.potential.in_keys
            inputs = {name: current[name] for name in in_keys}
            next_inputs = {name: out[name] for name in in_keys}
            out[key] = _transition(setup.batch_shape, inputs, next_inputs, rh_acc[0], k_acc[0], emit[0], done,
                                   terminated)
        return out

    def _value(
        self, entries: dict[str, torch.Tensor], batch_shape: torch.Size, slot: str | None = None
    ) -> torch.Tensor:
        """``Φ`` of abstract-state entries, ``[*B, 1]``.

        With ``slot``, the value is remembered under it with the entries, and given back without
        evaluating the potential while they are unchanged (``_phi_cache.check`` first, once per step).
        """
        inputs = {k: entries[k] for k in self.potential.in_keys}
        if slot is not None:
            cached = self._phi_cache.get(slot, inputs)
            if cached is not None:
                return cached
        td = TensorDict(inputs, batch_size=batch_shape)
        value = check_value(self.potential(td).get(self.value_key), batch_shape,
                            f"the potential {type(self.potential).__name__}")
        if slot is not None:
            self._phi_cache.put(slot, inputs, value)
        return value

    def _start_entries(self, current: dict[str, torch.Tensor]) -> dict[str, torch.Tensor]:
        """The potential's inputs at the start of the episode: ``z_0`` (0 for a subgoal series) or ``o_0``."""
        keys = self.keys
        start = dict(current)
        if keys.anchor in self.state_keys:
            start[keys.anchor] = current[keys.start]
        else:
            start[keys.index] = current[keys.start] if keys.start in current else torch.zeros_like(current[keys.index])
        return start

    def _shape_eager(
        self,
        setup: _Setup,
        current: dict[str, torch.Tensor],
        z_next: torch.Tensor,
        nxt: TensorDictBase,
        reward: torch.Tensor,
        env_reward: torch.Tensor,
        done: torch.Tensor,
        terminated: torch.Tensor,
        learn: bool,
    ) -> dict[str, Any]:
        keys = self.keys
        batch_shape = setup.batch_shape
        z, r_h, k = current[keys.index], current[keys.ret], current[keys.steps]
        achieved = z_next != z
        r_h = r_h + env_reward * self.value_gamma**k
        k = k + 1
        emit = achieved | done
        nxt_state: dict[str, torch.Tensor] = {keys.index: z_next}
        if keys.achieved in self.state_keys:
            nxt_state[keys.achieved] = achieved
        if keys.anchor in self.state_keys:
            anchor = self._flat_obs(nxt.get(self.anchor_key), batch_shape)
            nxt_state[keys.anchor] = torch.where(achieved, anchor, current[keys.anchor])
        for kept in (keys.learner, keys.start):
            if kept in self.state_keys:
                nxt_state[kept] = current[kept]
        in_keys = self.potential.in_keys
        transition = None
        if learn or self.transitions_key is not None:
            transition = _transition(
                batch_shape, {key: current[key] for key in in_keys}, {key: nxt_state[key] for key in in_keys},
                r_h, k, emit, done, terminated,
            )
        if learn and bool(emit.any()):
            assert transition is not None
            self.update_potential(transition)
        with torch.no_grad():
            # Φ(z) of this step is last step's Φ(z') (unless an env was reset), Φ(z') is Φ(z) until a
            # subgoal is achieved, and Φ(z_0) holds for the episode: none is evaluated again while the
            # inputs and the potential are unchanged
            self._phi_cache.check(self.potential)
            phi = self._value(current, batch_shape, "z")
            phi_next = self._value(nxt_state, batch_shape, "z")
            if self.start_potential != "value" and not isinstance(self.potential, NaivePotential):
                shift = self._value(self._start_entries(current), batch_shape, "start")
                shift = shift if self.start_potential == "zero" else shift.clamp(min=0.0)
                phi, phi_next = phi - shift, phi_next - shift
        if self.zero_terminal_potential:
            phi_next = phi_next.masked_fill(terminated, 0.0)
        shaping = self.gamma * phi_next - phi
        out: dict[str, Any] = dict(nxt_state)
        out[keys.ret] = r_h.masked_fill(emit, 0.0)
        out[keys.steps] = k.masked_fill(emit, 0)
        if reward is env_reward:
            out[self.env_reward_key] = reward
        out[self.reward_key] = reward + shaping.to(reward.dtype)
        if self.transitions_key is not None:
            out[self.transitions_key] = transition
        return out

    def update_potential(self, transitions: TensorDictBase) -> None:
        """The online update: one SGD step of the potential on ``transitions`` (SMDP layout, masked)."""
        assert self.value_loss is not None and self.value_optimizer is not None
        with torch.enable_grad():
            self.value_optimizer.zero_grad(set_to_none=True)
            self.value_loss(transitions)["loss_value"].backward()
            self.value_optimizer.step()

    def transitions(self, data: TensorDictBase) -> TensorDictBase:
        """The real SMDP transitions closed in collected ``data`` (any batch shape), as ``[N]``.

        Rebuilt from the entries the transform keeps: a step closes a
        transition when ``z`` changed or the episode ended; its ``r_h`` and
        ``k`` are the root ``"subgoal_return"``/``"subgoal_steps"`` plus this
        step's env reward (``r_h + γ_v^k r``, ``k + 1``). Rows keep the
        potential's inputs (with ``"subgoal_learner"``, a per-env table finds
        its row in a shuffled replay buffer), in the layout
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
        keys = self.keys
        missing: list[NestedKey] = [k for k in (keys.index, keys.ret, keys.steps) if k not in data]
        missing += [("next", k) for k in (keys.index, self.done_key) if ("next", k) not in data.keys(True)]
        if missing:
            raise KeyError(f"{type(self).__name__}.transitions: the data has no {missing}; pass data collected "
                           "through the transform (or shaped by it)")
        in_keys = self.potential.in_keys
        n, dims, nxt = data.batch_size.numel(), data.batch_dims, data.get("next")

        def flat(td: TensorDictBase, key: NestedKey) -> torch.Tensor | None:
            value = td.get(key, None)  # entry by entry: cheaper than reshaping and indexing the TensorDict
            return None if value is None else value.reshape(n, *value.shape[dims:])

        z, z_next, done = flat(data, keys.index), flat(nxt, keys.index), flat(nxt, self.done_key)
        assert z is not None and z_next is not None and done is not None
        terminated = flat(nxt, self.terminated_key)
        rows = ((z_next != z) | done).reshape(-1).nonzero().squeeze(1)  # found once, gathered per entry
        reward = flat(nxt, self.env_reward_key)
        reward = flat(nxt, self.reward_key) if reward is None else reward
        assert reward is not None
        k, ret = flat(data, keys.steps), flat(data, keys.ret)
        assert k is not None and ret is not None
        k = k.index_select(0, rows)
        r_h = ret.index_select(0, rows) + reward.index_select(0, rows).to(torch.float32) * self.value_gamma**k
        inputs = {key: v.index_select(0, rows) for key in in_keys if (v := flat(data, key)) is not None}
        next_inputs = {key: v.index_select(0, rows) for key in in_keys if (v := flat(nxt, key)) is not None}
        done = done.index_select(0, rows)
        return _transition(
            torch.Size([done.shape[0]]), inputs, next_inputs, r_h, k + 1, torch.ones_like(done), done,
            done if terminated is None else terminated.index_select(0, rows),
        )

    # ------------------------------------------------------------------ stored data

    def _learners_of(self, data: TensorDictBase, batch_shape: torch.Size, time_dim: int) -> tuple[torch.Tensor, int]:
        """Each row's learner (``[*B, 1]``) and the number of learners, for stored data."""
        pot = self.potential
        n_learners = (
            self._online.batch_shape.numel() if self._online is not None
            else pot.learners if isinstance(pot, TabularPotential) and pot.batch_shape
            else self.pattern_index.numel() if self.pattern_index is not None
            else len(self.patterns) if self.patterns is not None and len(self.patterns) > 1
            else 1
        )
        stored = data.get(self.keys.learner, None)
        if stored is not None:
            learner = stored.long().select(time_dim, 0)
            if not (stored.long() == learner.unsqueeze(time_dim)).all():
                raise ValueError(f"rows of the data mix learners along time ({self.keys.learner!r} changes)")
            if learner.shape != (*batch_shape, 1):
                raise ValueError(f"{self.keys.learner!r} has shape {tuple(stored.shape)}; expected "
                                 f"{(*data.batch_size, 1)}")
            if learner.numel() and (int(learner.min()) < 0 or int(learner.max()) >= n_learners):
                raise ValueError(f"{self.keys.learner!r} values must lie in [0, {n_learners})")
            return learner, n_learners
        if n_learners == 1:
            return torch.zeros((*batch_shape, 1), dtype=torch.long), 1
        if batch_shape.numel() == n_learners:
            return torch.arange(n_learners).reshape(*batch_shape, 1), n_learners
        raise ValueError(
            f"data of batch shape {tuple(batch_shape)} (time excluded) from {n_learners} learners with their own "
            f"patterns or tables: each row's learner is unknown. Keep the {self.keys.learner!r} entry in the "
            "stored data (the transform writes it when the potential reads it), or pass rows in env order"
        )

    def forward(self, tensordict: TensorDictBase) -> TensorDictBase:
        """Shape stored data (e.g. a replay-buffer sample) along its time dimension, without training.

        ``tensordict`` has shape ``[*B, T]`` with the time dimension named
        ``"time"`` (as :meth:`~torchrl.envs.EnvBase.rollout` returns) or last,
        and holds the root observation and the ``("next", ...)`` observation,
        reward, done and terminated entries. ``[*B]`` may be any shape: the
        abstraction is compiled for this call. The abstract state starts from
        the stored root entries of the first step when the data has them (a
        slice from the middle of an episode), else from the first observation
        as at a reset, and restarts from the next root observation after every
        ``done``. The reward shaped is the env reward (``env_reward_key`` when
        stored, else ``reward_key``). The potential is used as it is now and
        never changed, whatever ``value_lr``.
        """
        if tensordict.batch_dims == 0:
            raise ValueError("forward() shapes stored trajectories [*B, T]; got a TensorDict without batch dims")
        names = tensordict.names
        time_dim = names.index("time") if "time" in names else tensordict.batch_dims - 1
        steps = tensordict.unbind(time_dim)
        batch_shape = steps[0].batch_size
        first = steps[0]
        obs = first.get(self.observation_key, None) if self._uses_observation else None
        learner, n_learners = self._learners_of(tensordict, batch_shape, time_dim)
        setup = self._compile(batch_shape, learner, obs, n_learners)
        self._fused_potential(setup, online=False)
        if all(key in first for key in self.state_keys):
            current = {key: first.get(key) for key in self.state_keys}
            if self.keys.learner in current:
                current[self.keys.learner] = learner
        else:
            current = self._initial_state(setup, first)
        outs = []
        for t, step in enumerate(steps):
            nxt = step.get("next")
            reward = nxt.get(self.env_reward_key, None)
            if reward is None:
                reward = nxt.get(self.reward_key)
            view = nxt.exclude(self.env_reward_key)  # shallow: the step's entries with the env reward to shape
            view.set(self.reward_key, reward)
            obs = view.get(self.observation_key, None) if self._uses_observation else None
            out = self._advance(setup, current, view, obs, learn=False)
            outs.append(out)
            if t + 1 < len(steps):
                done = view.get(self.done_key)
                restart = self._initial_state(setup, steps[t + 1])
                current = {k: torch.where(_expand(done, out[k]), restart[k], out[k]) for k in current}
        for key, first_out in outs[0].items():
            values = [o[key] for o in outs]
            stacked = (
                torch.stack(values, time_dim) if isinstance(first_out, torch.Tensor)
                else TensorDict.stack(values, time_dim)
            )
            tensordict.set(("next", key), stacked)
        return tensordict


class _ValueCache:
    """``Φ`` of the last inputs seen under each slot, given back while the inputs (compared by value)
    and the potential's parameters and buffers are unchanged.

    The parameters are compared by value with a copy taken when they last changed: an in-place
    update that moves no version counter (through ``.data``, TorchRL's weight updates, or another
    process writing shared memory) is seen too. Assumes ``Φ`` is a deterministic function of its
    inputs and those tensors (no dropout).
    """

    def __init__(self) -> None:
        self._slots: dict[str, tuple[dict[str, torch.Tensor], torch.Tensor]] = {}
        self._module: TensorDictModuleBase | None = None
        self._versions: tuple[tuple[int, int], ...] = ()
        self._snapshot: list[torch.Tensor] = []

    def check(self, potential: TensorDictModuleBase) -> None:
        """Call once per step before :meth:`get`: forget every slot if the potential changed since."""
        tensors = [*potential.parameters(), *potential.buffers()]
        versions = tuple((id(t), t._version) for t in tensors)
        same = potential is self._module and versions == self._versions  # a moved counter: changed for sure
        if same:
            same = all(_equal(t, s) for t, s in zip(tensors, self._snapshot, strict=True))
        if not same:
            self._slots.clear()
            self._module, self._versions = potential, versions
            self._snapshot = [t.detach().clone() for t in tensors]

    def get(self, slot: str, inputs: dict[str, torch.Tensor]) -> torch.Tensor | None:
        entry = self._slots.get(slot)
        if entry is None:
            return None
        kept, value = entry
        if kept.keys() != inputs.keys():
            return None
        for key, tensor in inputs.items():
            ref = kept[key]
            if ref.shape != tensor.shape or ref.dtype != tensor.dtype or not _equal(ref, tensor):
                return None
        return value

    def put(self, slot: str, inputs: dict[str, torch.Tensor], value: torch.Tensor) -> None:
        self._slots[slot] = ({k: t.detach().clone() for k, t in inputs.items()}, value.detach())


def _equal(a: torch.Tensor, b: torch.Tensor) -> bool:
    """``torch.equal`` for tensors of one shape and dtype. Large CPU tensors are compared through numpy,
    several times faster on one thread (15 µs against 55 µs for 256 × 256 float32 here); small ones by
    torch (1 µs against numpy's 5). NaN equals nothing in both."""
    if a.numel() >= 4096 and a.device.type == "cpu" and b.device.type == "cpu" and a.dtype in _NUMPY_DTYPES:
        return bool((a.detach().numpy() == b.detach().numpy()).all())
    return torch.equal(a, b)


_NO_TABLE = np.zeros((0, 1), dtype=np.float32)
_NO_TRANSITION = tuple(np.zeros((0, 1), dtype=d) for d in (np.float32, np.int64, np.bool_))


def _check_finite(
    reward: torch.Tensor, obs: torch.Tensor | None, reward_key: NestedKey, obs_key: NestedKey
) -> None:
    """Refuse a NaN or infinite reward and a NaN observation, naming the entry and the env.

    One reduction per tensor when all is well (a NaN or inf anywhere makes the sum
    non-finite); the search for the culprit runs only then.
    """
    for tensor, key, bad in ((reward, reward_key, "NaN or infinite"), (obs, obs_key, "NaN")):
        if tensor is None or not tensor.is_floating_point():
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


def _col(t: torch.Tensor, n: int, name: str) -> np.ndarray:
    """A ``[*B, 1]`` CPU tensor as an ``[n, 1]`` numpy view (a copy if not contiguous); a clear
    ``ValueError`` if it does not hold one entry per row (the kernels index it unchecked)."""
    if t.numel() != n:
        raise ValueError(f"{name!r} has shape {tuple(t.shape)}, expected one entry per row of a batch of {n}")
    a = t.numpy()
    return a if a.ndim == 2 and a.shape[1] == 1 else a.reshape(n, 1)


def _empty_like(t: torch.Tensor) -> tuple[torch.Tensor, np.ndarray]:
    """A new tensor shaped like ``t`` and its ``[n, 1]`` numpy view, for kernel outputs (allocated by
    numpy: cheaper than ``torch.empty`` and ``.numpy()``)."""
    a: np.ndarray = np.empty((max(1, t.numel()), 1), dtype=_NUMPY_DTYPES[t.dtype])
    out = torch.from_numpy(a)
    return (out if out.shape == t.shape else out.view(t.shape)), a


_NUMPY_DTYPES = {torch.float32: np.float32, torch.float64: np.float64, torch.int64: np.int64, torch.bool: np.bool_}


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
