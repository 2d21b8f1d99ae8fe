"""Four-rooms (Sutton, Precup & Singh 1999) as a batched TorchRL env: batch = independent learners."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any, NamedTuple

import numpy as np
import torch
from tensordict import TensorDict, TensorDictBase
from tensordict.utils import NestedKey
from torchrl.data import Bounded, Categorical, Composite, Unbounded
from torchrl.envs import EnvBase

from torchrl_subgoal._kernels import steps
from torchrl_subgoal._kernels.grid import grid_reset, grid_reset_one, grid_step, grid_step_one
from torchrl_subgoal.subgoals import Cell, StateAggregation, SubgoalSeries

# fmt: off
__all__ = [
    "ACTIONS", "LAYOUT", "FourRoomsEnv", "draw_map", "free_cells", "goal_distances",
    "room_aggregation",
]
# fmt: on

LAYOUT = """\
wwwwwwwwwwwww
w     w     w
w     w     w
w           w
w     w     w
w     w     w
ww wwww     w
w     www www
w     w     w
w     w     w
w           w
w     w     w
wwwwwwwwwwwww"""

#: action index -> (d_row, d_col): down, right, up, left
ACTIONS = ((1, 0), (0, 1), (-1, 0), (0, -1))
START = (1, 1)
GOAL = (11, 11)
HALLWAYS = ((3, 6), (6, 2), (7, 9), (10, 6))
_ROWS = LAYOUT.splitlines()
SIZE = (len(_ROWS), len(_ROWS[0]))


def free_cells() -> list[tuple[int, int]]:
    """Free cells in row-major order; index = state number ((1,1) is 0, (11,11) is 103).

    Examples:
        >>> cells = free_cells()
        >>> len(cells), cells[0], cells[-1]
        (104, (1, 1), (11, 11))
    """
    return [(r, c) for r in range(SIZE[0]) for c in range(SIZE[1]) if _ROWS[r][c] != "w"]


_CELLS = free_cells()
_STATE = {cell: i for i, cell in enumerate(_CELLS)}


def goal_distances() -> dict[tuple[int, int], int]:
    """Fewest moves from every free cell to the goal (breadth-first search; moves are deterministic).

    Examples:
        >>> distance = goal_distances()
        >>> distance[START], distance[GOAL], len(distance)
        (20, 0, 104)
    """
    free = set(_CELLS)
    distance = {GOAL: 0}
    frontier = [GOAL]
    while frontier:
        nxt = []
        for r, c in frontier:
            for dr, dc in ACTIONS:
                cell = (r + dr, c + dc)
                if cell in free and cell not in distance:
                    distance[cell] = distance[(r, c)] + 1
                    nxt.append(cell)
        frontier = nxt
    return distance


def _room(cell: tuple[int, int]) -> int:
    """Room of a free cell: 0 top-left, 1 top-right, 2 bottom-left, 3 bottom-right.

    Hallways (3,6) and (6,2) belong to the top-left room, (7,9) to the
    top-right and (10,6) to the bottom-left (the SARSA-RS aggregation).
    """
    if cell in ((3, 6), (6, 2)):
        return 0
    if cell == (7, 9):
        return 1
    if cell == (10, 6):
        return 2
    r, c = cell
    left = c < 6
    if r <= 6:  # the top rooms span rows 1-6 (row 6 on the left is wall but for a hallway)
        return 0 if left else 1
    return 2 if left else 3


def room_aggregation() -> StateAggregation:
    """``g(s)`` = room of state ``s``: the SARSA-RS baseline's aggregation (4 abstract states).

    Examples:
        >>> aggregation = room_aggregation()
        >>> aggregation.num_states
        4
    """
    return StateAggregation(torch.tensor([_room(c) for c in _CELLS]), num_states=4)


class GridKernelState(NamedTuple):
    """A :class:`FourRoomsEnv`'s state and tables as numpy views, and its settings, for compiled loops
    (:func:`~torchrl_subgoal._kernels.grid.grid_step_one` steps one learner in place).

    Examples:
        >>> state = FourRoomsEnv(num_envs=2).kernel_state()
        >>> state.transitions.shape, state.cells.shape  # 104 free cells, 4 moves
        ((104, 4), (104, 2))
    """

    state: np.ndarray  #: ``[N]`` state number of every learner
    t: np.ndarray  #: ``[N]`` steps into the episode
    transitions: np.ndarray  #: ``[S, 4]`` next state of every state and action
    cells: np.ndarray  #: ``[S, 2]`` (row, column) of every state
    observed: (
        np.ndarray
    )  #: ``[S, D]`` what the shaping of a compiled loop reads in every state (see :meth:`FourRoomsEnv.kernel_state`)
    start: int  #: the start state
    goal: int  #: the goal state
    max_steps: int  #: steps before truncation
    goal_reward: float  #: reward on reaching the goal
    step_reward: float  #: reward of every other step


class FourRoomsEnv(EnvBase):
    """The four-rooms grid world, batched: each env of the batch is an independent learner.

    13 x 13 grid with 104 free cells, start (1, 1), goal (11, 11), four
    deterministic moves (0 down, 1 right, 2 up, 3 left; into a wall = stay),
    reward ``goal_reward`` on reaching the goal (terminated) and
    ``step_reward`` on every other step, truncation after ``max_steps``. The
    defaults are the paper's (+1 at the goal, 0 otherwise); ``goal_reward=0,
    step_reward=-1`` is the step-cost variant (−1 per step, 0 at the goal).
    The shortest path takes 20 steps.

    Observations: ``"observation"`` the state number (free cells numbered
    row-major, a ``Categorical(104)``) and ``"cell"`` its ``(row, col)``.

    Another map can be given as ``layout`` (rows of equal length, ``w`` for a
    wall), with its own ``start`` and ``goal`` cells: a maze, a corridor, rooms
    of another size; the rest works alike.

    Args:
        num_envs: batch size; ``None`` for a single unbatched env.
        max_steps: episode cap (1,000 in the paper).
        goal_reward: reward of the step that reaches the goal.
        step_reward: reward of every other step.
        layout: the map (default: the four rooms).
        start: the start cell ``(row, col)``.
        goal: the goal cell.
        device: torch device.

    Examples:
        >>> from torchrl.envs.utils import check_env_specs
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> env = FourRoomsEnv(num_envs=3)
        >>> check_env_specs(env)
        >>> env.reset()["cell"][0].tolist()
        [1, 1]
        >>> step_cost = FourRoomsEnv(num_envs=2, goal_reward=0.0, step_reward=-1.0)
        >>> step_cost.rollout(3)["next", "reward"][0, :, 0].tolist()
        [-1.0, -1.0, -1.0]
        >>> corridor = FourRoomsEnv(2, layout="wwwww\\nw   w\\nwwwww", start=(1, 1), goal=(1, 3))
        >>> corridor.num_states, corridor.rollout(2, lambda td: td.set("action", torch.ones(2, dtype=torch.long)))[
        ...     "next", "terminated"][0, :, 0].tolist()
        (3, [False, True])
    """

    batch_locked = True
    #: steps a learner makes per call of the fused engine's compiled loop (a four-rooms step is short)
    fused_block = 2048

    def __init__(
        self,
        num_envs: int | None = None,
        *,
        max_steps: int = 1000,
        goal_reward: float = 1.0,
        step_reward: float = 0.0,
        layout: str = LAYOUT,
        start: tuple[int, int] = START,
        goal: tuple[int, int] = GOAL,
        device: Any = "cpu",
    ) -> None:
        batch = torch.Size([]) if num_envs is None else torch.Size([num_envs])
        if num_envs is not None and num_envs < 1:
            raise ValueError(f"num_envs must be positive, got {num_envs}")
        if max_steps < 1:
            raise ValueError(f"max_steps must be positive, got {max_steps}")
        super().__init__(batch_size=batch, device=device)
        self.max_steps = int(max_steps)
        self.goal_reward = float(goal_reward)
        self.step_reward = float(step_reward)
        cells, size = _CELLS, SIZE
        if layout != LAYOUT:
            rows = layout.splitlines()
            if not rows or len({len(row) for row in rows}) != 1:
                raise ValueError("layout: give rows of equal length ('w' for a wall)")
            size = (len(rows), len(rows[0]))
            cells = [(r, c) for r in range(size[0]) for c in range(size[1]) if rows[r][c] != "w"]
        state = {cell: i for i, cell in enumerate(cells)}
        start, goal = (int(start[0]), int(start[1])), (int(goal[0]), int(goal[1]))
        for name, cell in (("start", start), ("goal", goal)):
            if cell not in state:
                raise ValueError(f"{name}: {cell} is not a free cell of the layout")
        n = len(cells)
        moves = [[state.get((r + dr, c + dc), state[(r, c)]) for dr, dc in ACTIONS] for r, c in cells]
        self.transitions = torch.tensor(moves, device=self.device)  # [S, A] next state
        self.cells = torch.tensor(cells, device=self.device)  # [S, 2]
        self.start_state = state[start]
        self.goal_state = state[goal]
        self.num_states = n
        self.observation_spec = Composite(
            observation=Categorical(n, shape=batch, dtype=torch.long, device=self.device),
            cell=Bounded(0, max(size) - 1, shape=(*batch, 2), dtype=torch.long, device=self.device),
            shape=batch,
        )
        self.action_spec = Categorical(len(ACTIONS), shape=batch, dtype=torch.long, device=self.device)
        self.reward_spec = Unbounded(shape=(*batch, 1), dtype=torch.float32, device=self.device)
        flag = Categorical(2, shape=(*batch, 1), dtype=torch.bool, device=self.device)
        self.full_done_spec = Composite(
            done=flag, terminated=flag.clone(), truncated=flag.clone(), shape=batch, device=self.device
        )
        flat = max(1, batch.numel())
        self._state = torch.full((flat,), self.start_state, dtype=torch.long, device=self.device)
        self._t = torch.zeros(flat, dtype=torch.long, device=self.device)
        if self.device.type == "cpu":
            self._transitions_np = self.transitions.numpy()
            self._cells_np = self.cells.numpy()
            self._numbers_np = np.arange(n, dtype=self._cells_np.dtype).reshape(n, 1)

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs: Any) -> TensorDictBase:
        reset = tensordict.get("_reset", None) if tensordict is not None else None
        shape = self.batch_size
        n = self._state.numel()
        mask = torch.ones(n, dtype=torch.bool, device=self.device) if reset is None else reset.reshape(-1)
        cell = torch.empty((*shape, 2), dtype=torch.long, device=self.device)
        if self.device.type == "cpu":
            grid_reset(self.kernel_state(), mask.numpy(), cell.numpy().reshape(n, 2))
        else:
            self._state.masked_fill_(mask, self.start_state)
            self._t.masked_fill_(mask, 0)
            cell.copy_(self.cells[self._state].view_as(cell))
        false = torch.zeros((*shape, 1), dtype=torch.bool, device=self.device)
        return TensorDict(
            {
                "observation": self._state.clone().view(shape),
                "cell": cell,
                "done": false,
                "terminated": false.clone(),
                "truncated": false.clone(),
            },
            batch_size=shape,
            device=self.device,
        )

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        shape = self.batch_size
        n = self._state.numel()
        action = tensordict.get("action").reshape(-1)
        reward = torch.empty((*shape, 1), dtype=torch.float32, device=self.device)
        terminated = torch.empty((*shape, 1), dtype=torch.bool, device=self.device)
        truncated = torch.empty((*shape, 1), dtype=torch.bool, device=self.device)
        cell = torch.empty((*shape, 2), dtype=torch.long, device=self.device)
        if self.device.type == "cpu":
            grid_step(
                self.kernel_state(),
                action.numpy(),
                reward.numpy().reshape(n),
                terminated.numpy().reshape(n),
                truncated.numpy().reshape(n),
                cell.numpy().reshape(n, 2),
            )
        else:
            self._state = self.transitions[self._state, action]
            self._t += 1
            terminated.copy_((self._state == self.goal_state).view_as(terminated))
            truncated.copy_((self._t >= self.max_steps).view_as(truncated) & ~terminated)
            reward.copy_(torch.where(terminated, self.goal_reward, self.step_reward))
            cell.copy_(self.cells[self._state].view_as(cell))
        return TensorDict(
            {
                "observation": self._state.clone().view(shape),
                "cell": cell,
                "reward": reward,
                "done": terminated | truncated,
                "terminated": terminated,
                "truncated": truncated,
            },
            batch_size=shape,
            device=self.device,
        )

    def _set_seed(self, seed: int | None) -> None:
        """The dynamics are deterministic: nothing to seed."""

    def kernel_state(self, observation_key: NestedKey = "observation") -> GridKernelState:
        """The env's state and tables as numpy views (CPU only), for a compiled loop to step in place.

        Args:
            observation_key: the entry a compiled loop's shaping reads (``observed``): ``"observation"``
                (the state number) or ``"cell"``.

        Examples:
            >>> FourRoomsEnv(num_envs=3).kernel_state().state.shape
            (3,)
            >>> FourRoomsEnv(num_envs=3).kernel_state("cell").observed.shape
            (104, 2)
        """
        if self.device.type != "cpu":
            raise TypeError(f"kernel_state needs a CPU env, not {self.device}")
        if observation_key not in ("observation", "cell"):
            raise TypeError(f"a compiled loop reads 'cell' or 'observation', not {observation_key!r}")
        observed = self._cells_np if observation_key == "cell" else self._numbers_np
        return GridKernelState(
            self._state.numpy(),
            self._t.numpy(),
            self._transitions_np,
            self._cells_np,
            observed,
            self.start_state,
            self.goal_state,
            self.max_steps,
            self.goal_reward,
            self.step_reward,
        )

    def shortest_path_length(self) -> int:
        """Steps of the shortest start-to-goal path (20)."""
        return goal_distances()[START]


def state_of(cell: tuple[int, int]) -> int:
    """State number of a free cell.

    Examples:
        >>> state_of((1, 1)), state_of((11, 11))
        (0, 103)
    """
    return _STATE[cell]


def draw_map(ax: Any, patterns: Mapping[str, SubgoalSeries | Sequence[tuple[int, int]]] | None = None) -> None:
    """Draw the grid (walls, start S, goal G) and each pattern's ordered subgoal cells.

    Cells chosen by several patterns are shaded darker; each subgoal is marked
    with its position in the series (1, 2, ...), as in the paper's figures of
    the participants' subgoals.

    Examples:
        >>> from matplotlib.figure import Figure
        >>> ax = Figure().subplots()
        >>> draw_map(ax, {"alice": [(4, 9), (10, 9)]})
        >>> len(ax.images)
        1
    """
    import matplotlib.colors as mcolors
    import numpy as np
    from matplotlib.patches import Rectangle

    walls = np.array([[ch == "w" for ch in row] for row in _ROWS], dtype=float)
    ax.imshow(walls, cmap=mcolors.ListedColormap(["white", "#404040"]), origin="upper")
    counts: dict[tuple[int, int, int], int] = {}
    for series in (patterns or {}).values():
        cells = (
            [(p.row, p.col) for p in series.predicates if isinstance(p, Cell)]
            if isinstance(series, SubgoalSeries)
            else [tuple(c) for c in series]
        )
        for order, (r, c) in enumerate(cells, start=1):
            counts[(r, c, order)] = counts.get((r, c, order), 0) + 1
    total = max(1, len(patterns or {}))
    colours = ["tab:blue", "tab:orange", "tab:green", "tab:purple"]
    for (r, c, order), count in sorted(counts.items()):
        colour = colours[(order - 1) % len(colours)]
        alpha = 0.25 + 0.75 * count / total
        ax.add_patch(Rectangle((c - 0.5, r - 0.5), 1, 1, color=colour, alpha=alpha))
        ax.text(c, r, str(order), ha="center", va="center", fontsize=7, color="black")
    for label, (r, c) in (("S", START), ("G", GOAL)):
        ax.text(c, r, label, ha="center", va="center", fontsize=9, fontweight="bold")
    ax.set_xticks(range(SIZE[1]))
    ax.set_yticks(range(SIZE[0]))
    ax.tick_params(labelsize=6)
    ax.set_xlim(-0.5, SIZE[1] - 0.5)
    ax.set_ylim(SIZE[0] - 0.5, -0.5)


# The fused engine's env step (torchrl_subgoal.fused._kernels.engine.fused_run): the learner reads the state number.


@steps.implements(steps.env_scratch, GridKernelState)
def _grid_scratch(env: GridKernelState) -> tuple[()]:
    return ()


@steps.implements(steps.env_observe, GridKernelState)
def _grid_observe(env: GridKernelState, b: int, scratch: tuple[()]) -> int:
    return env.state[b]


@steps.implements(steps.env_step, GridKernelState)
def _grid_step(env: GridKernelState, b: int, a: int, scratch: tuple[()]) -> tuple[int, np.float32, bool, bool]:
    return grid_step_one(env, b, a)


@steps.implements(steps.env_reset, GridKernelState)
def _grid_reset(env: GridKernelState, b: int, scratch: tuple[()]) -> int:
    grid_reset_one(env, b)
    return env.state[b]


@steps.implements(steps.env_shaping_observation, GridKernelState)
def _grid_shaping_observation(env: GridKernelState, s: int, scratch: tuple[()]) -> np.ndarray:
    return env.observed[s]
