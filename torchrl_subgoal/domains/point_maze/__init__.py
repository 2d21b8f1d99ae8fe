"""The PointMaze domain plugins (UMaze, Medium): env, subgoal check, and each layer's part (the learners'
set-up, report map, studio table).

Everything the package knows about the two PointMaze domains beyond the env
itself, in one place; :mod:`torchrl_subgoal.domains` imports this module the
first time ``"point_maze_umaze"`` or ``"point_maze_medium"`` is looked up.
Nothing here needs MuJoCo until an env is made.

A maze's subgoal patterns each belong to one direction of its route (their
names are the routes'): a learner following a pattern runs that direction
(:meth:`~torchrl_subgoal.training.LearnerDomain.env_for`), its start and goal
points drawn from its seed; an unshaped learner runs the direction its
learning number picks, so the two directions are balanced in every method.
In the studio, a maze is a table in its own coordinates (``y`` up): its wall
cells are the obstacles, a pattern's start and target are those of the route
it is named after, and "Try it" is off (deep learners only).
"""

from __future__ import annotations

import functools
from collections.abc import Callable, Mapping
from typing import Any

from torchrl.envs import EnvBase

from torchrl_subgoal import domains
from torchrl_subgoal.envs import point_maze
from torchrl_subgoal.experiments.plots import ReportMap, numbered_subgoals
from torchrl_subgoal.studio.domains import StudioDomain
from torchrl_subgoal.subgoals import Circle, Predicate
from torchrl_subgoal.training import DDPGTrainConfig, LearnerDomain, PPOConfig, SuccessSignal

__all__ = ["DOMAINS", "LEARNERS", "STUDIO", "check_subgoal", "maze_env", "route_env"]


def maze_env(maze: str, num_envs: int) -> EnvBase:
    """``num_envs`` envs of the maze's first route from seed 0 (what a subgoal file is checked against).

    Examples:
        >>> maze_env("umaze", 2).batch_size  # doctest: +SKIP
        torch.Size([2])
    """
    return point_maze.make_point_maze(maze, num_envs, seed=0)


def _route_seed(maze: str, route: str, seed: int) -> int:
    """``seed`` with its residue set to ``route``'s index (``point_maze_task`` runs route ``seed mod 2``)."""
    names = [r.name for r in point_maze.ROUTES[maze]]
    if route not in names:
        raise ValueError(
            f"pattern {route!r} names no route of the {maze} maze; its patterns are the routes {', '.join(names)}"
        )
    seed = abs(int(seed)) % 2**62
    return seed - seed % len(names) + names.index(route)


def route_env(maze: str, route: str, seed: int) -> Callable[[int], EnvBase]:
    """The env factory of a learner following ``route`` (a pattern's name) with ``seed``.

    Examples:
        >>> from torchrl_subgoal.envs.point_maze import point_maze_task
        >>> point_maze_task("umaze", _route_seed("umaze", "top_to_bottom", 10)).route.name
        'top_to_bottom'
    """
    return point_maze.point_maze_env(maze, _route_seed(maze, route, seed))


def check_subgoal(maze: str, predicate: Predicate) -> str | None:
    """Why ``predicate`` is not a valid subgoal of ``maze``, or ``None``: a circle over the ball's
    ``(x, y)`` (dims [0, 1]) with a positive radius, centred in a free cell.

    Examples:
        >>> check_subgoal("umaze", Circle((1.0, -1.0), 0.65)) is None
        True
        >>> check_subgoal("umaze", Circle((0.0, 0.0), 0.65))
        'centre (0, 0) lies in a wall cell (2, 2) of the umaze maze; move it to where the ball can go'
    """
    if not isinstance(predicate, Circle):
        return f"PointMaze subgoals are circles over the ball's (x, y), not {predicate.kind}"
    if tuple(predicate.dims()) != (0, 1):
        return f"a PointMaze subgoal circle covers (x, y), dims [0, 1], not {list(predicate.dims())}"
    if not predicate.radius > 0:
        return f"radius must be positive, got {predicate.radius}"
    x, y = (float(v) for v in predicate.centre)
    layout = point_maze.MAZES[maze]
    row, col = int(len(layout) / 2 - y), int(x + len(layout[0]) / 2)
    if (
        not (0 <= row < len(layout) and 0 <= col < len(layout[0]))
        or x + len(layout[0]) / 2 < 0
        or len(layout) / 2 - y < 0
    ):
        return f"centre ({x:g}, {y:g}) is outside the {maze} maze"
    if layout[row][col] == 1:
        return (
            f"centre ({x:g}, {y:g}) lies in a wall cell ({row}, {col}) of the {maze} maze; "
            "move it to where the ball can go"
        )
    return None


