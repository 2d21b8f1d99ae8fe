"""What shaping a batch needs, set up once per batch shape: the subgoals compiled for its rows, each
row's learner, and the potential as the compiled path reads it (when it can)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import numpy as np
import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase
from tensordict.utils import NestedKey
from torchrl.data import OneHot, TensorSpec

from torchrl_subgoal._kernels import NUMBA
from torchrl_subgoal.loss import SubgoalValueLoss, ValueUpdate
from torchrl_subgoal.potentials import NaivePotential, TabularPotential
from torchrl_subgoal.subgoals import (
    RegionTables,
    State,
    StateAggregation,
    SubgoalSeries,
    SubgoalTables,
)
from torchrl_subgoal.subgoals.tables import MEASURED
from torchrl_subgoal.transform.keys import SubgoalKeys, write
from torchrl_subgoal.transform.shaping import START_MODES, StartPotential
from torchrl_subgoal.transform.transitions import empty_transition

__all__ = [
    "BatchSetup",
    "PotentialKernelState",
    "Settings",
    "Subgoals",
    "check_backend",
    "check_monotone",
    "check_options",
    "check_potential",
    "compiled_potential",
    "initial_state",
    "kept_entries",
    "monotone_ancestors",
    "observation_layout",
    "online_update",
    "settings",
    "write_start",
]

#: ``table`` of a naive potential in the kernels: no table, ``Φ = η · achieved``
NO_TABLE = np.zeros((0, 1), dtype=np.float32)
#: ``ancestors`` of a table shaped as it is (not monotone)
NO_ANCESTORS = np.zeros((0, 0, 0), dtype=np.bool_)
#: ``updates`` of a potential updated with its own step size alone (no ``prior_weight``)
NO_UPDATES = np.zeros((0, 0), dtype=np.float32)


class Settings(NamedTuple):
    """What a step reads of its transform, fixed when the transform is made.

    Examples:
        >>> from torchrl_subgoal import State, SubgoalPotentialTransform
        >>> t = SubgoalPotentialTransform(SubgoalSeries([State(1)]), TabularPotential(2), gamma=0.9)
        >>> t._settings.kept, t._settings.value_gamma
        (('subgoal_index', 'subgoal_return', 'subgoal_steps'), 0.9)
    """

    keys: SubgoalKeys
    kept: tuple[str, ...]  #: the abstract-state entries kept in the TensorDict
    gamma: float  #: ``γ`` of the shaping term
    value_gamma: float  #: ``γ_v`` of the SMDP return
    zero_terminal: bool  #: ``Φ = 0`` at a terminal state
    start: StartPotential  #: the level of ``Φ``
    observation_key: NestedKey  #: what the region predicates read and the anchor snapshots
    reads_observation: bool  #: whether a region predicate or an aggregation reads it
    transitions: bool  #: whether every step writes its SMDP transition entry
    inputs: tuple[NestedKey, ...]  #: the potential's inputs (a transition keeps them at z and z')
    interpolate: bool = False  #: ``Φ(s, z)`` has the within-segment term (:mod:`.segments`)


class Subgoals:
    """The subgoals of a transform: distinct patterns and each env's (or a hand-given aggregation).

    Args:
        subgoals: a :class:`SubgoalSeries` for every env, one per env of the batch (flattened batch
            order; equal series are compiled once), or a :class:`StateAggregation`.

    Examples:
        >>> from torchrl_subgoal import Cell
        >>> a, b = SubgoalSeries([Cell(3, 6)]), SubgoalSeries([Cell(7, 9)])
        >>> subgoals = Subgoals([a, b, a])
        >>> len(subgoals.patterns), subgoals.pattern_of(3).tolist()
        (2, [0, 1, 0])
    """

    def __init__(self, subgoals: SubgoalSeries | Sequence[SubgoalSeries] | StateAggregation) -> None:
        self.aggregation: StateAggregation | None = None
        self._index: torch.Tensor | None = None  # each env's pattern; None: one pattern for every env
        self._given = 1
        if isinstance(subgoals, StateAggregation):
            self.aggregation, self.patterns = subgoals, []
            return
        series = [subgoals] if isinstance(subgoals, SubgoalSeries) else list(subgoals)
        if not series or not all(isinstance(s, SubgoalSeries) for s in series):
            raise TypeError("subgoals must be a SubgoalSeries, a sequence of them (one per env) or a StateAggregation")
        distinct = list(dict.fromkeys(series))
        self.patterns = distinct
        self._given = len(series)  # 1: every env's; else one per env
        if len(distinct) > 1:
            self._index = torch.tensor([distinct.index(s) for s in series], dtype=torch.long)

    @property
    def num_states(self) -> int:
        """Number of abstract states ``z`` (the terminal one excluded)."""
        if self.aggregation is not None:
            return self.aggregation.num_states
        return max(len(p) for p in self.patterns) + 1

    @property
    def per_env(self) -> bool:
        """Whether envs follow different patterns."""
        return self._index is not None

    @property
    def envs(self) -> int | None:
        """The number of envs the patterns were given for, one each (``None``: one pattern for every env)."""
        return None if self._index is None else self._index.numel()

    @property
    def reads_observation(self) -> bool:
        """Whether an aggregation or a region predicate reads the observation."""
        return self.aggregation is not None or any(pred.compiled for p in self.patterns for pred in p.predicates)

    @property
    def one_hot_states(self) -> bool:
        """Whether a :class:`State` predicate is among the subgoals (it reads a one-hot observation too)."""
        return any(isinstance(pred, State) for p in self.patterns for pred in p.predicates)

    def pattern_of(self, n_learners: int) -> torch.Tensor:
        """The pattern each of ``n_learners`` learners (flattened env batch) follows."""
        if self.aggregation is None and self._given not in (1, n_learners):
            raise ValueError(
                f"{self._given} subgoal series for a batch of {n_learners} envs: give one series "
                "for every env, or one per env"
            )
        return torch.zeros(n_learners, dtype=torch.long) if self._index is None else self._index

    def compile(
        self,
        learner: torch.Tensor,
        batch_shape: torch.Size,
        n_learners: int,
        layout: tuple[int, bool],
        observation_key: NestedKey,
    ) -> SubgoalTables | StateAggregation:
        """The abstraction for a batch whose rows belong to ``learner`` (``[*B, 1]``), observations of
        ``layout = (entries, one-hot)``."""
        if self.aggregation is not None:
            return self.aggregation
        patterns = self.pattern_of(n_learners)[learner.reshape(-1)].reshape(batch_shape)
        size, one_hot = layout
        return SubgoalTables(self.patterns, patterns, size, one_hot=one_hot, observation_key=str(observation_key))


class PotentialKernelState(NamedTuple):
    """A tabular or naive potential and the transform's settings, as the compiled shaping step reads them
    (:func:`~torchrl_subgoal._kernels.shaping._shape_learner`).

    Examples:
        >>> PotentialKernelState(NO_TABLE, 2.0, 0.9, 0.9, 0.0, True, 2).eta
        2.0
    """

    table: np.ndarray  #: ``[B or 1, Z]`` float32 view of the potential's table (updated in place); ``[0, 1]``: naive
    eta: float  #: the naive potential's ``η`` (``Φ = η`` once a subgoal is achieved)
    gamma: float  #: ``γ`` of the shaping term
    value_gamma: float  #: ``γ_v`` of the SMDP return
    value_lr: float  #: ``α_v`` of the online update (0: none)
    zero_terminal: bool  #: ``Φ = 0`` at a terminal state
    start_mode: int  #: ``_kernels.shaping.START_VALUE``, ``START_ZERO`` or ``START_NONPOSITIVE``
    expectile: float = 0.5  #: ``τ`` of the online update's target (0.5: the mean)
    bootstrap_truncated: bool = True  #: whether a time-out inside ``z`` trains ``V(z)``
    #: with a monotone table, ``[R, Z, Z]``: what comes before each ``z`` in each row's series; else empty
    ancestors: np.ndarray = NO_ANCESTORS
    achievement_reward: float = 0.0  #: added to the target of a transition that reached the next subgoal
    prior_weight: float = 0.0  #: ``k`` of the step size ``max(α_v, 1 / (k + n))`` (0: ``α_v``)
    updates: np.ndarray = NO_UPDATES  #: ``[R, Z]`` float32 view of the table's update counts (with a prior weight)


def compiled_potential(potential: TensorDictModuleBase, update: SubgoalValueLoss | None) -> str | None:
    """Why the compiled step cannot shape with ``potential`` (trained online by ``update``), or ``None``.

    Examples:
        >>> from torchrl_subgoal import NeuralPotential
        >>> compiled_potential(TabularPotential(3), None) is None
        True
        >>> compiled_potential(NeuralPotential(torch.nn.Linear(2, 1)), None)
        'it shapes with a TabularPotential or a NaivePotential, not NeuralPotential'
    """
    if isinstance(potential, TabularPotential):
        if potential.table.device.type != "cpu":
            return f"it reads the potential's table on the CPU, not {potential.table.device}"
    elif not isinstance(potential, NaivePotential):
        return f"it shapes with a TabularPotential or a NaivePotential, not {type(potential).__name__}"
    if update is not None and (type(update) is not SubgoalValueLoss or update.reduction != "sum"):
        return "its online update is one SGD step of the default SubgoalValueLoss (reduction 'sum')"
    return None


def check_device(potential: TensorDictModuleBase, data: torch.Tensor | None) -> None:
    """Refuse a potential whose parameters are not on the device of ``data`` (an entry it shapes; ``None``:
    nothing to compare).

    Examples:
        >>> check_device(TabularPotential(3), torch.zeros(2))  # fine
        >>> check_device(TabularPotential(3).to("meta"), torch.zeros(2))
        Traceback (most recent call last):
        ...
        ValueError: SubgoalPotentialTransform: the potential is on meta but the data it shapes on cpu; ...
    """
    device = data.device if data is not None else None
    for tensor in (*potential.parameters(), *potential.buffers()):
        if device is not None and tensor.device != device:
            raise ValueError(
                f"SubgoalPotentialTransform: the potential is on {tensor.device} but the data it shapes on {device}; "
                "keep them on one device: move the env with its transforms (env.to(device)), or the transform "
                "back (transform.to(device))"
            )


def check_options(gamma: float, start: str) -> None:
    """Refuse a discount outside ``[0, 1]`` or an unknown start level.

    Examples:
        >>> check_options(0.9, "highest")
        Traceback (most recent call last):
        ...
        ValueError: start_potential must be one of ['nonpositive', 'value', 'zero'], got 'highest'
    """
    if not 0.0 <= gamma <= 1.0:
        raise ValueError(f"gamma must lie in [0, 1], got {gamma}")
    if start not in START_MODES:
        raise ValueError(f"start_potential must be one of {sorted(START_MODES)}, got {start!r}")


def check_backend(backend: str) -> None:
    """Refuse an unknown backend.

    Examples:
        >>> check_backend("fast")
        Traceback (most recent call last):
        ...
        ValueError: backend must be 'auto', 'compiled' or 'torch', got 'fast'
    """
    if backend not in ("auto", "compiled", "torch"):
        raise ValueError(f"backend must be 'auto', 'compiled' or 'torch', got {backend!r}")


def settings(
    keys: SubgoalKeys,
    potential: TensorDictModuleBase,
    subgoals: Subgoals,
    gamma: float,
    update: ValueUpdate | None,
    observation_key: NestedKey,
    *,
    zero_terminal: bool,
    start: StartPotential,
) -> Settings:
    """A transform's :class:`Settings`: ``γ_v`` is the online update's loss's (``γ`` without one).

    Examples:
        >>> from torchrl_subgoal import State
        >>> s = settings(SubgoalKeys(), TabularPotential(2), Subgoals(SubgoalSeries([State(1)])), 0.9, None, "o",
        ...              zero_terminal=True, start="value")
        >>> s.value_gamma, s.kept
        (0.9, ('subgoal_index', 'subgoal_return', 'subgoal_steps'))
    """
    value_gamma = float(gamma) if update is None or update.loss is None else update.loss.gamma
    kept = kept_entries(keys, potential, subgoals, start)
    if isinstance(potential, TabularPotential) and potential.monotone:
        check_monotone(subgoals)
    interpolate = isinstance(potential, TabularPotential) and potential.interpolate and check_interpolate(subgoals)
    return Settings(keys, kept, float(gamma), value_gamma, zero_terminal, start, observation_key,
                    subgoals.reads_observation, keys.transitions is not None, tuple(potential.in_keys),
                    interpolate)  # fmt: skip


def check_interpolate(subgoals: Subgoals) -> bool:
    """Whether an interpolating table (``TabularPotential(interpolate=True)``) adds a within-segment term over
    ``subgoals``: only towards regions with a size (box, circle, cell); a discrete ``state`` or a condition adds
    none, so a series of them shapes as a plain table does. An aggregation, whose abstract states have no next
    subgoal to measure a distance to, is refused.

    Examples:
        >>> from torchrl_subgoal import Cell, State, StateAggregation
        >>> [check_interpolate(Subgoals(SubgoalSeries([pred]))) for pred in (State(1), Cell(1, 2))]
        [False, True]
        >>> check_interpolate(Subgoals(StateAggregation(torch.tensor([0, 1]), num_states=2)))
        Traceback (most recent call last):
        ...
        ValueError: TabularPotential(interpolate=True): the shaping needs subgoal series, not an aggregation
    """
    if subgoals.aggregation is not None:
        raise ValueError("TabularPotential(interpolate=True): the shaping needs subgoal series, not an aggregation")
    return any(pred.kind in MEASURED for series in subgoals.patterns for pred in series.predicates)


def check_monotone(subgoals: Subgoals) -> None:
    """Refuse a monotone table (``TabularPotential(monotone=True)``) over a hand-given aggregation, whose
    abstract states come in no order.

    Examples:
        >>> from torchrl_subgoal import StateAggregation
        >>> check_monotone(Subgoals(StateAggregation(torch.tensor([0, 0, 1, 1]), num_states=2)))
        Traceback (most recent call last):
        ...
        ValueError: TabularPotential(monotone=True): the shaping needs subgoal series, ...
    """
    if subgoals.aggregation is not None:
        raise ValueError(
            "TabularPotential(monotone=True): the shaping needs subgoal series, whose abstract states come "
            "one after another; an aggregation's states have no order (use monotone=False)"
        )


def monotone_ancestors(
    potential: TensorDictModuleBase, subgoals: Subgoals, learner: torch.Tensor, n_learners: int
) -> torch.Tensor | None:
    """With a monotone table (``TabularPotential(monotone=True)``), which abstract states of each row's
    series (``learner``: ``[*B, 1]``) come before each one, itself included, flattened: ``[R, Z, Z]``
    (``[r, z, a]``: ``a`` is ``z`` or comes before it; states past a short series are their own only);
    else ``None``.

    Examples:
        >>> from torchrl_subgoal import State
        >>> subgoals = Subgoals([SubgoalSeries([State(1)]), SubgoalSeries([State(1), State(2)])])
        >>> ancestors = monotone_ancestors(TabularPotential(3, monotone=True), subgoals, torch.tensor([[1], [0]]), 2)
        >>> ancestors[0, 2].tolist(), ancestors[1, 2].tolist()  # row 1's series has no z = 2
        ([True, True, True], [False, False, True])
        >>> monotone_ancestors(TabularPotential(3), subgoals, torch.tensor([[1], [0], [1]]), 2) is None
        True
    """
    if not (isinstance(potential, TabularPotential) and potential.monotone):
        return None
    n = potential.num_states
    masks = torch.eye(n, dtype=torch.bool).repeat(len(subgoals.patterns), 1, 1)
    for p, series in enumerate(subgoals.patterns):
        for z in range(series.num_abstract_states):
            masks[p, z, list(series.ancestors(z))] = True
    return masks[subgoals.pattern_of(n_learners)[learner.reshape(-1)]]


def check_table(potential: TensorDictModuleBase, n_learners: int, num_states: int) -> None:
    """Refuse a tabular potential whose tables do not fit a batch of ``n_learners`` envs or an abstraction of
    ``num_states`` abstract states.

    Examples:
        >>> check_table(TabularPotential(2), 4, 3)
        Traceback (most recent call last):
        ...
        ValueError: TabularPotential has 2 states; the abstraction has 3
    """
    if not isinstance(potential, TabularPotential):
        return
    if potential.batch_shape and potential.learners != n_learners:
        per_table = f" of {potential.envs_per_table} envs each" if potential.envs_per_table > 1 else ""
        raise ValueError(
            f"TabularPotential has batch_shape {tuple(potential.batch_shape)}{per_table} but the env batch has "
            f"{n_learners} envs: use one table per env (or per envs_per_table envs) or a shared one (batch_shape=())"
        )
    if potential.num_states < num_states:
        raise ValueError(f"TabularPotential has {potential.num_states} states; the abstraction has {num_states}")


def compiles(backend: str, potential: TensorDictModuleBase, update: ValueUpdate | None) -> bool:
    """Whether the compiled step shapes with ``potential`` (trained online by ``update``) under ``backend``;
    ``"compiled"`` where it cannot is a ``TypeError`` saying why.

    Examples:
        >>> compiles("auto", TabularPotential(3), None), compiles("torch", TabularPotential(3), None)
        (True, False)
        >>> compiles("auto", TabularPotential(3, monotone=True), None)
        True
    """
    why = (
        "backend='torch'"
        if backend == "torch"
        else "numba is not installed (pip install numba)"
        if not NUMBA
        else compiled_potential(potential, update.loss if update else None)
    )
    if why is not None and backend == "compiled":
        raise TypeError(f"SubgoalPotentialTransform backend 'compiled': {why}; use the backend 'torch' or 'auto'")
    return why is None


@dataclass
class BatchSetup:
    """What shaping a batch of a given shape needs: the abstraction compiled for its rows, each row's
    learner, and, for the compiled path, the potential as the kernels read it.

    Examples:
        >>> from torchrl_subgoal import State
        >>> subgoals, learner = Subgoals(SubgoalSeries([State(1)])), torch.zeros(3, 1, dtype=torch.long)
        >>> batch = BatchSetup(torch.Size([3]), subgoals.compile(learner, torch.Size([3]), 1, (1, False), "o"), learner)
        >>> batch.rows, batch.compiled
        (3, False)
    """

    batch_shape: torch.Size
    abstraction: SubgoalTables | StateAggregation
    learner: torch.Tensor  #: ``[*B, 1]`` long
    compiled: bool = False  #: whether the compiled step shapes this batch
    compiled_search: bool = True  #: whether the torch step advances regions with the compiled region search
    kernel: tuple[PotentialKernelState, PotentialKernelState] | None = None  #: (without, with) the online update
    group: int = 0  #: rows sharing each table (row ``b`` reads table ``b // group``; 0: a table per row)
    regions: RegionTables | None = None  #: the regions the compiled step advances (None: advanced in torch)
    table: torch.Tensor | None = None  #: the tabular potential's parameter, to see it move
    table_ptr: int = 0
    z_start: np.ndarray = field(default_factory=lambda: np.zeros((1, 1), np.int64))
    ancestors: torch.Tensor | None = None  #: with a monotone table: what comes before each ``z``, ``[R, Z, Z]``
    observation_size: int = 1  #: entries of one observation the abstraction reads
    backend: Any = None  #: the :class:`~torchrl_subgoal.transform.backends.ShapingBackend` that shapes it

    def __post_init__(self) -> None:
        self.rows = self.batch_shape.numel()  #: rows of the batch

    def use_kernels(
        self, potential: TensorDictModuleBase, settings: Settings, update: ValueUpdate | None, online: bool
    ) -> None:
        """Set the potential up for the compiled step, trained online by ``update`` (``online``: the env's
        batch, whose rows are the learners; else stored rows, each reading its learner's table, copied)."""
        abstraction = self.abstraction
        if isinstance(abstraction, SubgoalTables):
            self.regions = abstraction.kernel_state() if abstraction.fusable else None
        else:
            self.regions = abstraction.regions
        table, eta = NO_TABLE, 0.0
        if isinstance(potential, NaivePotential):
            eta = potential.eta
        else:
            assert isinstance(potential, TabularPotential)
            table = potential.table.detach().numpy().reshape(potential.tables, potential.num_states)
            if not potential.batch_shape:
                self.group = max(1, self.batch_shape.numel())  # one table for every row
            elif not online:  # stored rows: each row's table, copied
                table = np.ascontiguousarray(table[self.learner.reshape(-1).numpy() // potential.envs_per_table])
            elif potential.envs_per_table > 1:  # the env batch in order: consecutive envs share a table
                self.group = potential.envs_per_table
            self.table, self.table_ptr = potential.table, potential.table.data_ptr()
        n = self.batch_shape.numel()
        if self.group == 0 and table.shape[0] not in (0, n):
            raise ValueError(f"the potential has {table.shape[0]} tables for a batch of {n} rows")
        mode = START_MODES[settings.start]
        loss = update.loss if update is not None else None
        expectile, bootstrap = (0.5, True) if loss is None else (loss.expectile, loss.bootstrap_truncated)
        achievement = 0.0 if loss is None else loss.achievement_reward
        ancestors = NO_ANCESTORS if self.ancestors is None else self.ancestors.numpy()
        weight, updates = 0.0, NO_UPDATES
        if update is not None and update.prior_weight > 0.0 and online and isinstance(potential, TabularPotential):
            weight = update.prior_weight
            updates = potential.updates.numpy().reshape(potential.tables, potential.num_states)
        self.kernel = tuple(
            PotentialKernelState(
                table,
                eta,
                settings.gamma,
                settings.value_gamma,
                lr,
                settings.zero_terminal,
                mode,
                expectile,
                bootstrap,
                ancestors,
                achievement,
                weight,
                updates,
            )
            for lr in (0.0, update.lr if update else 0.0)
        )  # type: ignore[assignment]
        self.z_start = np.zeros((max(1, n), 1), np.int64)  # a subgoal series starts every episode in z = 0
        self.compiled = True

    @property
    def moved(self) -> bool:
        """Whether the tabular potential's table moved since (to shared memory, another device…)."""
        return self.table is not None and self.table.data_ptr() != self.table_ptr

    def stale(self, potential: TensorDictModuleBase) -> bool:
        """Whether ``potential``'s table moved since, or is another tensor now (``.to("meta")`` replaces it)."""
        return self.table is not None and (self.moved or self.table is not getattr(potential, "table", None))


def check_potential(potential: TensorDictModuleBase, keys: SubgoalKeys) -> None:
    """Refuse a potential that is not a TensorDict module writing a value, or that reads entries the
    transform does not keep; the message says what to build instead.

    Examples:
        >>> check_potential(TabularPotential(3), SubgoalKeys())  # reads subgoal_index: fine
    """
    if not isinstance(potential, TensorDictModuleBase) or not potential.out_keys:
        raise TypeError(
            "the potential must be a TensorDict module whose (last) output entry is the value (a Potential, or e.g. "
            f"TensorDictModule(net, in_keys=[{keys.anchor!r}], out_keys=['subgoal_value'])), "
            f"got {type(potential).__name__}"
        )
    provided = (keys.index, *keys.optional)
    unknown = [k for k in potential.in_keys if k not in provided]
    if unknown:
        raise ValueError(
            f"the potential reads {unknown}, which this transform does not keep; it keeps "
            f"{list(provided)} (prefix {keys.prefix!r}): build the potential with those keys"
        )


def kept_entries(
    keys: SubgoalKeys, potential: TensorDictModuleBase, subgoals: Subgoals, start: StartPotential
) -> tuple[str, ...]:
    """The entries kept: ``z``, ``r_h``, ``k``, those the potential reads, and its input at reset when the
    start level needs it (unless that input is ``z = 0``, where every subgoal series starts).

    Examples:
        >>> from torchrl_subgoal import State
        >>> kept_entries(SubgoalKeys(), TabularPotential(2, (4,)), Subgoals(SubgoalSeries([State(1)])), "zero")
        ('subgoal_index', 'subgoal_return', 'subgoal_steps', 'subgoal_learner')
    """
    reads = potential.in_keys
    extra = tuple(k for k in keys.optional if k in reads)
    if (
        start != "value"
        and not isinstance(potential, NaivePotential)
        and (keys.anchor in reads or (subgoals.aggregation is not None and keys.index in reads))
    ):
        extra = (*extra, keys.start)
    return (keys.index, keys.ret, keys.steps, *extra)


def online_update(
    value_update: ValueUpdate | float | None, potential: TensorDictModuleBase, gamma: float
) -> ValueUpdate | None:
    """``value_update`` as a :class:`ValueUpdate` whose loss trains ``potential`` (``None``: none); the
    default loss has ``γ_v = gamma``.

    Examples:
        >>> online_update(0.25, TabularPotential(3), 0.9).loss.reduction
        'sum'
    """
    if value_update is None:
        return None
    update = value_update if isinstance(value_update, ValueUpdate) else ValueUpdate(float(value_update))
    if not list(potential.parameters()):
        raise ValueError(f"value_update: {type(potential).__name__} has no parameters to train")
    if update.prior_weight > 0.0 and not isinstance(potential, TabularPotential):
        kind = type(potential).__name__
        raise ValueError(f"value_update: prior_weight counts a TabularPotential's updates, not {kind}'s")
    if update.loss is None:
        loss = SubgoalValueLoss(potential, reduction="sum").make_value_estimator(gamma=gamma)
        return ValueUpdate(update.lr, loss, prior_weight=update.prior_weight)
    if update.loss.potential is not potential:
        raise ValueError("value_update: its loss trains another potential than the transform's")
    return update


def observation_layout(
    spec: TensorSpec | None, obs: torch.Tensor | None, batch_shape: torch.Size, subgoals: Subgoals
) -> tuple[int, bool]:
    """(entries per observation, one-hot?): from the env's ``spec`` when there is one, else from the data
    (where a :class:`State` predicate reads an observation of more than one entry as one-hot).

    Examples:
        >>> from torchrl_subgoal import State
        >>> observation_layout(None, torch.zeros(3, 4), torch.Size([3]), Subgoals(SubgoalSeries([State(1)])))
        (4, True)
    """
    if spec is not None:
        shape = spec.shape[len(batch_shape) :]
        return (shape.numel() if len(shape) else 1), isinstance(spec, OneHot)
    if obs is None:
        return 0, False
    size = obs.shape[len(batch_shape) :].numel() if obs.dim() > len(batch_shape) else 1
    return size, subgoals.one_hot_states and size > 1


def initial_state(setup: BatchSetup, settings: Settings, obs: torch.Tensor | None) -> dict[str, torch.Tensor]:
    """The kept entries at a reset to the observation ``obs`` (``None`` when it is not read).

    Examples:
        >>> from torchrl_subgoal import State
        >>> subgoals = Subgoals(SubgoalSeries([State(1)]))
        >>> learner = torch.arange(2).reshape(2, 1)
        >>> setup = BatchSetup(torch.Size([2]), subgoals.compile(learner, torch.Size([2]), 2, (1, False), "o"), learner)
        >>> settings = Settings(SubgoalKeys(), ("subgoal_index", "subgoal_return", "subgoal_steps"), 0.9, 0.9, True,
        ...                     "value", "o", True, False, ("subgoal_index",))
        >>> initial_state(setup, settings, None)["subgoal_index"].tolist()
        [[0], [0]]
    """
    batch_shape, k, kept = setup.batch_shape, settings.keys, settings.kept
    col = (*batch_shape, 1)
    state = {
        k.index: setup.abstraction.initial(obs, batch_shape),
        k.ret: torch.zeros(col),
        k.steps: torch.zeros(col, dtype=torch.long),
    }
    if k.achieved in kept:
        state[k.achieved] = torch.zeros(col, dtype=torch.bool)
    if k.anchor in kept:
        assert obs is not None
        state[k.anchor] = obs.reshape(*batch_shape, -1).to(torch.float32)
    if k.learner in kept:
        state[k.learner] = setup.learner
    if k.start in kept:
        state[k.start] = state[k.anchor if k.anchor in kept else k.index]
    return state


def write_start(
    td: TensorDictBase,
    root: TensorDictBase,
    reset: torch.Tensor | None,
    setup: BatchSetup,
    settings: Settings,
    obs: torch.Tensor | None,
) -> None:
    """Write the kept entries at a reset into ``root`` (``td``'s reward group): every row's, or those of the rows
    ``reset`` flags (an env that reset itself in its step); a full reset also writes an empty transition.

    Examples:
        >>> from tensordict import TensorDict
        >>> from torchrl_subgoal import State, SubgoalPotentialTransform
        >>> t = SubgoalPotentialTransform(SubgoalSeries([State(1)]), TabularPotential(2), gamma=0.9)
        >>> td = TensorDict({}, [2])
        >>> obs = torch.zeros(2, 1, dtype=torch.long)
        >>> batch = t._batch(torch.Size([2]), torch.arange(2).reshape(2, 1), 2, obs, online=True)
        >>> write_start(td, td, None, batch, t._settings, obs)
        >>> td["subgoal_index"].tolist()
        [[0], [0]]
    """
    state = initial_state(setup, settings, obs)
    for name, value in state.items():
        if reset is not None:
            value = torch.where(reset.reshape(*setup.batch_shape, 1), value, root.get(name))
        write(root, name, value)
    key = settings.keys.transitions
    if key is not None and reset is None:
        write(td, key, empty_transition(setup.batch_shape, state, settings.inputs, settings.keys))
