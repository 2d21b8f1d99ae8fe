"""Achievement predicates: the built-in regions (state, cell, circle, box) and conditions on the TensorDict."""

from __future__ import annotations

import importlib
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import torch
from tensordict import TensorDictBase

from torchrl_subgoal.subgoals.errors import SubgoalFileError


@dataclass(frozen=True)
class Region:
    """A predicate compiled over an observation of ``size`` entries (see module doc).

    Examples:
        >>> region = Cell(4, 9).region(2)
        >>> region.lo.tolist(), region.hi.tolist()
        ([4.0, 9.0], [4.0, 9.0])
    """

    lo: torch.Tensor
    hi: torch.Tensor
    centre: torch.Tensor
    weight: torch.Tensor
    radius2: float


class Predicate:
    """Base class of achievement predicates.

    A predicate either compiles to a :class:`Region` of one observation entry
    (the built-ins: override :meth:`region` and :meth:`dims`), or is a
    *condition* on the step's TensorDict: override :meth:`__call__` to return
    a boolean mask of the batch (see :class:`Condition`).

    Examples:
        >>> cell = Cell(4, 9)
        >>> isinstance(cell, Predicate), cell.compiled, cell.to_dict()
        (True, True, {'cell': [4, 9]})
    """

    kind: str = "predicate"

    @property
    def compiled(self) -> bool:
        """Whether the predicate is a region (else it is called on the TensorDict)."""
        return type(self).region is not Predicate.region

    def __call__(self, tensordict: TensorDictBase) -> torch.Tensor:
        """The mask ``[*B]`` (or ``[*B, 1]``) of rows of ``tensordict`` that achieve the subgoal."""
        raise NotImplementedError(f"{type(self).__name__} is a region predicate; SubgoalTables evaluates it")

    def dims(self) -> tuple[int, ...]:
        """Observation entries the predicate reads."""
        return ()

    def region(self, size: int, one_hot: bool = False) -> Region:
        """Compile to a :class:`Region` over an observation with ``size`` entries."""
        raise NotImplementedError

    def to_dict(self) -> dict[str, Any]:
        """The predicate as it appears in a subgoal file."""
        raise NotImplementedError

    def _open_region(self, size: int) -> tuple[torch.Tensor, torch.Tensor]:
        lo = torch.full((size,), -math.inf)
        hi = torch.full((size,), math.inf)
        return lo, hi


@dataclass(frozen=True)
class State(Predicate):
    """A discrete observation equals ``state``.

    Works on a scalar categorical observation (``o == state``) and on a one-hot
    observation (``o[state] == 1``).

    Examples:
        >>> State(24).to_dict()  # as in a subgoal file
        {'state': 24}
        >>> State(2).region(4, one_hot=True).lo.tolist()  # o[2] == 1 in a one-hot observation of 4
        [-inf, -inf, 1.0, -inf]
    """

    state: int
    kind = "state"

    def dims(self) -> tuple[int, ...]:
        return (0,)

    def region(self, size: int, one_hot: bool = False) -> Region:
        lo, hi = self._open_region(size)
        if one_hot:
            if not 0 <= self.state < size:
                raise IndexError(f"state {self.state} outside a one-hot observation of size {size}")
            lo[self.state] = hi[self.state] = 1.0
        else:
            lo[0] = hi[0] = float(self.state)
        return Region(lo, hi, torch.zeros(size), torch.zeros(size), math.inf)

    def to_dict(self) -> dict[str, Any]:
        return {"state": self.state}


@dataclass(frozen=True)
class Cell(Predicate):
    """Observation entries ``dims`` (default the first two) equal ``(row, col)``.

    Examples:
        >>> Cell(3, 6).to_dict()
        {'cell': [3, 6]}
        >>> Cell(3, 6, cell_dims=(1, 2)).to_dict()
        {'cell': [3, 6], 'dims': [1, 2]}
    """

    row: int
    col: int
    cell_dims: tuple[int, int] = (0, 1)
    kind = "cell"

    def dims(self) -> tuple[int, ...]:
        return self.cell_dims

    def region(self, size: int, one_hot: bool = False) -> Region:
        lo, hi = self._open_region(size)
        for d, v in zip(self.cell_dims, (self.row, self.col), strict=True):
            lo[d] = hi[d] = float(v)
        return Region(lo, hi, torch.zeros(size), torch.zeros(size), math.inf)

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"cell": [self.row, self.col]}
        if self.cell_dims != (0, 1):
            out["dims"] = list(self.cell_dims)
        return out


