"""The learner sees ``z``: the subgoal index, one-hot, as an extra input of a network.

The shaped reward ``r + γΦ(z') − Φ(z)`` depends on the abstract state ``z``
(how far along the subgoal series the episode is), which the observation alone
does not tell: a critic over ``s`` alone sees a reward that is not Markov in
its input. :class:`SubgoalInput` joins the one-hot ``z`` that the shaping
transform keeps (``"subgoal_index"``) to the features of the observation, so
that a policy, a critic or a Q-network reads ``(s, z)``.
"""

from __future__ import annotations

import torch
from torch import nn

__all__ = ["SUBGOAL_INDEX", "SubgoalInput"]

#: The shaping transform's entry holding ``z`` (:class:`~torchrl_subgoal.SubgoalKeys`' default ``index``).
SUBGOAL_INDEX = "subgoal_index"


class SubgoalInput(nn.Module):
    """``body(join(features(x), one_hot(z)))``: a network over an input and the subgoal index ``z``.

    The join concatenates the features and the one-hot ``z`` (``product=False``:
    a network with hidden layers can learn how ``z`` interacts with the
    observation; a linear one adds one term per ``z`` to its output, the form of
    a shaped value ``V(s) − Φ(z)``), or takes their outer product
    (``product=True``: one copy of the features per ``z``, one weight set per
    abstract state, each trained only on the steps spent in it; over one-hot
    states, a table over ``(s, z)``; a linear critic can then also learn
    ``V(s) − Φ(s, z)`` of a potential that varies within a segment).

    Args:
        num_states: abstract states ``z`` can take (``series.num_abstract_states``).
        features: applied to the first input before the join (default: none).
        body: applied to the joined vector (default: none, the joined vector is the output).
        product: outer product instead of concatenation.

    Examples:
        >>> net = SubgoalInput(3, body=nn.Identity())
        >>> net(torch.tensor([[0.5, 0.25]]), torch.tensor([[2]])).tolist()
        [[0.5, 0.25, 0.0, 0.0, 1.0]]
        >>> SubgoalInput(3, product=True)(torch.tensor([[0.5, 0.25]]), torch.tensor([[1]])).tolist()
        [[0.0, 0.5, 0.0, 0.0, 0.25, 0.0]]
        >>> SubgoalInput.size(2, 3), SubgoalInput.size(2, 3, product=True)
        (5, 6)
    """

    def __init__(
        self,
        num_states: int,
        features: nn.Module | None = None,
        body: nn.Module | None = None,
        *,
        product: bool = False,
    ) -> None:
        super().__init__()
        if num_states < 1:
            raise ValueError(f"num_states must be >= 1, got {num_states}")
        self.num_states, self.product = int(num_states), bool(product)
        self.features = features if features is not None else nn.Identity()
        self.body = body if body is not None else nn.Identity()

    @staticmethod
    def size(features: int, num_states: int, *, product: bool = False) -> int:
        """Entries of the joined vector for ``features`` entries and ``num_states`` abstract states."""
        return features * num_states if product else features + num_states

    def forward(self, x: torch.Tensor, subgoal_index: torch.Tensor) -> torch.Tensor:
        h = self.features(x)
        z = nn.functional.one_hot(subgoal_index.reshape(h.shape[:-1]).long(), self.num_states).to(h.dtype)
        joined = (h.unsqueeze(-1) * z.unsqueeze(-2)).flatten(-2) if self.product else torch.cat([h, z], -1)
        return self.body(joined)
