"""PinBall's physics: the map, the ball's step (compiled, and in torch), and the record the fused
engine steps the balls through.

See :mod:`torchrl_subgoal.envs.pinball` for the dynamics and the rules of collisions and the goal.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal, NamedTuple

import numba
import numpy as np
import torch

from torchrl_subgoal._kernels import steps
from torchrl_subgoal._kernels.random import _random_action

__all__ = ["BallKernelState", "PinBallConfig", "PinBallPhysics", "point_in_polygon"]

#: Meaning of the five discrete actions, by index.
ACTION_NAMES: tuple[str, ...] = ("+x", "+y", "-x", "-y", "none")

SUBSTEPS = 20
DRAG = 0.995
THRUST = 1.0 / 5.0

_DATA_DIR = Path(__file__).resolve().parents[1] / "data" / "pinball"
_NAMED_CONFIGS = ("simple", "hard")

Backend = Literal["auto", "numba", "torch", "compile"]


# --------------------------------------------------------------------------
# Configuration files
# --------------------------------------------------------------------------


@dataclass(frozen=True)
class PinBallConfig:
    """A PinBall map: ball size, target, start and obstacle polygons.

    The text format has one item per line: ``ball R``, ``target X Y R``,
    ``start X Y`` and one ``polygon x1 y1 x2 y2 ...`` line per polygon (the
    walls are polygons too). Blank lines and lines starting with ``#`` are
    ignored.

    Args:
        ball_radius: radius of the ball.
        target: ``(x, y, radius)`` of the target circle.
        start: ``(x, y)`` start position of the ball.
        polygons: vertices of each obstacle polygon, in order.
        source: where the map came from (a file path or a name), for messages.

    Examples:
        >>> cfg = PinBallConfig.load("simple")
        >>> cfg.ball_radius, cfg.target, len(cfg.polygons)
        (0.02, (0.9, 0.2, 0.04), 10)
    """

    ball_radius: float
    target: tuple[float, float, float]
    start: tuple[float, float]
    polygons: tuple[tuple[tuple[float, float], ...], ...]
    source: str = "<memory>"

    @classmethod
    def load(cls, config: str | Path | PinBallConfig) -> PinBallConfig:
        """Load ``"simple"``, ``"hard"`` or a map file; a config is returned as is."""
        if isinstance(config, PinBallConfig):
            return config
        path = _DATA_DIR / f"{config}.cfg" if config in _NAMED_CONFIGS else Path(config)
        if not path.is_file():
            raise ValueError(f"PinBall config {str(config)!r} is neither one of {_NAMED_CONFIGS} nor an existing file")
        return cls.parse(path.read_text(), source=str(path))

    @classmethod
    def parse(cls, text: str, source: str = "<string>") -> PinBallConfig:
        """Parse the text format; errors name ``source`` and the line number."""
        values: dict[str, tuple[float, ...]] = {}
        lines: dict[str, int] = {}
        polygons: list[tuple[tuple[float, float], ...]] = []
        polygon_lines: list[int] = []
        arity = {"ball": 1, "target": 3, "start": 2}

        for number, raw in enumerate(text.splitlines(), start=1):
            words = raw.split()
            if not words or words[0].startswith("#"):
                continue

            def fail(what: str, number: int = number) -> ValueError:
                return ValueError(f"{source}, line {number}: {what}")

            keyword, fields = words[0], words[1:]
            try:
                numbers = tuple(float(word) for word in fields)
            except ValueError:
                raise fail(f"{keyword!r} expects numbers, got {' '.join(fields)!r}") from None
            if not all(math.isfinite(v) for v in numbers):
                raise fail(f"{keyword!r} has a non-finite number (NaN or inf)")
            if keyword in arity:
                if keyword in values:
                    raise fail(f"second {keyword!r} line (first on line {lines[keyword]})")
                if len(numbers) != arity[keyword]:
                    raise fail(f"{keyword!r} expects {arity[keyword]} number(s), got {len(numbers)}")
                values[keyword], lines[keyword] = numbers, number
            elif keyword == "polygon":
                if len(numbers) % 2:
                    raise fail(f"polygon has an odd number of coordinates ({len(numbers)})")
                vertices = tuple(zip(numbers[0::2], numbers[1::2], strict=True))
                if len(vertices) < 3:
                    raise fail(f"polygon needs at least 3 vertices, got {len(vertices)}")
                for i, vertex in enumerate(vertices):
                    if vertex == vertices[i - 1]:
                        raise fail(f"polygon repeats vertex {vertex} (zero-length edge)")
                polygons.append(vertices)
                polygon_lines.append(number)
            else:
                raise fail(f"unknown keyword {keyword!r} (expected ball, target, start, polygon)")

        for keyword in arity:
            if keyword not in values:
                raise ValueError(f"{source}: no {keyword!r} line")
        (ball_radius,) = values["ball"]
        tx, ty, tr = values["target"]
        sx, sy = values["start"]
        if ball_radius <= 0:
            raise ValueError(f"{source}, line {lines['ball']}: ball radius must be positive")
        if tr <= 0:
            raise ValueError(f"{source}, line {lines['target']}: target radius must be positive")
        for vertices, number in zip(polygons, polygon_lines, strict=True):
            if _circle_hits_polygon((sx, sy), ball_radius, vertices):
                raise ValueError(
                    f"{source}, line {lines['start']}: the ball at start ({sx}, {sy}) overlaps "
                    f"the obstacle of line {number}"
                )
            if point_in_polygon((tx, ty), vertices):
                raise ValueError(
                    f"{source}, line {lines['target']}: the target centre ({tx}, {ty}) lies "
                    f"inside the obstacle of line {number}"
                )
        return cls(ball_radius, (tx, ty, tr), (sx, sy), tuple(polygons), source)


def point_in_polygon(point: tuple[float, float], vertices: Sequence[tuple[float, float]]) -> bool:
    """Whether ``point`` lies inside the polygon ``vertices`` (even-odd rule).

    Args:
        point: ``(x, y)``.
        vertices: the polygon's corners in order (closed implicitly).

    Examples:
        >>> square = [(0.0, 0.0), (1.0, 0.0), (1.0, 1.0), (0.0, 1.0)]
        >>> point_in_polygon((0.5, 0.5), square), point_in_polygon((1.5, 0.5), square)
        (True, False)
    """
    x, y = point
    inside = False
    for (ax, ay), (bx, by) in zip(vertices, [*vertices[1:], vertices[0]], strict=True):
        if (ay > y) != (by > y) and x < ax + (y - ay) * (bx - ax) / (by - ay):
            inside = not inside
    return inside


def _circle_hits_polygon(centre: tuple[float, float], radius: float, vertices: Sequence[tuple[float, float]]) -> bool:
    """Whether a circle overlaps a polygon (centre inside, or an edge closer than ``radius``)."""
    if point_in_polygon(centre, vertices):
        return True
    x, y = centre
    for (ax, ay), (bx, by) in zip(vertices, [*vertices[1:], vertices[0]], strict=True):
        dx, dy = bx - ax, by - ay
        t = min(1.0, max(0.0, ((x - ax) * dx + (y - ay) * dy) / (dx * dx + dy * dy)))
        if (x - ax - t * dx) ** 2 + (y - ay - t * dy) ** 2 < radius * radius:
            return True
    return False


# --------------------------------------------------------------------------
# Physics kernels
# --------------------------------------------------------------------------


class _Geometry:
    """Edge and polygon arrays of one map, in the layouts the kernels read."""

    def __init__(self, config: PinBallConfig, device: torch.device) -> None:
        starts: list[tuple[float, float]] = []
        ends: list[tuple[float, float]] = []
        owner: list[int] = []
        for index, vertices in enumerate(config.polygons):
            starts.extend(vertices)
            ends.extend([*vertices[1:], vertices[0]])
            owner.extend([index] * len(vertices))
        a = np.asarray(starts, dtype=np.float64).reshape(-1, 2)
        d = np.asarray(ends, dtype=np.float64).reshape(-1, 2) - a
        length = np.hypot(d[:, 0], d[:, 1])  # > 0: the parser rejects repeated vertices
        normal = np.stack([-d[:, 1], d[:, 0]], axis=1) / length[:, None]
        # Per edge: start x, y; direction x, y; 1 / |direction|²; unit normal x, y.
        self.edges = np.ascontiguousarray(np.concatenate([a, d, (1.0 / length**2)[:, None], normal], 1))
        sizes = [len(vertices) for vertices in config.polygons]
        self.first_edge = np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        self.boxes = np.array(
            [[*np.min(v, axis=0), *np.max(v, axis=0)] for v in map(np.asarray, config.polygons)],
            dtype=np.float64,
        ).reshape(-1, 4)
        self.owner = np.asarray(owner, dtype=np.int64)
        self.ball_radius = config.ball_radius
        self.target = config.target
        edges = torch.as_tensor(self.edges, device=device)
        self.edge_start, self.edge_dir = edges[:, 0:2], edges[:, 2:4]
        self.edge_inv_len2, self.edge_normal = edges[:, 4], edges[:, 5:7]
        self.edge_owner = torch.as_tensor(self.owner, device=device)


@numba.njit(cache=True, nogil=True, inline="always")
def step_ball(
    px: float,
    py: float,
    vx: float,
    vy: float,
    a: int,
    edges: np.ndarray,
    boxes: np.ndarray,
    first_edge: np.ndarray,
    ball_radius: float,
    target_x: float,
    target_y: float,
    target_radius: float,
    velocity_limit: float,
    candidates: np.ndarray,
    owners: np.ndarray,
) -> tuple[float, float, float, float, bool]:
    """One environment step of one ball: ``(x, y, vx, vy, reached the target)`` (compiled by numba).

    Before its substeps, the ball collects the edges it can reach during this
    step: its speed is fixed by the thrust (reflections and reversals keep it),
    so in at most ``SUBSTEPS + 1`` moves its centre travels at most
    ``SUBSTEPS + 1`` moves of ``speed * move``; an edge farther than
    ``ball_radius`` plus that distance (``reach``) cannot be hit. Polygons are
    first rejected by their bounding box grown by that distance. The substeps
    then test only the collected edges (``candidates``, with their polygons in
    ``owners``: scratch of one entry per edge), which gives the same hits as
    testing every edge. :func:`step_balls` steps a batch; the fused engine
    calls this once per learner.

    Examples:
        >>> import numpy as np
        >>> from torchrl_subgoal.envs import PinBallEnv
        >>> g = PinBallEnv(1, seed=0).physics.geometry
        >>> scratch = np.empty(g.edges.shape[0], dtype=np.int64)
        >>> x, y, vx, vy, reached = step_ball(0.2, 0.9, 0.0, 0.0, 0, g.edges, g.boxes, g.first_edge,
        ...     g.ball_radius, *g.target, 1.0, scratch, scratch.copy())
        >>> vx > 0.0, vy == 0.0, bool(reached)  # thrust to the right, away from the target
        (True, True, False)
    """
    move = ball_radius / SUBSTEPS
    r2 = ball_radius * ball_radius
    t2 = target_radius * target_radius
    if a == 0:
        vx += THRUST
    elif a == 1:
        vy += THRUST
    elif a == 2:
        vx -= THRUST
    elif a == 3:
        vy -= THRUST
    vx = min(max(vx, -velocity_limit), velocity_limit)
    vy = min(max(vy, -velocity_limit), velocity_limit)

    reach = ball_radius + (SUBSTEPS + 1) * move * math.sqrt(vx * vx + vy * vy) + 1e-9
    count = 0
    for p in range(boxes.shape[0]):
        if px + reach < boxes[p, 0] or py + reach < boxes[p, 1] or px - reach > boxes[p, 2] or py - reach > boxes[p, 3]:
            continue
        for e in range(first_edge[p], first_edge[p + 1]):
            ax, ay = edges[e, 0], edges[e, 1]
            dx, dy = edges[e, 2], edges[e, 3]
            t = min(max(((px - ax) * dx + (py - ay) * dy) * edges[e, 4], 0.0), 1.0)
            ox = px - (ax + t * dx)
            oy = py - (ay + t * dy)
            if ox * ox + oy * oy <= reach * reach:
                candidates[count] = e
                owners[count] = p
                count += 1

    done = False
    for substep in range(SUBSTEPS):
        px += vx * move
        py += vy * move
        hits = 0
        polygons_hit = 0
        last_owner = -1
        hit_nx = 0.0
        hit_ny = 0.0
        for c in range(count):
            e = candidates[c]
            ax, ay = edges[e, 0], edges[e, 1]
            dx, dy = edges[e, 2], edges[e, 3]
            t = min(max(((px - ax) * dx + (py - ay) * dy) * edges[e, 4], 0.0), 1.0)
            ox = px - (ax + t * dx)
            oy = py - (ay + t * dy)
            if ox * ox + oy * oy <= r2 and vx * ox + vy * oy < 0.0:
                hits += 1
                hit_nx, hit_ny = edges[e, 5], edges[e, 6]
                if owners[c] != last_owner:  # candidates are grouped by polygon
                    polygons_hit += 1
                    last_owner = owners[c]
        if hits == 1:
            dot = vx * hit_nx + vy * hit_ny
            vx -= 2.0 * dot * hit_nx
            vy -= 2.0 * dot * hit_ny
        elif hits > 1:
            vx, vy = -vx, -vy
        if polygons_hit == 1 and substep == SUBSTEPS - 1:
            px += vx * move
            py += vy * move
        if (px - target_x) ** 2 + (py - target_y) ** 2 <= t2:
            done = True
            break
    if not done:
        vx *= DRAG
        vy *= DRAG
        out = False
        if px > 1.0:
            px, out = 0.95, True
        elif px < 0.0:
            px, out = 0.05, True
        if py > 1.0:
            py, out = 0.95, True
        elif py < 0.0:
            py, out = 0.05, True
        if out:
            vx, vy = 0.0, 0.0
    return px, py, vx, vy, done


class BallKernelState(NamedTuple):
    """A :class:`~torchrl_subgoal.envs.PinBallEnv`'s balls as numpy views, its map and its settings, for compiled loops
    (:func:`ball_step` steps one ball in place).

    Examples:
        >>> from torchrl_subgoal.envs import PinBallEnv
        >>> state = PinBallEnv(3, seed=0).kernel_state()
        >>> state.position.shape, state.velocity.shape, state.steps.shape
        ((3, 2), (3, 2), (3,))
    """

    position: np.ndarray  #: ``[N, 2]`` ball centres
    velocity: np.ndarray  #: ``[N, 2]`` velocities
    steps: np.ndarray  #: ``[N]`` steps into the episode
    streams: np.ndarray  #: ``[N, 4]`` the balls' random streams (random actions)
    start_x: float  #: start position
    start_y: float
    edges: np.ndarray  #: the map's edges, polygon boxes and first edge per polygon (see :func:`step_ball`)
    boxes: np.ndarray
    first_edge: np.ndarray
    ball_radius: float
    target_x: float
    target_y: float
    target_radius: float
    velocity_limit: float
    max_steps: int  #: steps before truncation
    random_prob: float  #: probability that a random action replaces the chosen one
    goal_reward: float
    step_penalty: float
    thrust_penalty: float


_NUM_ACTIONS, _NO_THRUST = len(ACTION_NAMES), ACTION_NAMES.index("none")  # ints: numba reads them as constants


@numba.njit(cache=True, nogil=True, inline="always")
def ball_step(
    balls: BallKernelState,
    b: int,
    a: int,
    candidates: np.ndarray,
    owners: np.ndarray,
) -> tuple[float, float, float, float, np.float32, bool, bool]:
    """Ball ``b``'s env step with action ``a`` (``balls`` updated in place), as :meth:`PinBallEnv.step` does it:
    ``(x, y, vx, vy, reward as float32, terminated, done)``. ``candidates``, ``owners``: :func:`step_ball`'s scratch.

    Examples:
        >>> import numpy as np
        >>> from torchrl_subgoal.envs import PinBallEnv
        >>> balls = PinBallEnv(1, seed=0).kernel_state()
        >>> scratch = np.empty(balls.edges.shape[0], dtype=np.int64)
        >>> x, y, vx, vy, reward, terminated, done = ball_step(balls, 0, 0, scratch, scratch.copy())
        >>> bool(vx > 0.0), int(balls.steps[0]), bool(done)
        (True, 1, False)
    """
    executed = _random_action(a, balls.streams, b, balls.random_prob, _NUM_ACTIONS)
    px, py, vx, vy, terminated = step_ball(
        balls.position[b, 0],
        balls.position[b, 1],
        balls.velocity[b, 0],
        balls.velocity[b, 1],
        executed,
        balls.edges,
        balls.boxes,
        balls.first_edge,
        balls.ball_radius,
        balls.target_x,
        balls.target_y,
        balls.target_radius,
        balls.velocity_limit,
        candidates,
        owners,
    )
    balls.position[b, 0], balls.position[b, 1] = px, py
    balls.velocity[b, 0], balls.velocity[b, 1] = vx, vy
    balls.steps[b] += 1
    done = terminated or balls.steps[b] >= balls.max_steps
    r = balls.goal_reward if terminated else 0.0
    if balls.step_penalty != 0.0 or balls.thrust_penalty != 0.0:
        r += balls.thrust_penalty if executed != _NO_THRUST else balls.step_penalty
    return px, py, vx, vy, np.float32(r), terminated, done


@numba.njit(cache=True, nogil=True, inline="always")
def ball_reset(balls: BallKernelState, b: int) -> tuple[float, float, float, float]:
    """Put ball ``b`` back at the start, at rest: ``(x, y, vx, vy)``.

    Examples:
        >>> from torchrl_subgoal.envs import PinBallEnv
        >>> balls = PinBallEnv(1, seed=0).kernel_state()
        >>> ball_reset(balls, 0)[2:], int(balls.steps[0])
        ((0.0, 0.0), 0)
    """
    balls.position[b, 0], balls.position[b, 1] = balls.start_x, balls.start_y
    balls.velocity[b, 0], balls.velocity[b, 1] = 0.0, 0.0
    balls.steps[b] = 0
    return balls.start_x, balls.start_y, 0.0, 0.0


# The fused engine's env step (torchrl_subgoal.fused._kernels.engine.fused_run): the learner and the shaping read the
# observation as PinBallEnv emits it (float32), held in float64 scratch rows: before, after and at a reset.


@steps.implements(steps.env_scratch, BallKernelState)
def _ball_scratch(env: BallKernelState) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    n = env.edges.shape[0]
    return np.empty(4), np.empty(4), np.empty(4), np.empty(n, np.int64), np.empty(n, np.int64)


@numba.njit(cache=True, nogil=True, inline="always")
def _observation(out: np.ndarray, px: float, py: float, vx: float, vy: float) -> np.ndarray:
    """``out`` ← the float32 observation ``(x, y, vx, vy)``."""
    out[0], out[1], out[2], out[3] = np.float32(px), np.float32(py), np.float32(vx), np.float32(vy)
    return out


@steps.implements(steps.env_observe, BallKernelState)
def _ball_observe(env: BallKernelState, b: int, scratch: tuple[np.ndarray, ...]) -> np.ndarray:
    return _observation(scratch[0], env.position[b, 0], env.position[b, 1], env.velocity[b, 0], env.velocity[b, 1])


@steps.implements(steps.env_step, BallKernelState)
def _ball_env_step(
    env: BallKernelState,
    b: int,
    a: int,
    scratch: tuple[np.ndarray, ...],
) -> tuple[np.ndarray, np.float32, bool, bool]:
    px, py, vx, vy, reward, terminated, done = ball_step(env, b, a, scratch[3], scratch[4])
    return _observation(scratch[1], px, py, vx, vy), reward, terminated, done


@steps.implements(steps.env_reset, BallKernelState)
def _ball_env_reset(env: BallKernelState, b: int, scratch: tuple[np.ndarray, ...]) -> np.ndarray:
    px, py, vx, vy = ball_reset(env, b)
    return _observation(scratch[2], px, py, vx, vy)


@steps.implements(steps.env_shaping_observation, BallKernelState)
def _ball_shaping_observation(env: BallKernelState, o: np.ndarray, scratch: tuple[np.ndarray, ...]) -> np.ndarray:
    return o


def _step_balls(
    position: np.ndarray,
    velocity: np.ndarray,
    action: np.ndarray,
    reached: np.ndarray,
    edges: np.ndarray,
    boxes: np.ndarray,
    first_edge: np.ndarray,
    ball_radius: float,
    target_x: float,
    target_y: float,
    target_radius: float,
    velocity_limit: float,
) -> None:
    """One environment step for every ball, in place (compiled by numba): :func:`step_ball` per ball."""
    candidates = np.empty(edges.shape[0], dtype=np.int64)
    owners = np.empty(edges.shape[0], dtype=np.int64)
    for i in range(position.shape[0]):
        px, py, vx, vy, done = step_ball(
            position[i, 0],
            position[i, 1],
            velocity[i, 0],
            velocity[i, 1],
            action[i],
            edges,
            boxes,
            first_edge,
            ball_radius,
            target_x,
            target_y,
            target_radius,
            velocity_limit,
            candidates,
            owners,
        )
        position[i, 0], position[i, 1] = px, py
        velocity[i, 0], velocity[i, 1] = vx, vy
        reached[i] = done


#: the compiled physics kernel (also called from the fused engine's loop)
step_balls = numba.njit(cache=True, nogil=True)(_step_balls)


def _torch_kernel(
    position: torch.Tensor,
    velocity: torch.Tensor,
    action: torch.Tensor,
    edge_start: torch.Tensor,
    edge_dir: torch.Tensor,
    edge_inv_len2: torch.Tensor,
    edge_normal: torch.Tensor,
    edge_owner: torch.Tensor,
    ball_radius: float,
    target: tuple[float, float, float],
    velocity_limit: float,
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """One environment step as whole-batch tensor operations over ``[balls, edges]``.

    Pure function (no Python loop over polygons or edges), so ``torch.compile``
    can fuse it. Returns the new position, velocity and the goal mask.
    """
    thrust = torch.zeros_like(velocity)
    thrust[:, 0] = (action == 0).to(velocity.dtype) - (action == 2).to(velocity.dtype)
    thrust[:, 1] = (action == 1).to(velocity.dtype) - (action == 3).to(velocity.dtype)
    velocity = (velocity + thrust * THRUST).clamp(-velocity_limit, velocity_limit)
    px, py = position[:, 0:1], position[:, 1:2]
    vx, vy = velocity[:, 0:1], velocity[:, 1:2]
    ax, ay = edge_start[:, 0], edge_start[:, 1]
    dx, dy = edge_dir[:, 0], edge_dir[:, 1]
    nx, ny = edge_normal[:, 0], edge_normal[:, 1]
    move = ball_radius / SUBSTEPS
    r2 = ball_radius * ball_radius
    tx, ty, tr = target
    live = torch.ones_like(px, dtype=torch.bool)
    for substep in range(SUBSTEPS):
        px = torch.where(live, px + vx * move, px)
        py = torch.where(live, py + vy * move, py)
        t = (((px - ax) * dx + (py - ay) * dy) * edge_inv_len2).clamp(0.0, 1.0)
        ox = px - (ax + t * dx)
        oy = py - (ay + t * dy)
        hit = (ox * ox + oy * oy <= r2) & (vx * ox + vy * oy < 0.0)
        hits = hit.sum(1, keepdim=True)
        hit_f = hit.to(px.dtype)
        hit_nx = (hit_f * nx).sum(1, keepdim=True)
        hit_ny = (hit_f * ny).sum(1, keepdim=True)
        single = live & (hits == 1)
        several = live & (hits > 1)
        dot = vx * hit_nx + vy * hit_ny
        vx = torch.where(single, vx - 2.0 * dot * hit_nx, torch.where(several, -vx, vx))
        vy = torch.where(single, vy - 2.0 * dot * hit_ny, torch.where(several, -vy, vy))
        if substep == SUBSTEPS - 1 and edge_owner.numel() > 0:
            first = torch.where(hit, edge_owner, edge_owner.numel()).amin(1, keepdim=True)
            last = torch.where(hit, edge_owner, -1).amax(1, keepdim=True)
            one_polygon = live & (hits > 0) & (first == last)
            px = torch.where(one_polygon, px + vx * move, px)
            py = torch.where(one_polygon, py + vy * move, py)
        live = live & ((px - tx) ** 2 + (py - ty) ** 2 > tr * tr)
    vx = torch.where(live, vx * DRAG, vx)
    vy = torch.where(live, vy * DRAG, vy)
    out_x_high, out_x_low = live & (px > 1.0), live & (px < 0.0)
    out_y_high, out_y_low = live & (py > 1.0), live & (py < 0.0)
    out = out_x_high | out_x_low | out_y_high | out_y_low
    px = torch.where(out_x_high, 0.95, torch.where(out_x_low, 0.05, px))
    py = torch.where(out_y_high, 0.95, torch.where(out_y_low, 0.05, py))
    vx = torch.where(out, 0.0, vx)
    vy = torch.where(out, 0.0, vy)
    return torch.cat([px, py], 1), torch.cat([vx, vy], 1), ~live.squeeze(1)


@functools.cache
def _compiled_torch_kernel() -> Callable[..., tuple[torch.Tensor, torch.Tensor, torch.Tensor]]:
    return torch.compile(_torch_kernel, dynamic=False, fullgraph=True)


def _numba_available() -> bool:
    try:
        import numba  # noqa: F401
    except ImportError:
        return False
    return True


class PinBallPhysics:
    """The batched PinBall dynamics of one map, independent of TorchRL.

    :meth:`step` advances ``N`` balls by one environment step in place. The
    state is kept in float64 so that long trajectories do not drift from a
    scalar double-precision implementation.

    Backends (same results up to rounding):

    * ``"numba"``: a compiled loop per ball that first collects the few edges
      the ball can reach in this step (bounding boxes, then distances) and
      tests only those in the substeps. CPU only; needs ``numba``. By far the
      fastest on CPU (``benchmarks/pinball_step.py``).
    * ``"torch"``: whole-batch tensor operations over ``[balls, all edges]``
      per substep, no Python loop over polygons or edges; runs on any device.
    * ``"compile"``: the same function through ``torch.compile`` (needs a C++
      compiler on CPU; the first call compiled for about 80 s here on a cold
      cache, and the result ran 2-4 times faster than ``"torch"``, far slower
      than numba).
    * ``"auto"``: ``"numba"`` when importable and on CPU, else ``"torch"``.

    Args:
        config: ``"simple"``, ``"hard"``, a map file or a :class:`PinBallConfig`.
        velocity_limit: per-axis velocity clip applied after the thrust.
        backend: one of the backends above.
        device: device of the state tensors.

    Examples:
        >>> physics = PinBallPhysics("simple", backend="torch")
        >>> position = torch.tensor([[0.5, 0.5]], dtype=torch.float64)
        >>> velocity = torch.zeros(1, 2, dtype=torch.float64)
        >>> physics.step(position, velocity, torch.tensor([0]))  # thrust +x
        tensor([False])
        >>> velocity
        tensor([[0.1990, 0.0000]], dtype=torch.float64)
    """

    def __init__(
        self,
        config: str | Path | PinBallConfig = "simple",
        *,
        velocity_limit: float = 2.0,
        backend: Backend = "auto",
        device: torch.device | str = "cpu",
    ) -> None:
        self.config = PinBallConfig.load(config)
        self.device = torch.device(device)
        if backend == "auto":
            backend = "numba" if self.device.type == "cpu" and _numba_available() else "torch"
        if backend == "numba" and self.device.type != "cpu":
            raise ValueError(f"the numba backend runs on CPU, not on {self.device}")
        if backend not in ("numba", "torch", "compile"):
            raise ValueError(f"unknown backend {backend!r}")
        self.backend: Backend = backend
        self.velocity_limit = float(velocity_limit)
        self.geometry = _Geometry(self.config, self.device)

    def step(self, position: torch.Tensor, velocity: torch.Tensor, action: torch.Tensor) -> torch.Tensor:
        """Advance every ball by one environment step.

        Args:
            position: ``[N, 2]`` float64 ball centres, updated in place.
            velocity: ``[N, 2]`` float64 velocities, updated in place.
            action: ``[N]`` integer actions (see :data:`ACTION_NAMES`).

        Returns:
            ``[N]`` bool: which balls entered the target during this step.
        """
        if position.dtype != torch.float64 or velocity.dtype != torch.float64:
            raise TypeError("PinBallPhysics.step needs float64 position and velocity")
        action = action.to(torch.int64)
        g = self.geometry
        tx, ty, tr = g.target
        if self.backend == "numba":
            reached = torch.empty(position.shape[0], dtype=torch.bool)
            step_balls(
                position.numpy(),
                velocity.numpy(),
                action.contiguous().numpy(),
                reached.numpy(),
                g.edges,
                g.boxes,
                g.first_edge,
                g.ball_radius,
                tx,
                ty,
                tr,
                self.velocity_limit,
            )
            return reached
        kernel = _compiled_torch_kernel() if self.backend == "compile" else _torch_kernel
        new_position, new_velocity, reached = kernel(
            position,
            velocity,
            action,
            g.edge_start,
            g.edge_dir,
            g.edge_inv_len2,
            g.edge_normal,
            g.edge_owner,
            g.ball_radius,
            g.target,
            self.velocity_limit,
        )
        position.copy_(new_position)
        velocity.copy_(new_velocity)
        return reached