@dataclass(frozen=True)
class Circle(Predicate):
    """Observation entries ``dims`` lie within ``radius`` of ``centre`` (boundary included).

    Examples:
        >>> Circle((0.5, 0.2), 0.04).to_dict()
        {'circle': {'centre': [0.5, 0.2], 'radius': 0.04}}
    """

    centre: tuple[float, ...]
    radius: float
    circle_dims: tuple[int, ...] | None = None
    kind = "circle"

    def dims(self) -> tuple[int, ...]:
        return self.circle_dims if self.circle_dims is not None else tuple(range(len(self.centre)))

    def region(self, size: int, one_hot: bool = False) -> Region:
        lo, hi = self._open_region(size)
        centre = torch.zeros(size)
        weight = torch.zeros(size)
        for d, c in zip(self.dims(), self.centre, strict=True):
            centre[d] = c
            weight[d] = 1.0
        return Region(lo, hi, centre, weight, self.radius**2)

    def to_dict(self) -> dict[str, Any]:
        body: dict[str, Any] = {"centre": list(self.centre), "radius": self.radius}
        if self.circle_dims is not None:
            body["dims"] = list(self.circle_dims)
        return {"circle": body}


@dataclass(frozen=True)
class Box(Predicate):
    """Observation entries ``dims`` lie within ``centre ± margin`` (per component).

    Examples:
        >>> Box((0.0, 0.0), (0.01, 0.01), (6, 7)).to_dict()
        {'box': {'centre': [0.0, 0.0], 'margin': 0.01, 'dims': [6, 7]}}
    """

    centre: tuple[float, ...]
    margin: tuple[float, ...]
    box_dims: tuple[int, ...]
    kind = "box"

    def dims(self) -> tuple[int, ...]:
        return self.box_dims

    def region(self, size: int, one_hot: bool = False) -> Region:
        lo, hi = self._open_region(size)
        for d, c, m in zip(self.box_dims, self.centre, self.margin, strict=True):
            lo[d] = c - m
            hi[d] = c + m
        return Region(lo, hi, torch.zeros(size), torch.zeros(size), math.inf)

    def to_dict(self) -> dict[str, Any]:
        margin: float | list[float] = self.margin[0] if len(set(self.margin)) == 1 else list(self.margin)
        return {"box": {"centre": list(self.centre), "margin": margin, "dims": list(self.box_dims)}}

    def outside(self, bounds: Sequence[tuple[float, float]], names: Sequence[str]) -> str | None:
        """Why the box misses an observation whose entry ``d`` lies in ``bounds[d]`` (named ``names[d]``), or
        ``None`` when it overlaps every entry it covers (its dims must index ``bounds``).

        Examples:
            >>> Box((2.0,), (0.5,), (1,)).outside([(-1.0, 1.0), (-1.0, 1.0)], ["x", "y"])
            'y: the box [1.5, 2.5] lies outside [-1.0, 1.0]'
        """
        for dim, centre, margin in zip(self.box_dims, self.centre, self.margin, strict=True):
            low, high = bounds[dim]
            if centre + margin < low or centre - margin > high:
                span = f"[{centre - margin:.3g}, {centre + margin:.3g}]"
                return f"{names[dim]}: the box {span} lies outside [{low}, {high}]"
        return None


def _import_path(fn: Any) -> str | None:
    """``"module:qualname"`` of a module-level function or class, else ``None``."""
    module, qualname = getattr(fn, "__module__", None), getattr(fn, "__qualname__", None)
    if not module or not qualname or "<" in qualname or module == "__main__":
        return None
    return f"{module}:{qualname}"


