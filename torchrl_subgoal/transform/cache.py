"""The by-value cache of ``Φ`` the torch step keeps: a neural potential is evaluated again only when its
inputs or its parameters changed (a step without an achievement evaluates nothing)."""

from __future__ import annotations

import torch
from tensordict.nn import TensorDictModuleBase

__all__ = ["ValueCache"]


class ValueCache:
    """``Φ`` of the last inputs seen under each slot, given back while the inputs (compared by value)
    and the potential's parameters and buffers are unchanged.

    The parameters are compared by value with a copy taken when they last changed: an in-place
    update that moves no version counter (through ``.data``, TorchRL's weight updates, or another
    process writing shared memory) is seen too. Assumes ``Φ`` is a deterministic function of its
    inputs and those tensors (no dropout).

    Examples:
        >>> from torchrl_subgoal import TabularPotential
        >>> v, cache = TabularPotential(3), ValueCache()
        >>> cache.check(v)
        >>> cache.put("z", {"subgoal_index": torch.tensor([[1]])}, torch.tensor([[0.5]]))
        >>> one, two = {"subgoal_index": torch.tensor([[1]])}, {"subgoal_index": torch.tensor([[2]])}
        >>> cache.get("z", one).item(), cache.get("z", two)
        (0.5, None)
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


_NUMPY_DTYPES = (torch.float32, torch.float64, torch.int64, torch.bool)
