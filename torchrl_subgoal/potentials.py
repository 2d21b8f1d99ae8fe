"""Potential functions ``Φ`` over the abstract state kept by the transform.

The shaping reward is ``F = γ Φ(next) − Φ(current)``. A potential reads some of
the abstract-state entries the transform keeps in the TensorDict:

* ``"subgoal_index"`` — ``z``, the node of the subgoal series reached;
* ``"subgoal_anchor"`` — the observation at the moment ``z`` was entered;
* ``"subgoal_achieved"`` — whether ``z`` was entered on this very step.

:class:`TabularPotential` (``V[z]``, one table per learner of a batch) and
:class:`NeuralPotential` (``V(o_z; θ)``) are learned by
:class:`~torchrl_subgoal.SubgoalValueLoss`; :class:`NaivePotential` is the
fixed ``η`` of the naive subgoal shaping baseline (NRS).

Every potential returns values shaped like its inputs' batch with a trailing
singleton, ``[*B, 1]``, as TorchRL value networks do.
"""

from __future__ import annotations

import torch
from tensordict.nn import TensorDictModule
from torch import nn

__all__ = ["NaivePotential", "NeuralPotential", "Potential", "TabularPotential"]

INDEX = "subgoal_index"
ANCHOR = "subgoal_anchor"
ACHIEVED = "subgoal_achieved"


class Potential(nn.Module):
    """Base class: a module mapping abstract-state entries to ``Φ`` of shape ``[*B, 1]``.

    Subclasses set :attr:`in_keys` (a subset of ``"subgoal_index"``,
    ``"subgoal_anchor"``, ``"subgoal_achieved"``) and take those tensors, in
    that order, as positional arguments.
    """

    in_keys: tuple[str, ...] = ()

    def as_value_operator(self, out_key: str = "state_value") -> TensorDictModule:
        """This potential as a TensorDict module, the value network of TorchRL estimators."""
        return TensorDictModule(self, in_keys=list(self.in_keys), out_keys=[out_key])


class TabularPotential(Potential):
    """``V[z]``: one table of abstract-state values per learner.

    Args:
        num_states: number of abstract states (``SubgoalSeries.num_abstract_states``
            or the aggregation's ``num_states``).
        batch_shape: shape of the learner batch (the env's batch size);
            ``()`` for a single learner. Inputs have this shape as leading
            dimensions, optionally followed by more (e.g. time) dims.
        init: initial value of every entry.

    Examples:
        >>> import torch
        >>> from torchrl_subgoal import TabularPotential
        >>> v = TabularPotential(3, batch_shape=(2,))
        >>> with torch.no_grad():
        ...     v.table[1, 2] = 0.5
        >>> v(torch.tensor([[2], [2]]))
        tensor([[0.0000],
                [0.5000]], grad_fn=<ViewBackward0>)
    """

    in_keys = (INDEX,)

    def __init__(self, num_states: int, batch_shape: tuple[int, ...] | torch.Size = (), init: float = 0.0):
        super().__init__()
        self.batch_shape = torch.Size(batch_shape)
        self.num_states = int(num_states)
        self.table = nn.Parameter(torch.full((*self.batch_shape, self.num_states), float(init)))

    def forward(self, z: torch.Tensor) -> torch.Tensor:
        if z.shape[-1:] != (1,):
            raise ValueError(f"subgoal_index must end with a singleton dim, got shape {tuple(z.shape)}")
        nb = len(self.batch_shape)
        if z.shape[:nb] != self.batch_shape:
            raise ValueError(
                f"subgoal_index of shape {tuple(z.shape)} does not start with the learner batch "
                f"shape {tuple(self.batch_shape)}"
            )
        if nb == 0:
            return self.table[z]
        learners = self.batch_shape.numel()
        table = self.table.reshape(learners, self.num_states)
        return table.gather(1, z.reshape(learners, -1)).view(z.shape)


class NeuralPotential(Potential):
    """``V(o_z; θ)``: a network over the observation at which ``z`` was entered.

    Args:
        network: maps ``[*B, D]`` anchor observations to ``[*B, 1]`` values
            (for pick-and-place, the critic's hidden layers without the action).

    Examples:
        >>> import torch
        >>> from torch import nn
        >>> from torchrl_subgoal import NeuralPotential
        >>> v = NeuralPotential(nn.Linear(4, 1))
        >>> v(torch.zeros(5, 4)).shape
        torch.Size([5, 1])
    """

    in_keys = (ANCHOR,)

    def __init__(self, network: nn.Module):
        super().__init__()
        self.network = network

    def forward(self, anchor: torch.Tensor) -> torch.Tensor:
        return self.network(anchor.float())


class NaivePotential(Potential):
    """``Φ = η`` on the step a subgoal is achieved, else 0 (naive subgoal shaping, NRS).

    The achieving step earns ``γη`` and the next step ``−η``: a fixed pulse,
    never learned.

    Args:
        eta: the potential of a subgoal state (the paper uses 1 in four-rooms,
            10,000 in PinBall).

    Examples:
        >>> import torch
        >>> from torchrl_subgoal import NaivePotential
        >>> NaivePotential(10.0)(torch.tensor([[True], [False]]))
        tensor([[10.],
                [ 0.]])
    """

    in_keys = (ACHIEVED,)

    def __init__(self, eta: float):
        super().__init__()
        self.eta = float(eta)

    def forward(self, achieved: torch.Tensor) -> torch.Tensor:
        return achieved.to(torch.get_default_dtype()) * self.eta
