"""Potential functions ``Φ`` over the abstract state kept by the transform.

The shaping reward is ``F = γ Φ(next) − Φ(current)``. A potential is a
TensorDict module: it reads some of the abstract-state entries the transform
keeps in the TensorDict and writes ``"subgoal_value"`` (``[*B, 1]``, as
TorchRL value networks do). The entries (with the transform's default prefix):

* ``"subgoal_index"`` — ``z``, the node of the subgoal series reached;
* ``"subgoal_anchor"`` — the observation at the moment ``z`` was entered;
* ``"subgoal_achieved"`` — whether ``z`` was entered on this very step;
* ``"subgoal_learner"`` — which env of the batch (which learner) the row came
  from, so a per-learner table picks its row by key, also in a shuffled
  replay-buffer sample.

:class:`TabularPotential` (``V[z]``, one table per learner of a batch or one
shared table) and :class:`NeuralPotential` (``V(o_z; θ)``) are learned by
:class:`~torchrl_subgoal.SubgoalValueLoss`; :class:`NaivePotential` is the
fixed ``η`` of the naive subgoal shaping baseline (NRS). Any other
:class:`~tensordict.nn.TensorDictModuleBase` whose ``in_keys`` are entries the
transform keeps and whose single ``out_keys`` entry is the value can be ``Φ``
too (an MLP over the anchor, a ``TensorDictSequential``…).

The built-in potentials also take their inputs as tensors, in ``in_keys``
order: ``potential(z)`` returns the values.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModule, TensorDictModuleBase
from tensordict.utils import NestedKey
from torch import nn

from torchrl_subgoal.subgoals import SubgoalSeries

__all__ = ["NaivePotential", "NeuralPotential", "Potential", "TabularPotential", "check_value"]

INDEX = "subgoal_index"
ANCHOR = "subgoal_anchor"
ACHIEVED = "subgoal_achieved"
LEARNER = "subgoal_learner"
VALUE = "subgoal_value"


def check_value(value: torch.Tensor, batch_shape: torch.Size, who: str) -> torch.Tensor:
    """``value`` if it is ``[*batch_shape, 1]`` (or ``[*batch_shape]``, viewed so); else a clear error.

    Examples:
        >>> check_value(torch.zeros(3), torch.Size([3]), "V").shape
        torch.Size([3, 1])
    """
    if not isinstance(value, torch.Tensor):
        raise TypeError(f"{who} returned {type(value).__name__}, expected a tensor of shape {(*batch_shape, 1)}")
    if value.shape == (*batch_shape, 1):
        return value
    if value.shape == batch_shape:
        return value.unsqueeze(-1)
    raise ValueError(
        f"{who} returned values of shape {tuple(value.shape)} for a batch of shape {tuple(batch_shape)}: "
        f"a potential must return one value per row, shape {(*batch_shape, 1)} (check the network's "
        "output size is 1 and its input entry is the one it expects)"
    )


class Potential(TensorDictModuleBase):
    """Base class: a TensorDict module from abstract-state entries to ``Φ`` (``[*B, 1]``).

    Subclasses implement :meth:`value`, which takes the ``in_keys`` entries as
    tensors in that order. Called on a TensorDict the module writes the value
    under ``out_keys[0]`` (``"subgoal_value"``); called on tensors it returns it.

    Args:
        in_keys: the entries read.
        out_key: where the value is written.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> class Progress(Potential):  # Φ(z) = z: a fixed potential over the subgoal index
        ...     def value(self, z):
        ...         return z.float()
        >>> phi = Progress(["subgoal_index"])
        >>> phi(TensorDict({"subgoal_index": torch.tensor([[0], [2]])}, [2]))["subgoal_value"].squeeze(-1)
        tensor([0., 2.])
    """

    #: entries of ``in_keys`` that may be absent from a TensorDict (passed as ``None``)
    optional_in_keys: tuple[NestedKey, ...] = ()

    def __init__(self, in_keys: Sequence[NestedKey], out_key: NestedKey = VALUE) -> None:
        super().__init__()
        self.in_keys = list(in_keys)
        self.out_keys = [out_key]

    def value(self, *inputs: torch.Tensor | None) -> torch.Tensor:
        """``Φ`` of the inputs (the ``in_keys`` entries, in order), shape ``[*B, 1]``."""
        raise NotImplementedError

    def forward(self, *args: torch.Tensor | TensorDictBase, **kwargs: torch.Tensor) -> torch.Tensor | TensorDictBase:
        if args and isinstance(args[0], TensorDictBase):
            tensordict = args[0]
            inputs = []
            for key in self.in_keys:
                entry = tensordict.get(key, None)
                if entry is None and key not in self.optional_in_keys:
                    raise KeyError(
                        f"{type(self).__name__} reads {key!r}, which the TensorDict does not hold; "
                        f"it has {sorted(map(str, tensordict.keys(True, True)))}"
                    )
                inputs.append(entry)
            value = check_value(self.value(*inputs), tensordict.batch_size, type(self).__name__)
            tensordict.set(self.out_keys[0], value)
            return tensordict
        if kwargs:
            raise TypeError(f"{type(self).__name__} takes a TensorDict or its inputs as positional tensors")
        return self.value(*args)

    def as_value_operator(self, out_key: NestedKey = "state_value") -> TensorDictModule:
        """This potential writing ``out_key`` instead (e.g. as a TorchRL estimator's value network)."""
        return TensorDictModule(self.value, in_keys=list(self.in_keys), out_keys=[out_key])


class TabularPotential(Potential):
    """``V[z]``: one table of abstract-state values per learner, or one shared table.

    With a learner batch, each row of a TensorDict picks its table by its
    ``"subgoal_learner"`` entry (the transform writes it), so flattened or
    shuffled samples (a replay buffer) read the right table. Without that entry
    (or called on tensors without learner indices), ``z`` must start with the
    learner batch shape and rows follow their position.

    Args:
        num_states: number of abstract states (``SubgoalSeries.num_abstract_states``
            or the aggregation's ``num_states``).
        batch_shape: shape of the learner batch (the env's batch size, or with ``envs_per_table``
            the number of tables); ``()`` for one table shared by every env.
        init: initial values: one for every entry, one per abstract state (``[num_states]``, e.g. a
            series' progress prior :meth:`~torchrl_subgoal.SubgoalSeries.progress`), or every table's
            (``[*batch_shape, num_states]``).

    Keyword Args:
        envs_per_table: envs that share each table of a batch: table ``t`` serves the envs
            (learner indices) ``t·envs_per_table … (t+1)·envs_per_table − 1``, so a batch of
            learners that each step several envs is one env batch (learner-major) with one table
            per learner, each updated as that learner's shared table would be on its own.
        monotone: the shaping transform shapes with the table lifted so that it does not decrease along
            the series (each ``z`` takes the largest value among itself and the states before it, each
            learner's table on its own) instead of the table as learned. Training and :meth:`value`
            read the table as it is. Where a learned table values a later subgoal below an earlier one,
            the shaping then neither charges the agent for reaching it nor pays it for staying before
            it. For subgoal series (the transform refuses an aggregation); every backend shapes with it.
        interpolate: between subgoals, ``Φ(s, z)`` also rises from ``V[z]`` towards the value of the next
            subgoal as the observation nears its region (:mod:`torchrl_subgoal.transform.segments`), so the
            potential guides before the next subgoal is reached. Towards subgoals that are regions (boxes,
            circles, cells; a discrete state or a condition adds nothing); every backend shapes with it
            (the default of :meth:`for_subgoals`).
        index_key: the abstract state entry read.
        learner_key: the learner entry read (with a batch of tables).
        out_key: where the value is written.

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl_subgoal import TabularPotential
        >>> v = TabularPotential(3, batch_shape=(2,))
        >>> with torch.no_grad():
        ...     v.table[1, 2] = 0.5
        >>> v(torch.tensor([[2], [2]]))
        tensor([[0.0000],
                [0.5000]], grad_fn=<ViewBackward0>)
        >>> sample = TensorDict({"subgoal_index": torch.tensor([[2], [2], [1]]),
        ...                      "subgoal_learner": torch.tensor([[1], [0], [1]])}, [3])
        >>> v(sample)["subgoal_value"].squeeze(-1)
        tensor([0.5000, 0.0000, 0.0000], grad_fn=<SqueezeBackward1>)
        >>> grouped = TabularPotential(3, batch_shape=(2,), envs_per_table=2)  # envs 0, 1 | envs 2, 3
        >>> with torch.no_grad():
        ...     grouped.table[1, 2] = 0.5
        >>> grouped.learners, grouped(torch.tensor([[2], [2], [2], [2]])).squeeze(-1).tolist()
        (4, [0.0, 0.0, 0.5, 0.5])
    """

    def __init__(
        self,
        num_states: int,
        batch_shape: tuple[int, ...] | torch.Size = (),
        init: float | Sequence[float] | torch.Tensor = 0.0,
        *,
        monotone: bool = False,
        interpolate: bool = False,
        envs_per_table: int = 1,
        index_key: NestedKey = INDEX,
        learner_key: NestedKey = LEARNER,
        out_key: NestedKey = VALUE,
    ) -> None:
        self.batch_shape = torch.Size(batch_shape)
        super().__init__([index_key, learner_key] if self.batch_shape else [index_key], out_key)
        self.optional_in_keys = (learner_key,)
        self.num_states = int(num_states)
        self.monotone = bool(monotone)
        self.interpolate = bool(interpolate)
        if self.num_states < 1:
            raise ValueError(f"num_states must be >= 1, got {num_states}")
        self.envs_per_table = int(envs_per_table)
        if self.envs_per_table < 1:
            raise ValueError(f"envs_per_table must be >= 1, got {envs_per_table}")
        if self.envs_per_table > 1 and not self.batch_shape:
            raise ValueError("envs_per_table needs a batch of tables (batch_shape); one shared table serves every env")
        shape = (*self.batch_shape, self.num_states)
        values = torch.as_tensor(init, dtype=torch.get_default_dtype())
        try:
            table = values.expand(shape).clone()
        except RuntimeError:
            raise ValueError(
                f"init of shape {tuple(values.shape)} does not fit tables of shape {shape}: give one value, "
                f"one per abstract state ({self.num_states}) or one per table entry"
            ) from None
        if not torch.isfinite(table).all():
            raise ValueError(f"init must be finite, got {values.tolist()}")
        self.table = nn.Parameter(table)
        #: how many online updates each entry has had, counted where the update's step size depends on it
        #: (:class:`~torchrl_subgoal.ValueUpdate`'s ``prior_weight``); not saved with the module's state
        self.register_buffer("updates", torch.zeros(shape), persistent=False)

    @classmethod
    def for_subgoals(
        cls,
        subgoals: SubgoalSeries | Sequence[SubgoalSeries],
        scale: float = 1.0,
        batch_shape: tuple[int, ...] | torch.Size | None = None,
        **kwargs: Any,
    ) -> TabularPotential:
        """The library's default potential over ``subgoals``: a table that starts at the series' progress
        prior (:meth:`~torchrl_subgoal.SubgoalSeries.progress`), is shaped non-decreasing along the
        series (``monotone=True``) and, between subgoals that are regions, rises as the next one comes
        nearer (``interpolate=True``), to be learned online by the shaping transform.

        Before the first success under a sparse goal reward every return is 0, so a table learned from 0
        stays 0 and cannot guide; this one rises with each subgoal from the first step and becomes the
        learned value as the transitions come in (docs/shaping_defaults.md). Pass ``interpolate=False``
        for a potential over ``z`` alone (the paper's).

        Args:
            subgoals: one series (one table, or the same prior in every table of ``batch_shape``), or one
                series per table.
            scale: what reaching the goal is worth, in the units of the reward the transform shapes
                (after any reward scaling of the learner); each subgoal's share is ``scale / (n + 1)``.
                Keep it at the size of the task's rewards: with ``Φ = 0`` at the goal, the goal's step
                takes back what the subgoals paid.
            batch_shape: the tables' batch shape (default: one per series given as a sequence, else shared).
            **kwargs: the other arguments of :class:`TabularPotential` (``envs_per_table``, keys...).

        Examples:
            >>> from torchrl_subgoal import Cell, SubgoalSeries
            >>> series = SubgoalSeries([Cell(3, 6), Cell(7, 9)])
            >>> v = TabularPotential.for_subgoals(series, scale=3.0)
            >>> v.table.tolist(), v.monotone, v.interpolate
            ([0.0, 1.0, 2.0], True, True)
            >>> TabularPotential.for_subgoals([series, SubgoalSeries([Cell(3, 6)])], scale=2.0).table.tolist()
            [[0.0, 0.6666666865348816, 1.3333333730697632], [0.0, 1.0, 1.0]]
        """
        many = not isinstance(subgoals, SubgoalSeries)
        series: list[SubgoalSeries] = [subgoals] if isinstance(subgoals, SubgoalSeries) else list(subgoals)
        if not series:
            raise ValueError("for_subgoals needs at least one subgoal series")
        if not scale >= 0:
            raise ValueError(f"scale must be >= 0 (what reaching the goal is worth), got {scale}")
        num_states = max(s.num_abstract_states for s in series)
        rows = []
        for s in series:  # past a shorter series' last state, its last value
            prior = list(s.progress(scale))
            rows.append(prior + prior[-1:] * (num_states - len(prior)))
        priors = torch.tensor(rows, dtype=torch.get_default_dtype())
        shape = torch.Size(batch_shape if batch_shape is not None else ((len(series),) if many else ()))
        if len(series) == 1 or len({tuple(r) for r in rows}) == 1:
            init = priors[0]
        elif len(series) == shape.numel():
            init = priors.reshape(*shape, num_states)
        else:
            raise ValueError(
                f"{len(series)} subgoal series for tables of batch shape {tuple(shape)}: give one series, or one "
                "per table"
            )
        kwargs.setdefault("monotone", True)
        kwargs.setdefault("interpolate", True)
        return cls(num_states, shape, init, **kwargs)

    @property
    def tables(self) -> int:
        """Number of tables (1 when shared)."""
        return self.batch_shape.numel()

    @property
    def learners(self) -> int:
        """Number of envs (learner indices) the tables serve: ``tables × envs_per_table`` (1 when shared)."""
        return self.tables * self.envs_per_table

    def freeze(self, values: Sequence[float] | torch.Tensor) -> TabularPotential:
        """Set every learner's table to ``values`` (one per abstract state) and stop it learning.

        The shaping transform then shapes with these values and does not update them
        (online or through :class:`~torchrl_subgoal.SubgoalValueLoss`): a known or
        previously learned potential, given from the first step.

        Examples:
            >>> v = TabularPotential(3, batch_shape=(2,)).freeze([0.25, 0.5, 0.75])
            >>> v.table.requires_grad, v.table[1].tolist() == [0.25, 0.5, 0.75]
            (False, True)
            >>> TabularPotential(3).freeze([0.2, 0.5])
            Traceback (most recent call last):
            ...
            ValueError: a frozen table needs 3 values (z = 0..2), got 2
        """
        values = torch.as_tensor(values, dtype=self.table.dtype).reshape(-1)
        if values.numel() != self.num_states:
            raise ValueError(
                f"a frozen table needs {self.num_states} values (z = 0..{self.num_states - 1}), got {values.numel()}"
            )
        if not torch.isfinite(values).all():
            raise ValueError(f"a frozen table's values must be finite, got {values.tolist()}")
        with torch.no_grad():
            self.table.copy_(values.expand_as(self.table))
        self.table.requires_grad_(False)
        return self

    def value(self, z: torch.Tensor, learner: torch.Tensor | None = None) -> torch.Tensor:  # type: ignore[override]
        if z.shape[-1:] != (1,):
            raise ValueError(f"subgoal_index must end with a singleton dim, got shape {tuple(z.shape)}")
        if z.dtype.is_floating_point or z.dtype == torch.bool:
            raise ValueError(f"subgoal_index must be an integer tensor, got {z.dtype}")
        if z.numel() and (int(z.min()) < 0 or int(z.max()) >= self.num_states):
            raise ValueError(
                f"subgoal_index values must lie in [0, {self.num_states}), got [{int(z.min())}, {int(z.max())}]"
            )
        if not self.batch_shape:
            return self.table[z]
        table = self.table.reshape(self.tables, self.num_states)
        if learner is not None:
            if learner.shape != z.shape:
                raise ValueError(
                    f"subgoal_learner has shape {tuple(learner.shape)}, subgoal_index {tuple(z.shape)}: they must match"
                )
            if learner.numel() and (int(learner.min()) < 0 or int(learner.max()) >= self.learners):
                raise ValueError(
                    f"subgoal_learner values must lie in [0, {self.learners}) for a table batch "
                    f"of shape {tuple(self.batch_shape)}"
                    + (f" of {self.envs_per_table} envs each" if self.envs_per_table > 1 else "")
                )
            rows = learner.long() if self.envs_per_table == 1 else learner.long() // self.envs_per_table
            return table[rows, z]
        envs = self.batch_shape if self.envs_per_table == 1 else torch.Size([self.learners])
        if z.shape[: len(envs)] != envs:
            raise ValueError(
                f"subgoal_index of shape {tuple(z.shape)} does not start with the learner batch "
                f"shape {tuple(envs)}; pass the learner indices (the 'subgoal_learner' entry)"
            )
        return table.gather(1, z.reshape(self.tables, -1)).view(z.shape)


class NeuralPotential(Potential):
    """``V(o_z; θ)``: a network over the observation at which ``z`` was entered.

    Args:
        network: maps ``[*B, D]`` anchor observations to ``[*B, 1]`` values
            (for pick-and-place, the critic's hidden layers without the action).

    Keyword Args:
        anchor_key: the anchor entry read.
        out_key: where the value is written.

    Examples:
        >>> import torch
        >>> from torch import nn
        >>> from torchrl_subgoal import NeuralPotential
        >>> v = NeuralPotential(nn.Linear(4, 1))
        >>> v(torch.zeros(5, 4)).shape
        torch.Size([5, 1])
    """

    def __init__(self, network: nn.Module, *, anchor_key: NestedKey = ANCHOR, out_key: NestedKey = VALUE) -> None:
        super().__init__([anchor_key], out_key)
        self.network = network

    def value(self, anchor: torch.Tensor) -> torch.Tensor:  # type: ignore[override]
        out = self.network(anchor.float())
        return check_value(out, anchor.shape[:-1], f"NeuralPotential's network {type(self.network).__name__}")


class NaivePotential(Potential):
    """``Φ = η`` on the step a subgoal is achieved, else 0 (naive subgoal shaping, NRS).

    The achieving step earns ``γη`` and the next step ``−η``: a fixed pulse,
    never learned.

    Args:
        eta: the potential of a subgoal state (the paper uses 1 in four-rooms,
            10,000 in PinBall).

    Keyword Args:
        achieved_key: the entry read.
        out_key: where the value is written.

    Examples:
        >>> import torch
        >>> from torchrl_subgoal import NaivePotential
        >>> NaivePotential(10.0)(torch.tensor([[True], [False]]))
        tensor([[10.],
                [ 0.]])
    """

    def __init__(self, eta: float, *, achieved_key: NestedKey = ACHIEVED, out_key: NestedKey = VALUE) -> None:
        super().__init__([achieved_key], out_key)
        self.eta = float(eta)

    def value(self, achieved: torch.Tensor) -> torch.Tensor:  # type: ignore[override]
        return achieved.to(torch.get_default_dtype()) * self.eta
