"""PointMaze (gymnasium-robotics) with a fixed start and goal per learning, as a batched TorchRL env.

A force-actuated ball (a MuJoCo point mass) rolls through a maze of unit
cells: ``PointMaze_UMaze-v3`` (5 × 5 cells) or ``PointMaze_Medium-v3``
(8 × 8). Potential-based shaping over subgoals needs one task per learning, so
the start and the goal are fixed for a learning and the same at every reset:

* **Start and goal cells: a canonical route, either way.** Each maze has one
  route (:data:`ROUTES`: a start cell, a goal cell, and the corners a path
  between them turns at), run in one direction or the other; learning ``seed``
  takes direction ``seed mod 2`` (consecutive seeds alternate). The ``maze_map``
  given to gymnasium marks the start cell ``r`` and the goal cell ``g``.
* **Start and goal points: drawn from the seed.** gymnasium places the ball and
  the goal at the centre of their cell plus a uniform offset in ``[−0.25, 0.25]``
  per coordinate; every reset here re-seeds that draw with the learning's seed,
  so both points are the same at every reset and differ across seeds.

Why not any free cell: the waypoint subgoals (a subgoal file per maze,
:data:`SUBGOAL_FILES`, one pattern per direction, named after it) are circles
over the ball's ``(x, y)`` at the corners of the route, in order; a series is
valid only for the start and goal it was drawn for. Fixing the cells keeps the
file valid; what varies across seeds is the direction and the points within
the cells. A learning uses the pattern of its route (:func:`point_maze_task`
gives both).

The task is gymnasium-robotics' sparse one: reward 1 within 0.45 of the goal
(0 otherwise), and the episode ends there (``continuing_task=False``); the time
limit is gymnasium's (300 steps in UMaze, 600 in Medium), a truncation. The
observation is the ball's ``(x, y, vx, vy)`` (``"observation"``, float32;
entries 0 and 1 are the position the waypoints read); actions are 2-d forces
in ``[−1, 1]``. The envs of a batch step in one process (:func:`gym_batch`).

Needs the ``fetch`` extra (MuJoCo 3.3 to 3.11, gymnasium-robotics 1.4.2).
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import partial
from importlib.resources import files
from typing import Any, Literal

import numpy as np
from torchrl.envs import EnvBase

from torchrl_subgoal.envs.gym_batch import GymTask, require_gymnasium
from torchrl_subgoal.subgoals import SubgoalSeries, load_patterns

__all__ = [
    "BALL_RADIUS",
    "GOAL_RADIUS",
    "MAX_EPISODE_STEPS",
    "MAZES",
    "ROUTES",
    "SUBGOAL_FILES",
    "WAYPOINT_RADIUS",
    "MazeRoute",
    "PointMazeTask",
    "cell_centre",
    "make_point_maze",
    "point_maze_env",
    "point_maze_task",
    "waypoint_patterns",
]

Maze = Literal["umaze", "medium"]

#: The maze layouts (``1``: wall), as gymnasium-robotics' ``U_MAZE`` and ``MEDIUM_MAZE``; rows top to bottom.
MAZES: dict[str, tuple[tuple[int, ...], ...]] = {
    "umaze": (
        (1, 1, 1, 1, 1),
        (1, 0, 0, 0, 1),
        (1, 1, 1, 0, 1),
        (1, 0, 0, 0, 1),
        (1, 1, 1, 1, 1),
    ),
    "medium": (
        (1, 1, 1, 1, 1, 1, 1, 1),
        (1, 0, 0, 1, 1, 0, 0, 1),
        (1, 0, 0, 1, 0, 0, 0, 1),
        (1, 1, 0, 0, 0, 1, 1, 1),
        (1, 0, 0, 1, 0, 0, 0, 1),
        (1, 0, 1, 0, 0, 1, 0, 1),
        (1, 0, 0, 0, 1, 0, 0, 1),
        (1, 1, 1, 1, 1, 1, 1, 1),
    ),
}
_ENV_IDS = {"umaze": "PointMaze_UMaze-v3", "medium": "PointMaze_Medium-v3"}
#: gymnasium's time limits of the two mazes.
MAX_EPISODE_STEPS = {"umaze": 300, "medium": 600}
#: gymnasium-robotics' success distance: the ball's centre within this of the goal point.
GOAL_RADIUS = 0.45
#: The ball's radius (gymnasium-robotics' point mass).
BALL_RADIUS = 0.1
#: Radius of the waypoint circles: a ball (radius 0.1) turning through a corner cell comes within
#: ``√2 · 0.5 − 0.1 ≈ 0.61`` of the cell's centre (its centre stays 0.1 from the wall's corner).
WAYPOINT_RADIUS = 0.65
SUBGOAL_FILES = {
    maze: str(files("torchrl_subgoal") / "domains" / "point_maze" / f"point_maze_{maze}.yaml") for maze in MAZES
}


@dataclass(frozen=True)
class MazeRoute:
    """A start cell, a goal cell and the corner cells a shortest path between them turns at, in order.

    Attributes:
        name: the route's name (its pattern's name in the maze's subgoal file).
        start: ``(row, col)`` of the start cell.
        goal: ``(row, col)`` of the goal cell.
        corners: the waypoints' cells, in the order a path from start to goal passes them.

    Examples:
        >>> ROUTES["umaze"][0]
        MazeRoute(name='bottom_to_top', start=(3, 1), goal=(1, 1), corners=((3, 3), (1, 3)))
    """

    name: str
    start: tuple[int, int]
    goal: tuple[int, int]
    corners: tuple[tuple[int, int], ...]

    def reversed(self, name: str) -> MazeRoute:
        """The same route from the goal back to the start."""
        return MazeRoute(name, self.goal, self.start, self.corners[::-1])


_U = MazeRoute("bottom_to_top", (3, 1), (1, 1), ((3, 3), (1, 3)))
_DIAGONAL = MazeRoute("top_left_to_bottom_right", (1, 1), (6, 6), ((3, 2), (3, 4), (4, 6)))
#: Each maze's routes: one canonical route, either way. UMaze: from one end of the U to the other
#: (the path turns at the U's two right-hand corners); Medium: between opposite corners, the top-left
#: and the bottom-right, the pair whose shortest path is unique (its corners cannot be avoided).
ROUTES: dict[str, tuple[MazeRoute, ...]] = {
    "umaze": (_U, _U.reversed("top_to_bottom")),
    "medium": (_DIAGONAL, _DIAGONAL.reversed("bottom_right_to_top_left")),
}


def _check_maze(maze: str) -> None:
    if maze not in MAZES:
        raise ValueError(f"unknown maze {maze!r}; known: {', '.join(MAZES)}")


def cell_centre(maze: str, cell: tuple[int, int]) -> tuple[float, float]:
    """The ``(x, y)`` of a cell's centre in the simulation (unit cells, the maze centred on the origin,
    ``y`` up).

    Args:
        maze: ``"umaze"`` or ``"medium"``.
        cell: ``(row, col)``, rows from the top.

    Examples:
        >>> cell_centre("umaze", (3, 1)), cell_centre("medium", (1, 1))
        ((-1.0, -1.0), (-2.5, 2.5))
    """
    _check_maze(maze)
    layout = MAZES[maze]
    row, col = cell
    if not (0 <= row < len(layout) and 0 <= col < len(layout[0])) or layout[row][col] == 1:
        raise ValueError(f"cell {cell} is not a free cell of the {maze} maze")
    return col + 0.5 - len(layout[0]) / 2, len(layout) / 2 - (row + 0.5)


@dataclass(frozen=True)
class PointMazeTask:
    """The task of one learning: its maze, route and seed (see the module's description).

    Attributes:
        maze: ``"umaze"`` or ``"medium"``.
        route: the route (start and goal cells, the pattern's name).
        seed: the learning's seed (draws the points within the start and goal cells).

    Examples:
        >>> task = point_maze_task("umaze", seed=3)
        >>> task.route.name, task.maze_map()[3][1], task.maze_map()[1][1]
        ('top_to_bottom', 'g', 'r')
    """

    maze: str
    route: MazeRoute
    seed: int

    def maze_map(self) -> list[list[int | str]]:
        """The maze's map with the route's start cell ``"r"`` and goal cell ``"g"`` (gymnasium's ``maze_map``)."""
        rows: list[list[int | str]] = [list(row) for row in MAZES[self.maze]]
        rows[self.route.start[0]][self.route.start[1]] = "r"
        rows[self.route.goal[0]][self.route.goal[1]] = "g"
        return rows

    def pattern(self) -> SubgoalSeries:
        """The waypoint subgoals of the route (from the maze's subgoal file)."""
        return waypoint_patterns(self.maze)[self.route.name]


def point_maze_task(maze: str, seed: int) -> PointMazeTask:
    """Learning ``seed``'s task in ``maze``: route ``seed mod len(ROUTES[maze])`` (the two directions).

    Args:
        maze: ``"umaze"`` or ``"medium"``.
        seed: the learning's seed (a non-negative integer).

    Examples:
        >>> [point_maze_task("medium", s).route.name for s in range(2)]
        ['top_left_to_bottom_right', 'bottom_right_to_top_left']
    """
    _check_maze(maze)
    if seed < 0:
        raise ValueError(f"seed must be >= 0, got {seed}")
    routes = ROUTES[maze]
    return PointMazeTask(maze, routes[seed % len(routes)], int(seed))


def waypoint_patterns(maze: str) -> dict[str, SubgoalSeries]:
    """The maze's shipped waypoint subgoals, one series per route (by the route's name).

    Args:
        maze: ``"umaze"`` or ``"medium"``.

    Examples:
        >>> patterns = waypoint_patterns("umaze")
        >>> sorted(patterns), len(patterns["bottom_to_top"])
        (['bottom_to_top', 'top_to_bottom'], 2)
    """
    _check_maze(maze)
    return load_patterns(SUBGOAL_FILES[maze])


def _make_single(task: PointMazeTask) -> Any:
    """One gymnasium env of ``task``: the sparse, terminating PointMaze, reset to the task's points."""
    gymnasium = require_gymnasium("PointMaze", robotics=True)

    class FixedTask(gymnasium.Wrapper):  # type: ignore[name-defined]
        """Every reset re-seeds the task's draw of the start and goal points; the 4-d float32 observation."""

        def __init__(self, env: Any, seed: int) -> None:
            super().__init__(env)
            self.task_seed = seed
            self.observation_space = gymnasium.spaces.Box(-np.inf, np.inf, (4,), np.float32)

        def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> Any:
            # the seed a caller passes (TorchRL's set_seed) is ignored: the task's seed fixes the points
            obs, info = self.env.reset(seed=self.task_seed)
            return obs["observation"].astype(np.float32), info

        def step(self, action: Any) -> Any:
            obs, reward, terminated, truncated, info = self.env.step(action)
            return obs["observation"].astype(np.float32), float(reward), terminated, truncated, info

    env = gymnasium.make(_ENV_IDS[task.maze], maze_map=task.maze_map(), continuing_task=False, reward_type="sparse")
    return FixedTask(env, task.seed)


def make_point_maze(maze: str, num_envs: int, seed: int) -> EnvBase:
    """``num_envs`` PointMaze envs of learning ``seed``'s task (:func:`point_maze_task`), one TorchRL env.

    Every env of the batch, and every reset, starts the ball at the same point and
    puts the goal at the same point (those of the seed). The batch steps in this
    process (:func:`~torchrl_subgoal.envs.gym_batch.gym_batch`); its ``max_steps``
    is gymnasium's time limit.

    Args:
        maze: ``"umaze"`` or ``"medium"``.
        num_envs: envs in the batch.
        seed: the learning's seed.

    Examples:
        >>> import torch
        >>> env = make_point_maze("umaze", num_envs=2, seed=0)
        >>> td = env.reset()
        >>> td["observation"].shape, env.max_steps
        (torch.Size([2, 4]), 300)
        >>> bool((td["observation"][:, :2] - torch.tensor([-1.0, -1.0])).abs().max() <= 0.25)  # in cell (3, 1)
        True
    """
    return point_maze_env(maze, seed)(num_envs)


def point_maze_env(maze: str, seed: int) -> GymTask:
    """The env factory ``make_env(num_envs)`` of learning ``seed``'s task (:func:`make_point_maze`); the
    factories of several learnings' tasks join into one env batch (:meth:`GymTask.join`).

    Args:
        maze: ``"umaze"`` or ``"medium"``.
        seed: the learning's seed.

    Examples:
        >>> make_env = point_maze_env("umaze", seed=1)
        >>> make_env.max_steps, make_env(3).batch_size
        (300, torch.Size([3]))
    """
    task = point_maze_task(maze, seed)
    require_gymnasium("PointMaze", robotics=True)
    return GymTask(partial(_make_single, task), MAX_EPISODE_STEPS[maze])