def _draw_map(maze: str, ax: Any, patterns: Mapping[str, Any], options: Mapping[str, Any]) -> None:
    from matplotlib.patches import Circle as Disc
    from matplotlib.patches import Rectangle

    layout = point_maze.MAZES[maze]
    rows, cols = len(layout), len(layout[0])
    for r, line in enumerate(layout):
        for c, wall in enumerate(line):
            if wall:
                ax.add_patch(Rectangle((c - cols / 2, rows / 2 - r - 1), 1, 1, color="0.6"))
    for _name, colour, number, circle in numbered_subgoals(patterns, Circle):
        x, y = (float(v) for v in circle.centre[:2])
        ax.add_patch(Disc((x, y), float(circle.radius), fill=False, color=colour))
        ax.annotate(str(number), (x, y), color=colour, ha="center", va="center")
    routes = {route.name: route for route in point_maze.ROUTES[maze]}
    for route in [routes[name] for name in patterns if name in routes] or list(routes.values())[:1]:
        ax.plot(*point_maze.cell_centre(maze, route.start), "o", color="tab:blue")
        ax.plot(*point_maze.cell_centre(maze, route.goal), "*", color="tab:red", markersize=12)
    ax.set_xlim(-cols / 2, cols / 2)
    ax.set_ylim(-rows / 2, rows / 2)
    ax.set_aspect("equal")


def _learners(maze: str) -> LearnerDomain:
    cap = point_maze.MAX_EPISODE_STEPS[maze]
    scale = 1 if maze == "umaze" else 2
    return LearnerDomain(
        f"point_maze_{maze}",
        functools.partial(maze_env, maze),
        "observation",
        "observation",
        "observation",
        point_maze.SUBGOAL_FILES[maze],
        eta=1.0,
        thresholds=(cap * 2 / 3, cap / 3),
        defaults={
            # TorchRL's examples' settings at a budget this machine affords (not tuned here)
            "ppo": PPOConfig(num_envs=8, frames_per_batch=2048, total_frames=200_000 * scale),
            "ddpg": DDPGTrainConfig(
                total_frames=100_000 * scale,
                learning_starts=5_000,
                frames_per_batch=1000,
                updates_per_batch=250,
                buffer_size=200_000,
            ),
        },
        pattern_env=functools.partial(route_env, maze),
        success=SuccessSignal(min_return=1.0),  # the sparse reward of 1 at the goal, where the episode ends
    )


def _geometry(maze: str, config: str) -> dict[str, Any]:
    """The maze as a studio table: its plane (``y`` up), one square per wall cell, each route's ends."""
    layout = point_maze.MAZES[maze]
    rows, cols = len(layout), len(layout[0])

    def square(r: int, c: int) -> list[list[float]]:
        x, y = c - cols / 2, rows / 2 - r  # the cell's top-left corner
        return [[x, y], [x + 1, y], [x + 1, y - 1], [x, y - 1]]

    walls = [square(r, c) for r, line in enumerate(layout) for c, wall in enumerate(line) if wall]
    ends = {
        route.name: {
            "start": list(point_maze.cell_centre(maze, route.start)),
            "target": [*point_maze.cell_centre(maze, route.goal), point_maze.GOAL_RADIUS],
        }
        for route in point_maze.ROUTES[maze]
    }
    first = ends[point_maze.ROUTES[maze][0].name]
    return {
        "kind": "table",
        "bounds": [-cols / 2, -rows / 2, cols / 2, rows / 2],
        "y_up": True,
        "ball_radius": point_maze.BALL_RADIUS,
        "start": first["start"],
        "target": first["target"],
        "routes": ends,  # a pattern named after a route is drawn with that route's start and target
        "polygons": walls,
        "default_radius": point_maze.WAYPOINT_RADIUS,
    }


def _studio(maze: str) -> StudioDomain:
    name = f"point_maze_{maze}"
    return StudioDomain(
        functools.partial(_geometry, maze),
        recipe=f"torchrl-subgoal train --algo ppo --domain {name}",
        try_note=(
            "Not offered for PointMaze: it is learned by deep learners only (PPO, DDPG; 100,000 frames or more), "
            "not by the quick learners Try it runs. Save the file and run the command shown under "
            f"File: torchrl-subgoal train --algo ppo --domain {name} --subgoals FILE"
        ),
        pattern_names=tuple(route.name for route in point_maze.ROUTES[maze]),
        position=3 if maze == "umaze" else 4,
    )


#: Each maze's studio table.
STUDIO = {maze: _studio(maze) for maze in point_maze.MAZES}

#: Each maze's learner set-up.
LEARNERS = {maze: _learners(maze) for maze in point_maze.MAZES}

DOMAINS = {
    maze: domains.register(
        domains.Domain(
            f"point_maze_{maze}",
            f"PointMaze {maze.capitalize()}",
            make_env=functools.partial(maze_env, maze),
            check_subgoal=functools.partial(check_subgoal, maze),
            parts=(LEARNERS[maze], ReportMap(functools.partial(_draw_map, maze)), STUDIO[maze]),
        )
    )
    for maze in point_maze.MAZES
}