class Condition(Predicate):
    """A subgoal achieved where ``fn(tensordict)`` holds: any condition on the step's entries.

    ``fn`` receives the TensorDict the subgoal is tested on — the ``"next"``
    entries of an env step, batch shape ``[*B]`` — and returns a boolean mask
    ``[*B]`` (or ``[*B, 1]``). It may read any entry: another observation than
    the one the built-in predicates or the potential read, a flag of a dict
    observation, a field decoded from a packed discrete state. Conditions are
    evaluated once per step for the whole batch (a vectorised torch
    expression, not a per-env loop).

    Args:
        fn: the function (a plain function given as a subgoal is wrapped in a ``Condition``).
        name: a label for messages (default: the function's name).

    Keyword Args:
        path: the ``"module:attribute"`` import path a subgoal file names it by
            (derived for a module-level function, so :func:`save_patterns` can write it).
        args: with ``args``, the attribute at ``path`` is a factory and ``fn`` is
            ``factory(**args)`` (see :meth:`from_path`).

    Examples:
        >>> import torch
        >>> from tensordict import TensorDict
        >>> from torchrl_subgoal import Condition
        >>> carrying = Condition(lambda td: td["inventory"] > 0, name="carrying")
        >>> carrying(TensorDict({"inventory": torch.tensor([0, 2])}, [2]))
        tensor([False,  True])
    """

    kind = "call"

    def __init__(
        self,
        fn: Callable[[TensorDictBase], torch.Tensor],
        name: str | None = None,
        *,
        path: str | None = None,
        args: Mapping[str, Any] | None = None,
    ) -> None:
        if not callable(fn):
            raise TypeError(f"a Condition needs a callable, got {type(fn).__name__}")
        self.fn = fn
        self.name = name or getattr(fn, "__name__", type(fn).__name__)
        self.args = dict(args) if args else None
        self.path = path if path is not None or self.args else _import_path(fn)

    @classmethod
    def from_path(cls, path: Any, args: Any = None, *, where: str = "call") -> Condition:
        """Import ``"package.module:function"`` (or ``"package.module.function"``); with ``args``
        (a mapping) call it with them to build the function. Errors name ``where``.

        Examples:
            >>> Condition.from_path("operator:truth").name
            'truth'
        """
        if not isinstance(path, str) or not path.strip():
            raise SubgoalFileError(
                f"{where}: expected an import path such as 'my_package.subgoals:carrying', got {path!r}"
            )
        if args is not None and not isinstance(args, Mapping):
            raise SubgoalFileError(f"{where}: args: expected a mapping of keyword arguments, got {args!r}")
        module_name, sep, attr = path.partition(":")
        if not sep:
            module_name, _, attr = path.rpartition(".")
        if not module_name or not attr:
            raise SubgoalFileError(f"{where}: {path!r} is not 'module:function'")
        try:
            obj: Any = importlib.import_module(module_name)
        except ImportError as exc:
            raise SubgoalFileError(
                f"{where}: cannot import module {module_name!r} ({exc}); is it installed or on PYTHONPATH?"
            ) from None
        for part in attr.split("."):
            if not hasattr(obj, part):
                raise SubgoalFileError(f"{where}: module {module_name!r} has no attribute {attr!r}")
            obj = getattr(obj, part)
        if args:
            try:
                obj = obj(**args)
            except Exception as exc:
                raise SubgoalFileError(f"{where}: {path}(**args) failed: {exc}") from None
        if not callable(obj):
            raise SubgoalFileError(f"{where}: {path!r} is not callable")
        return cls(obj, name=attr.split(".")[-1], path=f"{module_name}:{attr}", args=args)

    def __call__(self, tensordict: TensorDictBase) -> torch.Tensor:
        return self.fn(tensordict)

    def _identity(self) -> tuple[Any, ...]:
        if self.path is not None:
            return (self.path, tuple(sorted((self.args or {}).items(), key=lambda kv: kv[0])))
        return (id(self.fn),)

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Condition) and self._identity() == other._identity()

    def __hash__(self) -> int:
        try:
            return hash(self._identity())
        except TypeError:  # unhashable args
            return hash(self.path)

    def __repr__(self) -> str:
        return f"Condition({self.path or self.name!r})"

    def to_dict(self) -> dict[str, Any]:
        if self.path is None:
            raise SubgoalFileError(
                f"condition {self.name!r} has no import path (a lambda or a local function): define it at "
                "module level, or pass path='module:function', to write it to a subgoal file"
            )
        out: dict[str, Any] = {"call": self.path}
        if self.args:
            out["args"] = dict(self.args)
        return out
