"""PinBall (Konidaris & Barto 2009) as a batched TorchRL environment.

A ball of radius ``ball_radius`` moves in the unit square among polygonal
obstacles; the agent thrusts it along one axis per step and is rewarded when
the ball's centre enters the target circle. One environment holds ``N``
independent balls (the batch dimension = independent learners).

Dynamics of one step, for every ball (see :class:`PinBallPhysics`):

1. thrust: ``velocity += action / 5`` per axis, then both components are
   clipped to ``[-velocity_limit, velocity_limit]`` (2.0 by default, as the
   widely used Python ports; the Java original clips to 1.0);
2. 20 substeps of ``position += velocity * ball_radius / 20``, each followed
   by the collision test against every edge of every polygon and by the goal
   test (below);
3. drag ``velocity *= 0.995`` and the bounds rule: a coordinate above 1 is set
   to 0.95, one below 0 to 0.05, and the velocity of a ball that left the unit
   square is zeroed.

Collision rule. An edge is *hit* when its closest point to the ball's centre
lies within ``ball_radius`` of the centre and the ball moves toward that point
(``velocity · (closest - centre) > 0``). Exactly one edge hit in a substep
reflects the velocity about that edge (speed kept); two or more (two edges of
one polygon at a corner, or edges of two polygons touched in the same
substep) reverse the velocity. When the last substep had a collision with
exactly one polygon (one edge or a corner of it), the ball makes one extra
substep move so that it does not end the step touching the obstacle (the rule
of the original domain; not after a collision with two polygons). The
bounding-box rejection of the classic implementation is a speed-up only: a hit
needs the centre within ``ball_radius`` of an edge, hence inside the polygon's
box grown by the radius.

Goal rule. When the centre is within the target radius after a substep, the
episode ends at once: the ball stays where it entered the target, makes no
further substep, and gets neither drag nor the bounds rule (its observation
is the state at entry). Stepping such a ball again without a reset simply
continues the physics from there; ``step_and_maybe_reset`` resets it first.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any, Literal, NamedTuple

import numba
import numpy as np
import torch
from tensordict import TensorDict, TensorDictBase
from tensordict.utils import NestedKey
from torchrl.data import Bounded, Categorical, Composite, Unbounded
from torchrl.envs import EnvBase

from torchrl_subgoal._kernels.random import (
    ENV_STREAM,
    _random_action,
    learner_keys,
    new_streams,
    random_actions,
)
from torchrl_subgoal._kernels.steps import (
    env_observe,
    env_reset,
    env_scratch,
    env_shaping_observation,
    env_step,
    implements,
)

if TYPE_CHECKING:
    from matplotlib.axes import Axes

    from torchrl_subgoal.subgoals import Predicate

__all__ = [
    "ACTION_NAMES",
    "PinBallConfig",
    "PinBallEnv",
    "PinBallPhysics",
    "check_subgoal",
    "draw_map",
    "point_in_polygon",
]

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
            raise ValueError(
                f"PinBall config {str(config)!r} is neither one of {_NAMED_CONFIGS} "
                f"nor an existing file"
            )
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
                    raise fail(
                        f"{keyword!r} expects {arity[keyword]} number(s), got {len(numbers)}"
                    )
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


def _circle_hits_polygon(
    centre: tuple[float, float], radius: float, vertices: Sequence[tuple[float, float]]
) -> bool:
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
        self.edges = np.ascontiguousarray(
            np.concatenate([a, d, (1.0 / length**2)[:, None], normal], 1)
        )
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
    px: float, py: float, vx: float, vy: float, a: int, edges: np.ndarray, boxes: np.ndarray, first_edge: np.ndarray,
    ball_radius: float, target_x: float, target_y: float, target_radius: float, velocity_limit: float,
    candidates: np.ndarray, owners: np.ndarray,
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
        if (
            px + reach < boxes[p, 0]
            or py + reach < boxes[p, 1]
            or px - reach > boxes[p, 2]
            or py - reach > boxes[p, 3]
        ):
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
    """A :class:`PinBallEnv`'s balls as numpy views, its map and its settings, for compiled loops
    (:func:`ball_step` steps one ball in place).

    Examples:
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
def ball_step(balls: BallKernelState, b: int, a: int, candidates: np.ndarray, owners: np.ndarray,
              ) -> tuple[float, float, float, float, np.float32, bool, bool]:
    """Ball ``b``'s env step with action ``a`` (``balls`` updated in place), as :meth:`PinBallEnv.step` does it:
    ``(x, y, vx, vy, reward as float32, terminated, done)``. ``candidates``, ``owners``: :func:`step_ball`'s scratch.

    Examples:
        >>> import numpy as np
        >>> balls = PinBallEnv(1, seed=0).kernel_state()
        >>> scratch = np.empty(balls.edges.shape[0], dtype=np.int64)
        >>> x, y, vx, vy, reward, terminated, done = ball_step(balls, 0, 0, scratch, scratch.copy())
        >>> bool(vx > 0.0), int(balls.steps[0]), bool(done)
        (True, 1, False)
    """
    executed = _random_action(a, balls.streams, b, balls.random_prob, _NUM_ACTIONS)
    px, py, vx, vy, terminated = step_ball(
        balls.position[b, 0], balls.position[b, 1], balls.velocity[b, 0], balls.velocity[b, 1], executed,
        balls.edges, balls.boxes, balls.first_edge, balls.ball_radius, balls.target_x, balls.target_y,
        balls.target_radius, balls.velocity_limit, candidates, owners)
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
        >>> balls = PinBallEnv(1, seed=0).kernel_state()
        >>> ball_reset(balls, 0)[2:], int(balls.steps[0])
        ((0.0, 0.0), 0)
    """
    balls.position[b, 0], balls.position[b, 1] = balls.start_x, balls.start_y
    balls.velocity[b, 0], balls.velocity[b, 1] = 0.0, 0.0
    balls.steps[b] = 0
    return balls.start_x, balls.start_y, 0.0, 0.0


# The fused engine's env step (torchrl_subgoal._kernels.engine.fused_run): the learner and the shaping read the
# observation as PinBallEnv emits it (float32), held in float64 scratch rows: before, after and at a reset.


@implements(env_scratch, BallKernelState)
def _ball_scratch(env: BallKernelState) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    n = env.edges.shape[0]
    return np.empty(4), np.empty(4), np.empty(4), np.empty(n, np.int64), np.empty(n, np.int64)


@numba.njit(cache=True, nogil=True, inline="always")
def _observation(out: np.ndarray, px: float, py: float, vx: float, vy: float) -> np.ndarray:
    """``out`` ← the float32 observation ``(x, y, vx, vy)``."""
    out[0], out[1], out[2], out[3] = np.float32(px), np.float32(py), np.float32(vx), np.float32(vy)
    return out


@implements(env_observe, BallKernelState)
def _ball_observe(env: BallKernelState, b: int, scratch: tuple[np.ndarray, ...]) -> np.ndarray:
    return _observation(scratch[0], env.position[b, 0], env.position[b, 1], env.velocity[b, 0], env.velocity[b, 1])


@implements(env_step, BallKernelState)
def _ball_env_step(env: BallKernelState, b: int, a: int, scratch: tuple[np.ndarray, ...],
                   ) -> tuple[np.ndarray, np.float32, bool, bool]:
    px, py, vx, vy, reward, terminated, done = ball_step(env, b, a, scratch[3], scratch[4])
    return _observation(scratch[1], px, py, vx, vy), reward, terminated, done


@implements(env_reset, BallKernelState)
def _ball_env_reset(env: BallKernelState, b: int, scratch: tuple[np.ndarray, ...]) -> np.ndarray:
    px, py, vx, vy = ball_reset(env, b)
    return _observation(scratch[2], px, py, vx, vy)


@implements(env_shaping_observation, BallKernelState)
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
            position[i, 0], position[i, 1], velocity[i, 0], velocity[i, 1], action[i], edges, boxes, first_edge,
            ball_radius, target_x, target_y, target_radius, velocity_limit, candidates, owners,
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

    def step(
        self, position: torch.Tensor, velocity: torch.Tensor, action: torch.Tensor
    ) -> torch.Tensor:
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


# --------------------------------------------------------------------------
# TorchRL environment
# --------------------------------------------------------------------------


class PinBallEnv(EnvBase):
    """A batch of independent PinBall balls as one TorchRL environment.

    Observation ``[N, 4]`` float32 ``(x, y, xdot, ydot)``; action ``[N]`` int64
    in ``0..4`` = ``+x, +y, -x, -y, none`` (:data:`ACTION_NAMES`); reward
    ``[N, 1]``; ``done``/``terminated``/``truncated`` ``[N, 1]``. With
    probability ``random_action_prob`` the executed action is drawn uniformly
    from the five instead (drawn from each ball's own random stream, so a
    ball's trajectory depends on its seed and its actions only). ``terminated`` is set when the ball enters the target
    (reward ``goal_reward``), ``truncated`` after ``max_steps`` steps. The
    per-step reward also adds ``thrust_penalty`` when the executed action is a
    thrust and ``step_penalty`` when it is "none" (the classic domain charges
    -5 and -1; both default to 0 as in the paper's released code). Partial
    resets through ``"_reset"`` reset only the flagged balls (to the start, at
    rest). The dynamics are described in the module docstring and run by
    :class:`PinBallPhysics` on a float64 state held by the env; observations
    are its float32 copy.

    Args:
        num_envs: number of balls (the batch size).
        config: ``"simple"``, ``"hard"``, a map file or a :class:`PinBallConfig`.
        max_steps: steps after which an episode is truncated.
        random_action_prob: probability that a random action replaces the chosen one.
        goal_reward: reward on entering the target.
        step_penalty: reward added on a step with action "none" (classic: -1).
        thrust_penalty: reward added on a step with a thrust (classic: -5).
        velocity_limit: per-axis velocity clip after the thrust (Java original: 1.0).
        seed: one seed per ball, or one integer they are derived from (see
            :func:`~torchrl_subgoal._kernels.random.learner_keys`); ``None`` draws one.
        device: device of the tensors.
        backend: physics backend, see :class:`PinBallPhysics`.

    Examples:
        >>> env = PinBallEnv(num_envs=8, seed=0)
        >>> td = env.reset()
        >>> td["observation"][0]
        tensor([0.2000, 0.9000, 0.0000, 0.0000])
        >>> td["action"] = torch.zeros(8, dtype=torch.int64)  # thrust +x
        >>> td, td_next = env.step_and_maybe_reset(td)
        >>> td["next", "observation"].shape
        torch.Size([8, 4])
    """

    def __init__(
        self,
        num_envs: int = 1,
        config: str | Path | PinBallConfig = "simple",
        *,
        max_steps: int = 10_000,
        random_action_prob: float = 0.1,
        goal_reward: float = 10_000.0,
        step_penalty: float = 0.0,
        thrust_penalty: float = 0.0,
        velocity_limit: float = 2.0,
        seed: int | Sequence[int] | np.ndarray | None = None,
        device: torch.device | str = "cpu",
        backend: Backend = "auto",
    ) -> None:
        if num_envs < 1:
            raise ValueError(f"num_envs must be at least 1, got {num_envs}")
        if not 0.0 <= random_action_prob <= 1.0:
            raise ValueError(f"random_action_prob must be in [0, 1], got {random_action_prob}")
        if max_steps < 1:
            raise ValueError(f"max_steps must be at least 1, got {max_steps}")
        super().__init__(device=device, batch_size=torch.Size([num_envs]))
        device = self.device
        self.physics = PinBallPhysics(
            config, velocity_limit=velocity_limit, backend=backend, device=device
        )
        cfg = self.physics.config
        self.config = cfg
        self.ball_radius: float = cfg.ball_radius
        self.target: tuple[float, float, float] = cfg.target
        self.start: tuple[float, float] = cfg.start
        self.obstacles: list[torch.Tensor] = [
            torch.tensor(vertices, dtype=torch.float32, device=device) for vertices in cfg.polygons
        ]
        self.max_steps = int(max_steps)
        self.random_action_prob = float(random_action_prob)
        self.goal_reward = float(goal_reward)
        self.step_penalty = float(step_penalty)
        self.thrust_penalty = float(thrust_penalty)
        self.velocity_limit = float(velocity_limit)

        n = num_envs
        self._position = torch.empty(n, 2, dtype=torch.float64, device=device)
        self._velocity = torch.zeros(n, 2, dtype=torch.float64, device=device)
        self._steps = torch.zeros(n, dtype=torch.int64, device=device)
        self._start = torch.tensor(cfg.start, dtype=torch.float64, device=device)
        self._position[:] = self._start
        self._set_seed(seed)

        # Reflections keep the speed, which the thrust clip bounds by √2·limit.
        speed = math.sqrt(2.0) * self.velocity_limit
        low = torch.tensor([0.0, 0.0, -speed, -speed])
        self.observation_spec = Composite(
            observation=Bounded(
                low=low.expand(n, 4),
                high=torch.tensor([1.0, 1.0, speed, speed]).expand(n, 4),
                shape=(n, 4),
                dtype=torch.float32,
                device=device,
            ),
            shape=(n,),
            device=device,
        )
        self.action_spec = Categorical(
            len(ACTION_NAMES), shape=(n,), dtype=torch.int64, device=device
        )
        self.reward_spec = Unbounded(shape=(n, 1), dtype=torch.float32, device=device)
        self.full_done_spec = Composite(
            done=Categorical(2, shape=(n, 1), dtype=torch.bool, device=device),
            terminated=Categorical(2, shape=(n, 1), dtype=torch.bool, device=device),
            truncated=Categorical(2, shape=(n, 1), dtype=torch.bool, device=device),
            shape=(n,),
            device=device,
        )

    # -- TorchRL hooks -----------------------------------------------------

    def _observation(self) -> torch.Tensor:
        return torch.cat([self._position, self._velocity], 1).to(torch.float32)

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs: Any) -> TensorDictBase:
        reset = tensordict.get("_reset", None) if tensordict is not None else None
        if reset is None:
            self._position[:] = self._start
            self._velocity.zero_()
            self._steps.zero_()
        else:
            mask = reset.reshape(-1, 1)
            self._position.copy_(torch.where(mask, self._start, self._position))
            self._velocity.masked_fill_(mask, 0.0)
            self._steps.masked_fill_(mask.squeeze(1), 0)
        false = torch.zeros(*self.batch_size, 1, dtype=torch.bool, device=self.device)
        return TensorDict(
            {
                "observation": self._observation(),
                "done": false,
                "terminated": false.clone(),
                "truncated": false.clone(),
            },
            batch_size=self.batch_size,
            device=self.device,
        )

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        action = tensordict.get("action")
        if self.random_action_prob > 0.0:
            executed = np.empty(action.shape[0], np.int64)
            random_actions(action.cpu().numpy().astype(np.int64), self.streams, self.random_action_prob,
                                    len(ACTION_NAMES), executed)
            action = torch.from_numpy(executed).to(self.device)
        terminated = self.physics.step(self._position, self._velocity, action).unsqueeze(1)
        self._steps += 1
        truncated = (self._steps >= self.max_steps).unsqueeze(1) & ~terminated
        reward = terminated.to(torch.float32) * self.goal_reward
        if self.step_penalty or self.thrust_penalty:
            thrust = (action != ACTION_NAMES.index("none")).unsqueeze(1)
            reward += torch.where(thrust, self.thrust_penalty, self.step_penalty)
        return TensorDict(
            {
                "observation": self._observation(),
                "reward": reward,
                "done": terminated | truncated,
                "terminated": terminated,
                "truncated": truncated,
            },
            batch_size=self.batch_size,
            device=self.device,
        )

    def _set_seed(self, seed: int | Sequence[int] | np.ndarray | None) -> None:
        keys = learner_keys(np.random.default_rng() if seed is None else seed, self.batch_size.numel())
        self.streams = new_streams(keys, ENV_STREAM)

    # -- map helpers -------------------------------------------------------

    def kernel_state(self, observation_key: NestedKey = "observation") -> BallKernelState:
        """The balls' state as numpy views (CPU only), for a compiled loop to step in place.

        Args:
            observation_key: the entry a compiled loop's shaping reads: ``"observation"``, the one there is.

        Examples:
            >>> PinBallEnv(2, seed=0).kernel_state().position.shape
            (2, 2)
        """
        if self.device.type != "cpu":
            raise TypeError(f"kernel_state needs a CPU env, not {self.device}")
        if observation_key != "observation":
            raise TypeError(f"a compiled loop reads PinBall's 'observation', not {observation_key!r}")
        if self.physics.backend != "numba":  # the compiled loop steps the numba physics
            raise TypeError("a compiled loop needs PinBall's numba physics backend")
        g = self.physics.geometry
        tx, ty, tr = g.target
        return BallKernelState(
            self._position.numpy(), self._velocity.numpy(), self._steps.numpy(), self.streams, self.start[0],
            self.start[1], g.edges, g.boxes, g.first_edge, g.ball_radius, tx, ty, tr, self.physics.velocity_limit,
            self.max_steps, self.random_action_prob, self.goal_reward, self.step_penalty, self.thrust_penalty)

    def sample_free_positions(
        self, n: int, generator: torch.Generator | None = None
    ) -> torch.Tensor:
        """Draw ``n`` uniform points of the unit square whose target-sized circle is obstacle-free.

        Used to draw random subgoals: a point is kept when its circle of the
        target's radius neither contains nor touches any obstacle.

        Args:
            n: number of points.
            generator: CPU generator to draw from (the global one if ``None``).

        Returns:
            ``[n, 2]`` float32 points on the env's device.
        """
        radius = self.target[2]
        kept: list[torch.Tensor] = []
        count = 0
        for _ in range(10_000):
            if count >= n:
                break
            points = torch.rand(
                max(2 * (n - count), 64), 2, generator=generator, dtype=torch.float64
            )
            points = points[_circles_free(points, radius, self.config)]
            kept.append(points)
            count += points.shape[0]
        else:
            raise RuntimeError(
                f"{self.config.source}: found no obstacle-free circle of radius {radius}"
            )
        return torch.cat(kept)[:n].to(device=self.device, dtype=torch.float32)


def _circles_free(points: torch.Tensor, radius: float, config: PinBallConfig) -> torch.Tensor:
    """``[M]`` mask of the points whose circle of ``radius`` overlaps no polygon."""
    free = torch.ones(points.shape[0], dtype=torch.bool)
    px, py = points[:, 0:1], points[:, 1:2]
    for vertices in config.polygons:
        a = torch.tensor(vertices, dtype=torch.float64)
        d = torch.roll(a, -1, 0) - a
        ax, ay, dx, dy = a[:, 0], a[:, 1], d[:, 0], d[:, 1]
        t = (((px - ax) * dx + (py - ay) * dy) / (dx * dx + dy * dy)).clamp(0.0, 1.0)
        near = ((px - ax - t * dx) ** 2 + (py - ay - t * dy) ** 2 < radius * radius).any(1)
        straddles = (ay > py) != (ay + dy > py)
        crossing_x = ax + (py - ay) * dx / torch.where(straddles, dy, torch.ones_like(dy))
        inside = (straddles & (px < crossing_x)).sum(1) % 2 == 1
        free &= ~(near | inside)
    return free


def check_subgoal(predicate: Predicate) -> str | None:
    """Why ``predicate`` is not a valid PinBall subgoal, or ``None``.

    A PinBall subgoal is a circle over the ball position (observation entries
    0 and 1) with a positive radius and its centre on the table (the unit
    square). Used by subgoal files that declare ``domain: pinball``.

    Examples:
        >>> from torchrl_subgoal import Cell, Circle
        >>> check_subgoal(Circle((0.5, 0.2), 0.04)) is None
        True
        >>> check_subgoal(Cell(3, 6))
        'pinball subgoals are circles over (x, y), not cell'
    """
    from torchrl_subgoal.subgoals import Circle

    if not isinstance(predicate, Circle):
        return f"pinball subgoals are circles over (x, y), not {predicate.kind}"
    if tuple(predicate.dims()) != (0, 1):
        return f"a pinball subgoal circle covers (x, y), dims [0, 1], not {list(predicate.dims())}"
    if not predicate.radius > 0:
        return f"radius must be positive, got {predicate.radius}"
    x, y = predicate.centre
    if not (0.0 <= x <= 1.0 and 0.0 <= y <= 1.0):
        return f"centre ({x}, {y}) is off the table (the unit square)"
    return None


# --------------------------------------------------------------------------
# Drawing
# --------------------------------------------------------------------------


def draw_map(
    ax: Axes,
    config: str | Path | PinBallConfig = "simple",
    circles: Mapping[str, Sequence[tuple[float, float, float]]] | None = None,
) -> Axes:
    """Draw a PinBall map, and optionally ordered subgoal circles, on matplotlib axes.

    Obstacles are grey, the start a blue dot, the target a red circle. Each
    named pattern in ``circles`` gets one colour; its circles are numbered in
    order (1, 2, ...). The y axis points down, as in the usual PinBall
    pictures (the start of the simple map at the bottom left).

    Args:
        ax: the axes to draw on.
        config: ``"simple"``, ``"hard"``, a map file or a :class:`PinBallConfig`.
        circles: pattern name → ordered ``(x, y, radius)`` subgoal circles.

    Returns:
        The axes, for chaining.

    Examples:
        >>> import matplotlib
        >>> matplotlib.use("Agg")
        >>> import matplotlib.pyplot as plt
        >>> fig, ax = plt.subplots()
        >>> _ = draw_map(ax, "simple", {"participant 1": [(0.59, 0.65, 0.04), (0.64, 0.32, 0.04)]})
    """
    from matplotlib.patches import Circle, Polygon

    cfg = PinBallConfig.load(config)
    for vertices in cfg.polygons:
        ax.add_patch(Polygon(vertices, closed=True, facecolor="0.45", edgecolor="0.25", lw=0.5))
    tx, ty, tr = cfg.target
    ax.add_patch(Circle((tx, ty), tr, facecolor="tab:red", alpha=0.8, label="target"))
    ax.plot(*cfg.start, "o", color="tab:blue", markersize=6, label="start")
    colours = [f"C{i}" for i in range(10) if i not in (0, 3)]  # C0 / C3: start, target
    for index, (name, pattern) in enumerate((circles or {}).items()):
        colour = colours[index % len(colours)]
        for order, (x, y, r) in enumerate(pattern, start=1):
            ax.add_patch(
                Circle(
                    (x, y),
                    r,
                    facecolor=colour,
                    edgecolor=colour,
                    alpha=0.35,
                    label=name if order == 1 else "_nolegend_",
                )
            )
            ax.annotate(str(order), (x, y), ha="center", va="center", fontsize=7, color="black")
    ax.set_xlim(0.0, 1.0)
    ax.set_ylim(1.0, 0.0)
    ax.set_aspect("equal")
    ax.set_xticks([])
    ax.set_yticks([])
    return ax
