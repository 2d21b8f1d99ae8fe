"""A single-ball PinBall in plain Python, the yardstick for the batched env.

Written from the domain description (Konidaris & Barto 2009, as summarised in
the project's facts sheet) with one object per obstacle, the way the original
domain is usually written, and nothing shared with
``torchrl_subgoal.envs.pinball``: its own file parser, its own geometry (the
hit test uses a true distance and the reflection uses the edge's unit
tangent). Slow on purpose; only for tests.

One step:

* thrust ``velocity += (ax, ay) / 5`` for the action's unit vector, then each
  component clipped to ``[-velocity_limit, velocity_limit]``;
* 20 substeps: move by ``velocity * radius / 20``; ask every obstacle whether
  the ball hits it (bounding box first, then each edge: the edge's closest
  point is within the radius and the ball moves toward it); an obstacle hit on
  one edge answers with the velocity reflected about that edge, one hit on two
  or more edges (a corner) with the velocity reversed; exactly one obstacle
  hit: take its answer, and move once more if this was the last substep;
  several obstacles hit: reverse the velocity; then, if the centre is within
  the target circle, stop: the episode is over;
* otherwise drag ``velocity *= 0.995``, and if the ball left the unit square,
  put the offending coordinate at 0.05 or 0.95 and stop the ball.
"""

from __future__ import annotations

import math
from pathlib import Path

# action -> unit thrust direction: +x, +y, -x, -y, none
DIRECTIONS = ((1.0, 0.0), (0.0, 1.0), (-1.0, 0.0), (0.0, -1.0), (0.0, 0.0))


class Obstacle:
    """One polygon."""

    def __init__(self, points: list[tuple[float, float]]) -> None:
        self.points = points
        xs = [p[0] for p in points]
        ys = [p[1] for p in points]
        self.min_x, self.max_x = min(xs), max(xs)
        self.min_y, self.max_y = min(ys), max(ys)

    def edges(self) -> list[tuple[tuple[float, float], tuple[float, float]]]:
        return [(self.points[k], self.points[(k + 1) % len(self.points)]) for k in range(len(self.points))]

    def hit_edges(
        self, x: float, y: float, vx: float, vy: float, radius: float
    ) -> list[tuple[tuple[float, float], tuple[float, float]]]:
        """The edges the ball hits now (empty when its bounding box rules it out)."""
        if x + radius < self.min_x or x - radius > self.max_x or y + radius < self.min_y or y - radius > self.max_y:
            return []
        found = []
        for p, q in self.edges():
            cx, cy = closest_point(p, q, x, y)
            toward = vx * (cx - x) + vy * (cy - y) > 0.0
            if toward and math.hypot(x - cx, y - cy) <= radius:
                found.append((p, q))
        return found

    def answer(
        self, hits: list[tuple[tuple[float, float], tuple[float, float]]], vx: float, vy: float
    ) -> tuple[float, float, bool]:
        """New velocity, and whether it was a corner (several edges) hit."""
        if len(hits) > 1:
            return -vx, -vy, True
        (p, q) = hits[0]
        length = math.hypot(q[0] - p[0], q[1] - p[1])
        ux, uy = (q[0] - p[0]) / length, (q[1] - p[1]) / length
        along = vx * ux + vy * uy
        # mirror image: keep the tangential part, flip the normal part
        return 2.0 * along * ux - vx, 2.0 * along * uy - vy, False


def closest_point(p: tuple[float, float], q: tuple[float, float], x: float, y: float) -> tuple[float, float]:
    ex, ey = q[0] - p[0], q[1] - p[1]
    s = ((x - p[0]) * ex + (y - p[1]) * ey) / (ex * ex + ey * ey)
    s = 0.0 if s < 0.0 else 1.0 if s > 1.0 else s
    return p[0] + s * ex, p[1] + s * ey


class ReferencePinBall:
    """One ball on one map file."""

    def __init__(self, path: str | Path, velocity_limit: float = 2.0) -> None:
        self.obstacles: list[Obstacle] = []
        for line in Path(path).read_text().splitlines():
            words = line.split()
            if not words:
                continue
            numbers = [float(w) for w in words[1:]]
            if words[0] == "ball":
                self.radius = numbers[0]
            elif words[0] == "target":
                self.target_x, self.target_y, self.target_radius = numbers
            elif words[0] == "start":
                self.start_x, self.start_y = numbers
            elif words[0] == "polygon":
                self.obstacles.append(Obstacle(list(zip(numbers[::2], numbers[1::2], strict=True))))
        self.velocity_limit = velocity_limit
        # event counters, so that tests can show which rules a run exercised
        self.reflections = self.reversals = self.extra_moves = self.clamps = 0
        self.reset()

    def reset(self) -> None:
        self.set_state(self.start_x, self.start_y, 0.0, 0.0)

    def set_state(self, x: float, y: float, vx: float, vy: float) -> None:
        self.x, self.y, self.vx, self.vy = x, y, vx, vy

    @property
    def state(self) -> tuple[float, float, float, float]:
        return self.x, self.y, self.vx, self.vy

    def in_target(self) -> bool:
        return math.hypot(self.x - self.target_x, self.y - self.target_y) <= self.target_radius

    def move(self) -> None:
        self.x += self.vx * self.radius / 20
        self.y += self.vy * self.radius / 20

    def step(self, action: int) -> bool:
        """Play one action; True when the ball entered the target."""
        dx, dy = DIRECTIONS[action]
        limit = self.velocity_limit
        self.vx = max(-limit, min(limit, self.vx + dx / 5))
        self.vy = max(-limit, min(limit, self.vy + dy / 5))
        for substep in range(20):
            self.move()
            answers = []
            for obstacle in self.obstacles:
                hits = obstacle.hit_edges(self.x, self.y, self.vx, self.vy, self.radius)
                if hits:
                    answers.append(obstacle.answer(hits, self.vx, self.vy))
            if len(answers) == 1:
                self.vx, self.vy, corner = answers[0]
                self.reversals += corner
                self.reflections += not corner
                if substep == 19:
                    self.move()
                    self.extra_moves += 1
            elif len(answers) > 1:
                self.vx, self.vy = -self.vx, -self.vy
                self.reversals += 1
            if self.in_target():
                return True
        self.vx *= 0.995
        self.vy *= 0.995
        left = False
        if self.x > 1.0:
            self.x, left = 0.95, True
        if self.x < 0.0:
            self.x, left = 0.05, True
        if self.y > 1.0:
            self.y, left = 0.95, True
        if self.y < 0.0:
            self.y, left = 0.05, True
        if left:
            self.vx = self.vy = 0.0
            self.clamps += 1
        return False
