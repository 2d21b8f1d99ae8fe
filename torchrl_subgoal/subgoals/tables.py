"""Abstraction tables: subgoal series compiled for a batch of learners, and hand-given aggregations ``z = g(s)``."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import NamedTuple

import numpy as np
import torch
from tensordict import TensorDictBase

from torchrl_subgoal._kernels import NUMBA
from torchrl_subgoal.subgoals.errors import SubgoalFileError, _where
from torchrl_subgoal.subgoals.predicates import Condition, Predicate
from torchrl_subgoal.subgoals.series import SubgoalSeries

if NUMBA:  # the compiled region search; without numba, the torch one (advance_eager)
    from torchrl_subgoal._kernels.regions import advance_regions, advance_with_conditions


def _misfit(pred: Predicate, size: int, one_hot: bool) -> str | None:
    """Why ``pred`` cannot read an observation of ``size`` entries (one-hot or not), or None.

    A ``state`` predicate reads a scalar state index or a one-hot vector; on any other
    observation it would silently compare entry 0 (e.g. a cell's row). The others read
    entries by index, which must exist and must not be a one-hot code.
    """
    if pred.kind == "state":
        return None if one_hot or size == 1 else "a state predicate reads a scalar state index or a one-hot state"
    if one_hot:
        return f"a {pred.kind} predicate reads entries by position, not a one-hot code,"
    beyond = [d for d in pred.dims() if d >= size]
    return f"reads entry {beyond[0]}" if beyond else None


#: the kinds of subgoal a distance is measured to (an interpolating potential's within-segment term)
MEASURED = ("box", "circle", "cell")
_NO_ENTRIES = np.zeros((0, 0), np.float64)  # the observation of subgoals that are all conditions
_NO_MASK = torch.zeros(0, dtype=torch.bool)


class RegionTables(NamedTuple):
    """Regions as the compiled region search reads them (:func:`~torchrl_subgoal._kernels.regions.region_search`).

    Learner ``b`` follows pattern ``pattern[b]`` (pattern 0 for every learner when ``pattern`` is
    empty). From abstract state ``z`` it moves to ``j + offset`` for the first region ``j`` that
    ``succ[p, z]`` allows and that contains the observation, and stays in ``z`` when none does.
    :meth:`SubgoalTables.kernel_state` gives a subgoal series' (``offset`` 1), and
    :meth:`StateAggregation.from_regions` a region aggregation's (``offset`` 0, every region allowed).

    Examples:
        >>> import torch
        >>> from torchrl_subgoal import State
        >>> tables = SubgoalTables([SubgoalSeries([State(1), State(3)])], torch.zeros(2, dtype=torch.long), 1)
        >>> regions = tables.kernel_state()
        >>> regions.lo.shape, regions.succ.shape, regions.offset  # [P, J, D], [P, J + 1, J]
        ((1, 2, 1), (1, 3, 2), 1)
    """

    pattern: np.ndarray  #: ``[N]`` int64 pattern of every learner (empty: all follow pattern 0)
    lo: np.ndarray  #: ``[P, J, D]`` float32 lower bounds (``+inf``: padding, never inside)
    hi: np.ndarray  #: ``[P, J, D]`` float32 upper bounds
    centre: np.ndarray  #: ``[P, J, D]`` float32 circle centres
    weight: np.ndarray  #: ``[P, J, D]`` float32 weights of the circle's distance (0: not read)
    radius2: np.ndarray  #: ``[P, J]`` float32 squared radii (``inf``: no circle)
    succ: np.ndarray  #: ``[P, Z, J]`` bool: which regions count from each abstract state
    offset: int  #: ``z`` of region ``j`` is ``j + offset``


class SubgoalTables:
    """Subgoal series of a batch of learners, compiled for one vectorised test.

    Each learner ``b`` follows pattern ``pattern_index[b]``. The tables hold,
    per pattern, every region predicate (padded to the longest pattern) and
    which subgoals are achievable from each abstract state; conditions
    (:class:`Condition`) are called once per step on the step's TensorDict.

    Args:
        patterns: the distinct patterns.
        pattern_index: the pattern of each learner, shape ``batch_shape``.
        observation_size: entries of the observation the region predicates read.
        one_hot: the observation is one-hot (for :class:`State` predicates).
        observation_key: for error messages.

    Examples:
        >>> import torch
        >>> from torchrl_subgoal import State, SubgoalSeries
        >>> tables = SubgoalTables([SubgoalSeries([State(1), State(3)])], torch.zeros(2, dtype=torch.long), 1)
        >>> tables.advance(torch.tensor([[0], [1]]), torch.tensor([[1], [1]])).tolist()
        [[1], [1]]
    """

    def __init__(
        self,
        patterns: Sequence[SubgoalSeries],
        pattern_index: torch.Tensor,
        observation_size: int,
        *,
        one_hot: bool = False,
        observation_key: str = "observation",
    ) -> None:
        n_nodes = max(len(p) for p in patterns)
        P, J, D = len(patterns), n_nodes, observation_size
        lo = torch.full((P, J, D), math.inf)  # padded nodes (and conditions) are never inside a region
        hi = torch.full((P, J, D), -math.inf)
        centre = torch.zeros(P, J, D)
        weight = torch.zeros(P, J, D)
        radius2 = torch.full((P, J), math.inf)
        measured = torch.zeros(P, J, dtype=torch.bool)  # regions with a size to measure a distance in
        succ = torch.zeros(P, J + 1, J, dtype=torch.bool)
        slots: dict[Predicate, torch.Tensor] = {}  # condition -> [P, J] where a pattern uses it
        condition_of = np.full((P, J), -1, np.int64)  # the index of the condition at [p, j], -1: a region
        for p, series in enumerate(patterns):
            for j, pred in enumerate(series.predicates):
                if not pred.compiled:
                    slots.setdefault(pred, torch.zeros(P, J, dtype=torch.bool))[p, j] = True
                    condition_of[p, j] = list(slots).index(pred)
                    continue
                problem = _misfit(pred, D, one_hot)
                try:
                    if problem:
                        raise IndexError(problem)
                    region = pred.region(D, one_hot=one_hot)
                except IndexError as exc:
                    label = series.names[j] if series.names else f"subgoals[{j}]"
                    raise SubgoalFileError(
                        f"{_where(series.source, series.name, f'{label}.{pred.kind}')}: {exc} but the "
                        f"observation {observation_key!r} has {D} entries"
                        f"{' (one-hot)' if one_hot else ''} (wrong observation_key?)"
                    ) from None
                lo[p, j], hi[p, j] = region.lo, region.hi
                centre[p, j], weight[p, j] = region.centre, region.weight
                radius2[p, j] = region.radius2
                measured[p, j] = pred.kind in MEASURED
            for z in range(len(series) + 1):
                for j in series.successors(z):
                    succ[p, z, j] = True
        idx = pattern_index.long()
        if idx.numel() and (int(idx.min()) < 0 or int(idx.max()) >= P):
            raise ValueError(f"pattern_index values must lie in [0, {P})")
        self.batch_shape = idx.shape
        self.num_states = J + 1
        self.observation_size = D
        self.observation_key = observation_key
        self.chain = all(p.is_chain for p in patterns)
        self.uses_regions = any(pred.compiled for series in patterns for pred in series.predicates)
        # per-learner tables, flattened batch first
        flat = idx.reshape(-1)
        self.lo, self.hi = lo[flat], hi[flat]
        self.centre, self.weight = centre[flat], weight[flat]
        self.radius2 = radius2[flat]
        self.measured = measured[flat]  #: ``[B, J]``: the regions a distance is measured to (not ``state``)
        self.succ = succ[flat]
        self.uses_circle = bool(torch.isfinite(radius2).any())
        self._rows = torch.arange(flat.numel())
        self.conditions = [(pred, where[flat]) for pred, where in slots.items()]
        self._condition_of = condition_of
        self._calls = [pred.fn if isinstance(pred, Condition) else pred for pred in slots]
        self._n, self._dims = flat.numel(), len(self.batch_shape)
        # the kernels read per-pattern tables and each learner's pattern (small, stays in cache)
        self._kernel_tables = RegionTables(
            flat.contiguous().numpy(),
            lo.numpy(),
            hi.numpy(),
            centre.numpy(),
            weight.numpy(),
            radius2.numpy(),
            succ.numpy(),
            1,
        )

    def kernel_state(self) -> RegionTables:
        """The region tables as the compiled kernels read them (numpy, per pattern; CPU).

        Examples:
            >>> import torch
            >>> from torchrl_subgoal import State
            >>> tables = SubgoalTables([SubgoalSeries([State(1)])], torch.zeros(3, dtype=torch.long), 1)
            >>> tables.kernel_state().pattern.tolist()
            [0, 0, 0]
        """
        return self._kernel_tables

    @property
    def fusable(self) -> bool:
        """Whether one compiled kernel can advance the batch (no conditions to call)."""
        return not self.conditions

    def initial(self, observation: torch.Tensor | None, batch_shape: torch.Size) -> torch.Tensor:
        """Abstract state at reset: 0 for every learner, shape ``[*batch_shape, 1]``."""
        return torch.zeros((*batch_shape, 1), dtype=torch.long)

    def rows(self, observation: torch.Tensor) -> torch.Tensor:
        """``observation`` as ``[B, D]`` rows of this batch; a ``ValueError`` if it does not fit."""
        n, d = self._rows.numel(), self.observation_size
        if observation.numel() != n * d:
            raise ValueError(
                f"observation {self.observation_key!r} of shape {tuple(observation.shape)} does not fit the subgoal "
                f"tables compiled for {n} learners x {d} entries (batch shape {tuple(self.batch_shape)})"
            )
        return observation.reshape(n, d)

    def _check_z(self, z: torch.Tensor) -> None:
        if z.numel() != self._rows.numel():
            raise ValueError(
                f"{z.numel()} abstract states for subgoal tables compiled for "
                f"{self._rows.numel()} learners (batch shape {tuple(self.batch_shape)})"
            )

    def inside(self, observation: torch.Tensor) -> torch.Tensor:
        """Which subgoal regions contain the observation, ``[B, J]`` (flattened batch)."""
        obs = self.rows(observation).unsqueeze(1).to(torch.float64)
        return _in_regions(obs, self.lo, self.hi, self.centre, self.weight, self.radius2, self.uses_circle)

    def achieved(self, observation: torch.Tensor | None, tensordict: TensorDictBase | None) -> torch.Tensor:
        """Which subgoals hold, ``[B, J]``: regions on ``observation``, conditions on ``tensordict``."""
        n = self._rows.numel()
        if self.uses_regions:
            if observation is None:
                raise ValueError(f"the region subgoals read {self.observation_key!r}, which is missing")
            hit = self.inside(observation)
        else:
            hit = torch.zeros(n, self.num_states - 1, dtype=torch.bool)
        for pred, slots in self.conditions:
            if tensordict is None:
                raise ValueError(f"condition {pred!r} needs the step's TensorDict")
            hit = hit | (slots & self._mask(pred, tensordict).unsqueeze(-1))
        return hit

    def _mask(self, pred: Predicate, tensordict: TensorDictBase) -> torch.Tensor:
        n = self._rows.numel()
        try:
            mask = pred(tensordict)
        except Exception as exc:
            raise type(exc)(f"subgoal condition {pred!r} failed on the step's TensorDict: {exc}") from exc
        if (
            not isinstance(mask, torch.Tensor)
            or mask.numel() != n
            or mask.shape[: len(self.batch_shape)] != self.batch_shape
        ):
            shape = tuple(mask.shape) if isinstance(mask, torch.Tensor) else type(mask).__name__
            raise ValueError(
                f"subgoal condition {pred!r} returned {shape}; expected a boolean mask of shape "
                f"{tuple(self.batch_shape)} (or with a trailing 1)"
            )
        if mask.dtype != torch.bool:  # a number is not a truth value: 2 would silently read as achieved
            raise ValueError(
                f"subgoal condition {pred!r} returned a {mask.dtype} tensor; expected a boolean mask "
                "(a comparison such as `td['passenger'] == 4`)"
            )
        return mask.reshape(n).to(device=self.lo.device)

    def advance(
        self, z: torch.Tensor, observation: torch.Tensor | None, tensordict: TensorDictBase | None = None
    ) -> torch.Tensor:
        """Next abstract state after observing ``observation`` (and ``tensordict``) in abstract state ``z``.

        On the CPU with numba installed this is one compiled region search (the conditions called first,
        once each); elsewhere :meth:`advance_eager`.
        """
        self._check_z(z)
        if z.device.type != "cpu" or not NUMBA:
            return self.advance_eager(z, observation, tensordict)
        out = np.empty((self._n, 1), dtype=np.int64)
        self.advance_into(z.numpy().reshape(self._n, 1), observation, tensordict, out)
        result = torch.from_numpy(out)
        return result if result.shape == z.shape else result.view(z.shape)

    def advance_into(
        self, z: np.ndarray, observation: torch.Tensor | None, tensordict: TensorDictBase | None, out: np.ndarray
    ) -> None:
        """:meth:`advance` on ``[B, 1]`` numpy arrays: ``out`` gets the next abstract state of ``z`` (CPU).

        Examples:
            >>> from torchrl_subgoal import State
            >>> tables = SubgoalTables([SubgoalSeries([State(1)])], torch.zeros(2, dtype=torch.long), 1)
            >>> out = np.empty((2, 1), np.int64)
            >>> tables.advance_into(np.zeros((2, 1), np.int64), torch.tensor([[1.0], [0.0]]), None, out)
            >>> out.tolist()
            [[1], [0]]
        """
        if self.uses_regions and observation is None:
            raise ValueError(f"the region subgoals read {self.observation_key!r}, which is missing")
        if self.conditions:
            obs = self.rows(observation).numpy() if observation is not None and self.uses_regions else _NO_ENTRIES
            advance_with_conditions(self._kernel_tables, self._condition_of, self._hits(tensordict), z, obs, out)
        else:
            assert observation is not None
            advance_regions(self._kernel_tables, z, self.rows(observation).numpy(), out)

    def _hits(self, tensordict: TensorDictBase | None) -> np.ndarray:
        """``[B, C]``: where each condition holds (each called once, on the step's TensorDict)."""
        if tensordict is None:
            raise ValueError(f"condition {self.conditions[0][0]!r} needs the step's TensorDict")
        n, masks = self._n, [_NO_MASK] * len(self._calls)
        for c, call in enumerate(self._calls):
            try:
                mask = call(tensordict)
            except Exception as exc:
                raise type(exc)(
                    f"subgoal condition {self.conditions[c][0]!r} failed on the step's TensorDict: {exc}"
                ) from exc
            if (
                not isinstance(mask, torch.Tensor)
                or mask.shape[: self._dims] != self.batch_shape
                or mask.numel() != n
                or mask.dtype is not torch.bool
            ):
                self._mask(self.conditions[c][0], tensordict)  # raises, saying what was expected
            masks[c] = mask.reshape(n)
        return torch.stack(masks, -1).numpy()

    def advance_eager(
        self, z: torch.Tensor, observation: torch.Tensor | None, tensordict: TensorDictBase | None = None
    ) -> torch.Tensor:
        """:meth:`advance` with torch operations only (any device; the reference)."""
        self._check_z(z)
        zf = z.reshape(-1)
        if self.chain and self.fusable:
            # only subgoal z can be achieved next: test that one region
            assert observation is not None
            j = zf.clamp(max=self.num_states - 2)
            obs = self.rows(observation).to(torch.float64)
            rows = self._rows
            hit = _in_regions(
                obs,
                self.lo[rows, j],
                self.hi[rows, j],
                self.centre[rows, j],
                self.weight[rows, j],
                self.radius2[rows, j],
                self.uses_circle,
            )
            hit = hit & self.succ[self._rows, zf, j]
            return (zf + hit.long()).view_as(z)
        cand = self.succ[self._rows, zf] & self.achieved(observation, tensordict)
        first = cand.long().argmax(-1)  # lowest-index achievable subgoal
        return torch.where(cand.any(-1), first + 1, zf).view_as(z)


def _in_regions(
    obs: torch.Tensor,
    lo: torch.Tensor,
    hi: torch.Tensor,
    centre: torch.Tensor,
    weight: torch.Tensor,
    radius2: torch.Tensor,
    circles: bool,
) -> torch.Tensor:
    """``_in_region`` in torch: the same float64 comparisons, summed in the same order,
    so both paths agree on every input (NaN is never inside; unread entries never matter)."""
    hit = ((obs >= lo) & (obs <= hi)).all(-1)
    if circles:
        diff = obs - centre.to(torch.float64)
        w = weight.to(torch.float64)
        terms = torch.where(w != 0, w * diff * diff, 0.0)
        d2 = torch.zeros(terms.shape[:-1], dtype=torch.float64, device=terms.device)
        for d in range(terms.shape[-1]):  # in order, as the kernel adds them
            d2 = d2 + terms[..., d]
        hit = hit & (d2 <= radius2)
    return hit


class StateAggregation:
    """A hand-given aggregation ``z = g(s)`` (the SARSA-RS baseline).

    Args:
        mapping: a lookup tensor indexed by a discrete observation, or a
            function from an observation batch ``[*B, D]`` to integer states ``[*B]``.
        num_states: number of abstract states.

    Use :meth:`from_regions` for regions of a continuous observation.

    Examples:
        >>> import torch
        >>> from torchrl_subgoal import StateAggregation
        >>> rooms = StateAggregation(torch.tensor([0, 0, 1, 1]), num_states=2)
        >>> rooms.advance(torch.zeros(3, 1, dtype=torch.long), torch.tensor([0, 2, 3]))
        tensor([[0],
                [1],
                [1]])
    """

    def __init__(
        self,
        mapping: torch.Tensor | Callable[[torch.Tensor], torch.Tensor] | None,
        num_states: int,
    ) -> None:
        self.mapping = mapping
        self.num_states = int(num_states)
        self.regions: RegionTables | None = None  # from_regions: the regions, as the kernels read them
        if isinstance(mapping, torch.Tensor):
            if mapping.dtype != torch.long or mapping.ndim != 1:
                raise ValueError("a lookup aggregation must be a 1-D long tensor indexed by state")
            if int(mapping.min()) < 0 or int(mapping.max()) >= self.num_states:
                raise ValueError(f"aggregation values must lie in [0, {self.num_states})")

    @classmethod
    def from_regions(cls, regions: Sequence[Predicate], observation_size: int) -> StateAggregation:
        """``z`` = the first of ``regions`` containing the observation (kept when none does).

        Examples:
            >>> from torchrl_subgoal import Box, StateAggregation
            >>> thirds = StateAggregation.from_regions(
            ...     [Box((c,), (1 / 6,), (0,)) for c in (1 / 6, 1 / 2, 5 / 6)], observation_size=4)
            >>> thirds.advance(torch.zeros(2, 1, dtype=torch.long), torch.tensor([[0.2, 0, 0, 0], [0.9, 0, 0, 0]]))
            tensor([[0],
                    [2]])
        """
        if not regions:
            raise ValueError("from_regions needs at least one region")
        compiled = [p.region(observation_size) for p in regions]
        agg = cls(None, len(regions))
        j = len(compiled)

        def table(name: str) -> np.ndarray:
            return torch.stack([getattr(r, name) for r in compiled])[None].numpy()  # [1, J, D]: one pattern

        agg.regions = RegionTables(  # every region allowed from every z; region j is z = j
            np.zeros(0, np.int64),
            table("lo"),
            table("hi"),
            table("centre"),
            table("weight"),
            np.array([[r.radius2 for r in compiled]], dtype=np.float32),
            np.ones((1, j, j), np.bool_),
            0,
        )
        return agg

    def _g(self, observation: torch.Tensor, batch_shape: torch.Size) -> torch.Tensor:
        if isinstance(self.mapping, torch.Tensor):
            return self.mapping[observation.long().reshape(batch_shape)]
        assert self.mapping is not None
        return self.mapping(observation).long().reshape(batch_shape)

    def _search(self, z: torch.Tensor, observation: torch.Tensor) -> torch.Tensor:
        """The first region containing each row's observation (its ``z`` when none does), in torch: the
        region search of the kernels (:func:`~torchrl_subgoal._kernels.regions.region_search`)."""
        regions = self.regions
        assert regions is not None
        n = z.numel()
        lo, hi, centre, weight, radius2 = (
            torch.from_numpy(a[0]).to(z.device)
            for a in (regions.lo, regions.hi, regions.centre, regions.weight, regions.radius2)
        )
        obs = observation.reshape(n, 1, -1).to(torch.float64)
        inside = _in_regions(obs, lo, hi, centre, weight, radius2, bool(torch.isfinite(radius2).any()))
        return torch.where(inside.any(-1), inside.long().argmax(-1), z.reshape(-1)).view(z.shape)

    def initial(self, observation: torch.Tensor | None, batch_shape: torch.Size) -> torch.Tensor:
        """Abstract state of the reset observation, ``[*batch_shape, 1]``."""
        if observation is None:
            raise ValueError("a state aggregation needs the observation it reads")
        if self.regions is not None:
            return self._search(
                torch.zeros((*batch_shape, 1), dtype=torch.long, device=observation.device), observation
            )
        return self._g(observation, batch_shape).unsqueeze(-1)

    @property
    def fusable(self) -> bool:
        """Whether the fused kernels can shape with it (always: it is evaluated before them)."""
        return True

    def advance(
        self, z: torch.Tensor, observation: torch.Tensor | None, tensordict: TensorDictBase | None = None
    ) -> torch.Tensor:
        """``g`` of the new observation (the previous ``z`` matters only outside every region); the region
        search compiled on the CPU."""
        if observation is None:
            raise ValueError("a state aggregation needs the observation it reads")
        if self.regions is not None and z.device.type == "cpu" and NUMBA:
            n = z.numel()
            if n and not 0 <= int(z.min()) <= int(z.max()) < self.num_states:  # the kernel indexes by z unchecked
                raise ValueError(
                    f"abstract states must lie in [0, {self.num_states}) for this aggregation, got "
                    f"{int(z.min())}..{int(z.max())}"
                )
            out = np.empty((n, 1), dtype=np.int64)
            advance_regions(self.regions, z.numpy().reshape(n, 1), observation.numpy().reshape(n, -1), out)
            return torch.from_numpy(out).view(z.shape)
        return self.advance_eager(z, observation, tensordict)

    def advance_eager(
        self, z: torch.Tensor, observation: torch.Tensor | None, tensordict: TensorDictBase | None = None
    ) -> torch.Tensor:
        """:meth:`advance` with torch operations only (any device; the reference)."""
        if observation is None:
            raise ValueError("a state aggregation needs the observation it reads")
        if self.regions is not None:
            return self._search(z, observation)
        return self._g(observation, z.shape[:-1]).unsqueeze(-1)
