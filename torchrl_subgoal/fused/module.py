"""The base of the batched learners: an ``nn.Module`` whose tables compiled kernels update in place."""

from __future__ import annotations

import numpy as np
import torch
from torch import nn

__all__ = ["KernelLearner"]


class KernelLearner(nn.Module):
    """An ``nn.Module`` learner whose tables are buffers that numba kernels update in place.

    The tables, the per-learner state the next step needs and the random
    streams are registered buffers, so ``state_dict()`` / ``load_state_dict()``
    checkpoint a learner through torch (loading copies into the same memory)
    and ``.to(device, dtype)`` moves or casts them (the streams are integers
    and keep their type). The kernels read and write the buffers through
    :meth:`numpy_view`, a numpy array sharing the tensor's memory, so they run
    on the CPU: a learner moved elsewhere is moved back with ``.to("cpu")``
    before it learns.

    Examples:
        >>> import torch
        >>> class Counter(KernelLearner):
        ...     def __init__(self) -> None:
        ...         super().__init__()
        ...         self.register_buffer("table", torch.zeros(3))
        >>> counter = Counter()
        >>> counter.numpy_view("table")[1] = 5.0  # what a kernel does, in place
        >>> counter.table.tolist(), list(counter.state_dict())
        ([0.0, 5.0, 0.0], ['table'])
    """

    def numpy_view(self, name: str) -> np.ndarray:
        """The buffer ``name`` as a numpy array sharing its memory (for the kernels).

        Args:
            name: a buffer of this learner.

        Raises:
            RuntimeError: the buffer is not on the CPU.
        """
        tensor: torch.Tensor = getattr(self, name)
        if tensor.device.type != "cpu":
            raise RuntimeError(
                f"{type(self).__name__}.{name} is on {tensor.device}, but the learner's kernels run on the CPU; "
                "move it back with .to('cpu') before it learns"
            )
        return tensor.numpy()
