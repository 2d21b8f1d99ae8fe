"""The within-segment term of an interpolating potential (``TabularPotential(interpolate=True)``).

Between two subgoals the abstract state ``z`` does not change, so a potential over ``z`` alone says
nothing until the next subgoal is reached; where the agent does not reach it by chance (a car that must
swing back up a hill first, a maze's far corner), it shapes nothing. For subgoals that are regions of the
observation (boxes, circles, cells) the potential can also say how close the next one is:

    Φ(s, z) = Φ(z) + max_j (Φ(z_j) − Φ(z))⁺ · 1 / (1 + d_j(s))

over the subgoals ``j`` that count from ``z`` (the next one, in a chain), ``z_j`` the abstract state
reaching ``j`` leads to, and ``d_j(s)`` the distance of the observation to ``j``'s region in units of the
region's own size (each box dimension's excess over its half-width, a circle's excess over its radius;
cells, of size 0, in the observation's units). At the region's boundary the term is the whole step up, so
``Φ`` is continuous where ``z`` changes, and no step pays more than the step up to the next subgoal; its
scale is the table's own, with no length to tune. It is potential-based over ``(s, z)``, so the optimal
policy is kept.
"""

from __future__ import annotations

import torch

from torchrl_subgoal.subgoals.tables import SubgoalTables

__all__ = ["closeness", "segment_term"]


def closeness(tables: SubgoalTables, observation: torch.Tensor) -> torch.Tensor:
    """``1 / (1 + d)`` of each row's observation to each of its regions, ``[B, J]`` (0 for padding, a
    condition or a discrete ``state``, which have no distance).

    Examples:
        >>> from torchrl_subgoal import Box, Circle, SubgoalSeries
        >>> series = SubgoalSeries([Box((0.0,), (1.0,), (0,)), Circle((4.0, 0.0), 1.0)])
        >>> tables = SubgoalTables([series], torch.zeros(2, dtype=torch.long), 2)
        >>> closeness(tables, torch.tensor([[3.0, 0.0], [0.5, 0.0]])).tolist()
        [[0.3333333432674408, 1.0], [1.0, 0.2857142984867096]]
    """
    obs = tables.rows(observation).unsqueeze(1).to(torch.float64)  # [B, 1, D], as the regions are tested
    lo, hi = tables.lo, tables.hi  # [B, J, D]
    bounded = torch.isfinite(lo) & torch.isfinite(hi)
    half = torch.where(bounded, (hi - lo) / 2, torch.ones_like(lo))
    half = torch.where(half > 0, half, torch.ones_like(half))
    excess = torch.maximum(lo - obs, obs - hi).clamp(min=0.0)
    box = torch.where(bounded, excess / half, torch.zeros_like(excess)).square().sum(-1)
    radius = tables.radius2.sqrt()  # [B, J]
    circle = torch.zeros_like(box)
    if tables.uses_circle:
        weighted = torch.where(tables.weight > 0, tables.weight * (obs - tables.centre).square(), 0.0)
        to_centre = weighted.sum(-1).sqrt()
        scale = torch.where(radius > 0, radius, torch.ones_like(radius))
        circle = torch.where(torch.isfinite(radius), ((to_centre - radius).clamp(min=0.0) / scale), 0.0).square()
    # only measured regions: padding, conditions and states are never measured (their lo, hi are never read)
    return torch.where(tables.measured, 1.0 / (1.0 + (box + circle).sqrt()), torch.zeros_like(box)).to(torch.float32)


def segment_term(
    tables: SubgoalTables, values: torch.Tensor, z: torch.Tensor, observation: torch.Tensor, offset: int = 1
) -> torch.Tensor:
    """The within-segment term at ``(s, z)``, ``[*B, 1]``: ``max_j (V[z_j] − V[z])⁺ · closeness_j(s)`` over the
    regions ``j`` that count from ``z`` (``values``: each row's table as it shapes, ``[B, n]``).

    Examples:
        >>> from torchrl_subgoal import Box, SubgoalSeries
        >>> series = SubgoalSeries([Box((0.0,), (1.0,), (0,)), Box((4.0,), (1.0,), (0,))])
        >>> tables = SubgoalTables([series], torch.zeros(2, dtype=torch.long), 1)
        >>> values = torch.tensor([[0.0, 1.0, 2.0], [0.0, 1.0, 2.0]])
        >>> segment_term(tables, values, torch.tensor([[0], [1]]), torch.tensor([[3.0], [3.0]])).tolist()
        [[0.3333333432674408], [1.0]]
    """
    rows = z.reshape(-1)
    near = closeness(tables, observation)  # [B, J]
    counts = tables.succ[torch.arange(rows.numel()), rows]  # [B, J]
    j = torch.arange(near.shape[1])
    reached = values[:, (j + offset).clamp(max=values.shape[1] - 1)]  # [B, J]: V of the state reaching j leads to
    step_up = (reached - values.gather(1, rows.unsqueeze(1))).clamp(min=0.0)
    term = torch.where(counts, step_up * near, torch.zeros_like(near)).amax(-1, keepdim=True)
    return term.view(*z.shape[:-1], 1)
