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

import math
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import torch
from tensordict import TensorDict, TensorDictBase
from tensordict.utils import NestedKey
from torchrl.data import Bounded, Categorical, Composite, Unbounded
from torchrl.envs import EnvBase

from torchrl_subgoal._kernels.random import ENV_STREAM, learner_keys, new_streams, random_actions
from torchrl_subgoal.envs.pinball_physics import (
    _DATA_DIR,  # noqa: F401  (the shipped maps' folder, read here too)
    ACTION_NAMES,
    Backend,
    BallKernelState,
    PinBallConfig,
    PinBallPhysics,
    point_in_polygon,
)

if TYPE_CHECKING:
    from matplotlib.axes import Axes


__all__ = [
    "ACTION_NAMES",
    "PinBallConfig",
    "PinBallEnv",
    "PinBallPhysics",
    "draw_map",
    "point_in_polygon",
]


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
        self.physics = PinBallPhysics(config, velocity_limit=velocity_limit, backend=backend, device=device)
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
        self.action_spec = Categorical(len(ACTION_NAMES), shape=(n,), dtype=torch.int64, device=device)
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
            random_actions(
                action.cpu().numpy().astype(np.int64),
                self.streams,
                self.random_action_prob,
                len(ACTION_NAMES),
                executed,
            )
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
            self._position.numpy(),
            self._velocity.numpy(),
            self._steps.numpy(),
            self.streams,
            self.start[0],
            self.start[1],
            g.edges,
            g.boxes,
            g.first_edge,
            g.ball_radius,
            tx,
            ty,
            tr,
            self.physics.velocity_limit,
            self.max_steps,
            self.random_action_prob,
            self.goal_reward,
            self.step_penalty,
            self.thrust_penalty,
        )

    def sample_free_positions(self, n: int, generator: torch.Generator | None = None) -> torch.Tensor:
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
            points = torch.rand(max(2 * (n - count), 64), 2, generator=generator, dtype=torch.float64)
            points = points[_circles_free(points, radius, self.config)]
            kept.append(points)
            count += points.shape[0]
        else:
            raise RuntimeError(f"{self.config.source}: found no obstacle-free circle of radius {radius}")
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
