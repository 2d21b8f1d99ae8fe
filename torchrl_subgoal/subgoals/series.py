"""Subgoal series: subgoals and the order in which they are achieved (a chain or a DAG)."""

from __future__ import annotations

from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any, NoReturn

import torch
from tensordict import TensorDictBase

from torchrl_subgoal.subgoals.errors import SubgoalFileError, _where
from torchrl_subgoal.subgoals.predicates import Condition, Predicate

#: Most subgoals one pattern of a file may have.
MAX_SUBGOALS = 1000


def _as_predicate(subgoal: Any, where: str) -> Predicate:
    """A predicate as given, or a plain callable wrapped in a :class:`Condition`."""
    if isinstance(subgoal, Predicate):
        return subgoal
    if callable(subgoal):
        return Condition(subgoal)
    raise TypeError(f"{where}: a subgoal is a Predicate or a function of the TensorDict, got {subgoal!r}")


@dataclass(frozen=True)
class SubgoalSeries:
    """An ordered set of subgoals: a chain (total order) or a DAG (partial order).

    The abstract state ``z`` of an episode is the node reached: ``0`` at reset
    (no subgoal yet), ``i + 1`` once subgoal ``i`` was achieved. From ``z``
    the achievable subgoals are the *immediate successors* of ``z`` in the
    order (the sources of the DAG from ``z = 0``); each subgoal is achieved
    once and out-of-order visits do nothing. A chain of ``n`` subgoals thus
    has ``n + 1`` abstract states.

    Args:
        predicates: one achievement predicate per subgoal: a built-in region
            (:class:`Cell`, :class:`Circle`…), a :class:`Condition`, or any
            function of the step's TensorDict returning a boolean mask.
        order: pairs ``(i, j)`` meaning subgoal ``i`` comes before ``j``.
            ``None`` means the chain ``0 ≺ 1 ≺ … ≺ n-1``. Transitive pairs are
            allowed; only the covering relation decides what comes next.
        names: optional names of the subgoals (as in the file).
        name: the pattern's name (e.g. ``"participant_1"``).
        source: the file it came from, for error messages.

    Examples:
        >>> from torchrl_subgoal import SubgoalSeries
        >>> from torchrl_subgoal.subgoals import Cell
        >>> series = SubgoalSeries([Cell(3, 6), Cell(7, 9)], name="hallways")
        >>> series.num_abstract_states
        3
        >>> series.successors(0), series.successors(1), series.successors(2)
        ((0,), (1,), ())
    """

    predicates: tuple[Predicate, ...]
    order: tuple[tuple[int, int], ...] | None = None
    names: tuple[str, ...] | None = None
    name: str = "pattern"
    source: str | None = field(default=None, compare=False)
    description: str | None = field(default=None, compare=False)

    def __init__(
        self,
        predicates: Sequence[Predicate | Callable[[TensorDictBase], torch.Tensor]],
        order: Iterable[tuple[int, int]] | None = None,
        names: Sequence[str] | None = None,
        name: str = "pattern",
        source: str | None = None,
        description: str | None = None,
    ) -> None:
        where = _where(source, name, "")
        preds = tuple(_as_predicate(p, f"{where}: subgoals[{i}]") for i, p in enumerate(predicates))
        n = len(preds)
        if n == 0:
            raise SubgoalFileError(f"{where}: a pattern needs at least one subgoal")
        if names is not None and len(names) != n:
            raise SubgoalFileError(f"{where}: {len(names)} names for {n} subgoals")
        if names is not None and len(set(names)) != n:
            twice = next(nm for i, nm in enumerate(names) if nm in names[:i])
            raise SubgoalFileError(f"{_where(source, name, 'subgoals')}: duplicate subgoal name {twice!r}")
        edges = None
        if order is not None:
            edges = tuple((int(a), int(b)) for a, b in order)
            for a, b in edges:
                if not (0 <= a < n and 0 <= b < n) or a == b:
                    raise SubgoalFileError(f"{where}: order: invalid pair ({a}, {b}) for {n} subgoals")
            if edges == tuple((i, i + 1) for i in range(n - 1)):
                edges = None  # the chain, stated explicitly
        object.__setattr__(self, "predicates", preds)
        object.__setattr__(self, "order", edges)
        object.__setattr__(self, "names", tuple(names) if names is not None else None)
        object.__setattr__(self, "name", name)
        object.__setattr__(self, "source", source)
        object.__setattr__(self, "description", description)
        object.__setattr__(self, "_succ", self._covering())

    # ---------------------------------------------------------------- structure

    def __len__(self) -> int:
        return len(self.predicates)

    @property
    def is_chain(self) -> bool:
        """Whether the order is total (a chain)."""
        return self.order is None

    @property
    def num_abstract_states(self) -> int:
        """``len(self) + 1``: the start plus one state per subgoal (the terminal one is extra)."""
        return len(self) + 1

    def successors(self, z: int) -> tuple[int, ...]:
        """Subgoal indices achievable next from abstract state ``z``."""
        succ: tuple[tuple[int, ...], ...] = self._succ  # type: ignore[attr-defined]
        return succ[z]

    def parents(self, z: int) -> tuple[int, ...]:
        """The abstract states from which ``z`` is entered (``()`` for the start, ``z = 0``).

        Examples:
            >>> from torchrl_subgoal.subgoals import Cell
            >>> diamond = SubgoalSeries([Cell(1, 1), Cell(2, 2), Cell(3, 3)], order=[(0, 2), (1, 2)])
            >>> diamond.parents(3), diamond.parents(1)
            ((1, 2), (0,))
        """
        if z == 0:
            return ()
        return tuple(node for node in range(self.num_abstract_states) if z - 1 in self.successors(node))

    def ancestors(self, z: int) -> tuple[int, ...]:
        """``z`` and every abstract state an episode can pass through before entering it.

        Examples:
            >>> from torchrl_subgoal.subgoals import Cell
            >>> SubgoalSeries([Cell(1, 1), Cell(2, 2), Cell(3, 3)], order=[(0, 2), (1, 2)]).ancestors(3)
            (0, 1, 2, 3)
        """
        seen, stack = {z}, [z]
        while stack:
            for p in self.parents(stack.pop()):
                if p not in seen:
                    seen.add(p)
                    stack.append(p)
        return tuple(sorted(seen))

    @property
    def levels(self) -> tuple[int, ...]:
        """For every abstract state, the number of subgoals achieved on the longest way to it: ``z`` in a
        chain; in a partial order, one more than the deepest of its :meth:`parents`.

        Examples:
            >>> from torchrl_subgoal.subgoals import Cell
            >>> SubgoalSeries([Cell(1, 1), Cell(2, 2)]).levels
            (0, 1, 2)
            >>> SubgoalSeries([Cell(1, 1), Cell(2, 2), Cell(3, 3)], order=[(0, 2), (1, 2)]).levels
            (0, 1, 1, 2)
        """
        levels = [0] * self.num_abstract_states
        for _ in range(len(self)):  # a path has at most len(self) subgoals: that many relaxations settle it
            for z in range(1, self.num_abstract_states):
                levels[z] = 1 + max(levels[p] for p in self.parents(z))
        return tuple(levels)

    def progress(self, scale: float = 1.0) -> tuple[float, ...]:
        """The progress prior of every abstract state: ``scale · level / (depth + 1)``, where ``depth`` is
        the deepest level. The goal, one stage further, would be worth ``scale``: each subgoal achieved
        adds an equal share of it.

        Examples:
            >>> from torchrl_subgoal.subgoals import Cell
            >>> SubgoalSeries([Cell(1, 1), Cell(2, 2), Cell(3, 3)]).progress(2.0)
            (0.0, 0.5, 1.0, 1.5)
        """
        levels = self.levels
        return tuple(scale * level / (max(levels) + 1) for level in levels)

    def _covering(self) -> tuple[tuple[int, ...], ...]:
        n = len(self)
        if self.order is None:
            return tuple((z,) if z < n else () for z in range(n + 1))
        after: list[set[int]] = [set() for _ in range(n)]
        for a, b in self.order:
            after[a].add(b)
        # topological order (Kahn); what is left over lies on or after a cycle
        indegree = [0] * n
        for a in range(n):
            for b in after[a]:
                indegree[b] += 1
        sources = tuple(i for i in range(n) if indegree[i] == 0)
        topo, stack = [], list(sources)
        while stack:
            v = stack.pop()
            topo.append(v)
            for b in after[v]:
                indegree[b] -= 1
                if indegree[b] == 0:
                    stack.append(b)
        if len(topo) < n:
            self._raise_cycle(after, set(range(n)) - set(topo))
        # reach[a]: bitset of the subgoals after a, filled in reverse topological order
        reach = [0] * n
        for a in reversed(topo):
            for b in after[a]:
                reach[a] |= reach[b] | (1 << b)
        # b directly follows a when no other successor c of a comes before b
        cover = []
        for a in range(n):
            later = 0
            for c in after[a]:
                later |= reach[c]
            cover.append(tuple(sorted(b for b in after[a] if not later >> b & 1)))
        return (tuple(sorted(sources)), *cover)

    def _raise_cycle(self, after: list[set[int]], left: set[int]) -> NoReturn:
        """Name the first subgoal (by index) that lies on a cycle of the order."""
        for start in sorted(left):
            seen: set[int] = set()
            stack = [b for b in after[start] if b in left]
            while stack:
                v = stack.pop()
                if v == start:
                    names = self.names or tuple(str(i) for i in range(len(self)))
                    raise SubgoalFileError(
                        f"{_where(self.source, self.name, 'order')}: the order has a cycle through "
                        f"subgoal {names[start]!r}"
                    )
                if v not in seen:
                    seen.add(v)
                    stack.extend(b for b in after[v] if b in left)
        raise AssertionError("no cycle found among the subgoals a topological order left over")

    # ---------------------------------------------------------------- file I/O

    def to_dict(self) -> dict[str, Any]:
        """The pattern as it appears in a subgoal file (``patterns: {name: <this>}``)."""
        out: dict[str, Any] = {} if self.description is None else {"description": self.description}
        if self.order is None and self.names is None:
            return {**out, "subgoals": [p.to_dict() for p in self.predicates]}
        names = self.names or tuple(f"sg{i}" for i in range(len(self)))
        out["subgoals"] = {nm: p.to_dict() for nm, p in zip(names, self.predicates, strict=True)}
        edges = self.order if self.order is not None else tuple((i, i + 1) for i in range(len(self) - 1))
        out["order"] = [[names[a], names[b]] for a, b in edges]
        return out

    @classmethod
    def random(
        cls,
        candidates: Sequence[Predicate],
        num_subgoals: int,
        generator: torch.Generator,
        *,
        name: str = "random",
    ) -> SubgoalSeries:
        """A chain of ``num_subgoals`` distinct predicates drawn from ``candidates``.

        This is the random-subgoal baseline (RRS): for a grid, the candidates
        are the free cells; for a continuous map, circles at free positions.
        """
        if num_subgoals > len(candidates):
            raise ValueError(f"cannot draw {num_subgoals} subgoals from {len(candidates)} candidates")
        picks = torch.randperm(len(candidates), generator=generator)[:num_subgoals].tolist()
        return cls([candidates[i] for i in picks], name=name)
