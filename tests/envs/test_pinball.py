"""PinBall: physics rules, TorchRL behaviour, config files, and agreement with a scalar reference."""

from __future__ import annotations

import math
import re
from pathlib import Path

import pytest
import torch
from torchrl.envs import ParallelEnv, SerialEnv
from torchrl.envs.utils import check_env_specs

from torchrl_subgoal.domains.pinball import check_subgoal
from torchrl_subgoal.envs.pinball import (
    ACTION_NAMES,
    PinBallConfig,
    PinBallEnv,
    PinBallPhysics,
    draw_map,
)
from torchrl_subgoal.envs.pinball_physics import DRAG

from .pinball_reference import Obstacle, ReferencePinBall, closest_point

PLUS_X, PLUS_Y, MINUS_X, MINUS_Y, NONE = range(5)

try:
    import numba  # noqa: F401

    BACKENDS = ["numba", "torch"]
except ImportError:
    BACKENDS = ["torch"]

HEADER = "ball 0.02\ntarget 0.9 0.9 0.04\nstart 0.5 0.5\n"
# the same, with the start away from the obstacles the tests place in the middle
FAR_START = "ball 0.02\ntarget 0.9 0.9 0.04\nstart 0.9 0.1\n"
WALLS = (
    "polygon 0 0 0 .01 1 .01 1 0\n"
    "polygon 0 0 .01 0 .01 1 0 1\n"
    "polygon 0 1 0 .99 1 .99 1 1\n"
    "polygon 1 1 .99 1 .99 0 1 0\n"
)


def physics(text: str, backend: str, **kwargs: float) -> PinBallPhysics:
    config = PinBallConfig.parse(text, source="test map")
    return PinBallPhysics(config, backend=backend, **kwargs)  # type: ignore[arg-type]


def ball(x: float, y: float, vx: float, vy: float) -> tuple[torch.Tensor, torch.Tensor]:
    return (
        torch.tensor([[x, y]], dtype=torch.float64),
        torch.tensor([[vx, vy]], dtype=torch.float64),
    )


def act(*actions: int) -> torch.Tensor:
    return torch.tensor(actions, dtype=torch.int64)


# -- physics rules ------------------------------------------------------------


@pytest.mark.parametrize("backend", BACKENDS)
def test_straight_flight_with_drag(backend: str) -> None:
    sim = physics(HEADER, backend)
    pos, vel = ball(0.5, 0.5, 0.0, 0.0)
    assert not sim.step(pos, vel, act(PLUS_X)).item()
    # the thrust acts before the substeps: 20 moves of 0.2 * 0.02 / 20, then drag
    torch.testing.assert_close(pos, torch.tensor([[0.504, 0.5]], dtype=torch.float64))
    torch.testing.assert_close(vel, torch.tensor([[0.2 * DRAG, 0.0]], dtype=torch.float64))
    sim.step(pos, vel, act(NONE))
    torch.testing.assert_close(pos[0, 0].item(), 0.504 + 0.2 * DRAG * 0.02)
    torch.testing.assert_close(vel[0, 0].item(), 0.2 * DRAG**2)
    sim.step(pos, vel, act(MINUS_Y))
    torch.testing.assert_close(vel[0, 1].item(), -0.2 * DRAG)
    torch.testing.assert_close(pos[0, 1].item(), 0.5 - 0.2 * 0.02)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("limit", [2.0, 1.0])
def test_thrust_is_clipped_per_axis(backend: str, limit: float) -> None:
    sim = physics(HEADER, backend, velocity_limit=limit)
    pos, vel = ball(0.3, 0.5, limit - 0.05, -limit - 0.3)
    sim.step(pos, vel, act(PLUS_X))
    # x clipped after the thrust; y (already beyond the limit) clipped too
    torch.testing.assert_close(vel, torch.tensor([[limit, -limit]], dtype=torch.float64) * DRAG)
    torch.testing.assert_close(pos[0, 0].item(), 0.3 + limit * 0.02)


@pytest.mark.parametrize("backend", BACKENDS)
def test_reflection_off_flat_wall(backend: str) -> None:
    sim = physics(HEADER + WALLS, backend)
    # moving down-right toward the floor's top edge (y = 0.01); contact at y = 0.03
    pos, vel = ball(0.5, 0.035, 0.6, -0.8)
    sim.step(pos, vel, act(NONE))
    torch.testing.assert_close(vel, torch.tensor([[0.6, 0.8]], dtype=torch.float64) * DRAG)
    angle_in, angle_out = math.atan2(0.8, 0.6), math.atan2(vel[0, 1].item(), vel[0, 0].item())
    assert angle_out == pytest.approx(angle_in, abs=1e-12)
    assert pos[0, 1].item() > 0.03  # bounced back off the wall


@pytest.mark.parametrize("backend", BACKENDS)
def test_reflection_off_slanted_edge(backend: str) -> None:
    angle = math.radians(30.0)
    ux, uy = math.cos(angle), math.sin(angle)
    # triangle whose lower edge rises at 30 degrees; the ball comes straight up at it
    sim = physics(FAR_START + f"polygon 0.2 0.2 0.8 {0.2 + 0.6 * math.tan(angle)} 0.2 0.7\n", backend)
    edge_y = 0.2 + 0.3 * math.tan(angle)
    pos, vel = ball(0.5, edge_y - 0.021 / ux, 0.0, 1.0)
    sim.step(pos, vel, act(NONE))
    # mirror image about the edge: 2 (v.u) u - v, speed kept
    expected = torch.tensor([[2 * uy * ux, 2 * uy * uy - 1.0]], dtype=torch.float64) * DRAG
    torch.testing.assert_close(vel, expected)
    assert vel.norm().item() == pytest.approx(DRAG, abs=1e-12)


@pytest.mark.parametrize("backend", BACKENDS)
def test_corner_of_one_polygon_reverses_velocity(backend: str) -> None:
    diamond = "polygon 0.5 0.4 0.6 0.5 0.5 0.6 0.4 0.5\n"
    sim = physics(FAR_START + diamond, backend)
    # aimed (slightly off-axis) at the bottom vertex: both edges' closest point is the vertex
    pos, vel = ball(0.5, 0.375, 0.05, 1.0)
    sim.step(pos, vel, act(NONE))
    torch.testing.assert_close(vel, torch.tensor([[-0.05, -1.0]], dtype=torch.float64) * DRAG)


@pytest.mark.parametrize("backend", BACKENDS)
def test_two_polygons_in_one_substep_reverse_velocity(backend: str) -> None:
    sim = physics(HEADER + WALLS, backend)
    # diagonally into the bottom-left corner: floor and left wall touched together
    pos, vel = ball(0.04, 0.04, -1.0, -1.0)
    sim.step(pos, vel, act(NONE))
    torch.testing.assert_close(vel, torch.tensor([[1.0, 1.0]], dtype=torch.float64) * DRAG)


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize(
    ("case", "start", "velocity", "end"),
    [
        # 20 moves of 0.001: contact only at the 20th substep, then one move back out
        ("one edge", (0.5, 0.0495), (0.0, -1.0), (0.5, 0.0305)),
        ("corner of one polygon", (0.5, 0.3605), (0.0, 1.0), (0.5, 0.3795)),
        # floor and left wall together: reversed, but no extra move
        ("two polygons", (0.0495, 0.0495), (-1.0, -1.0), (0.0295, 0.0295)),
    ],
)
def test_extra_move_after_a_hit_in_the_last_substep(
    backend: str,
    case: str,
    start: tuple[float, float],
    velocity: tuple[float, float],
    end: tuple[float, float],
) -> None:
    diamond = "polygon 0.5 0.4 0.6 0.5 0.5 0.6 0.4 0.5\n"
    sim = physics(FAR_START + WALLS + diamond, backend)
    pos, vel = ball(*start, *velocity)
    sim.step(pos, vel, act(NONE))
    torch.testing.assert_close(vel, -torch.tensor([velocity], dtype=torch.float64) * DRAG)
    torch.testing.assert_close(pos, torch.tensor([end], dtype=torch.float64), rtol=0, atol=1e-12)


@pytest.mark.parametrize("backend", BACKENDS)
def test_out_of_bounds_clamp(backend: str) -> None:
    sim = physics(HEADER, backend)  # no walls
    pos = torch.tensor([[0.999, 0.5], [0.5, 0.001], [0.5, 0.5]], dtype=torch.float64)
    vel = torch.tensor([[1.0, 0.1], [0.3, -1.0], [0.3, 0.1]], dtype=torch.float64)
    sim.step(pos, vel, act(NONE, NONE, NONE))
    torch.testing.assert_close(pos[0], torch.tensor([0.95, 0.5 + 0.1 * 0.02], dtype=torch.float64))
    torch.testing.assert_close(pos[1], torch.tensor([0.5 + 0.3 * 0.02, 0.05], dtype=torch.float64))
    torch.testing.assert_close(vel[:2], torch.zeros(2, 2, dtype=torch.float64))
    # the ball inside the square only got drag
    torch.testing.assert_close(vel[2], torch.tensor([0.3, 0.1], dtype=torch.float64) * DRAG)


@pytest.mark.parametrize("backend", BACKENDS)
def test_goal_stops_the_ball_at_entry(backend: str) -> None:
    sim = physics("ball 0.02\ntarget 0.545 0.5 0.04\nstart 0.5 0.5\n", backend)
    pos, vel = ball(0.504, 0.5, 0.199, 0.0)
    assert sim.step(pos, vel, act(PLUS_X)).item()
    # velocity 0.399, moves of 0.000399: the centre enters (x >= 0.505) at the 3rd substep
    torch.testing.assert_close(pos[0, 0].item(), 0.504 + 3 * 0.000399)
    torch.testing.assert_close(vel[0, 0].item(), 0.399)  # no drag once terminated


# -- the TorchRL environment --------------------------------------------------


def test_named_maps_load() -> None:
    simple, hard = PinBallConfig.load("simple"), PinBallConfig.load("hard")
    assert (simple.ball_radius, simple.target, simple.start) == (0.02, (0.9, 0.2, 0.04), (0.2, 0.9))
    assert (hard.ball_radius, hard.target, hard.start) == (0.015, (0.5, 0.06, 0.04), (0.055, 0.95))
    assert len(simple.polygons) == 4 + 6
    assert len(hard.polygons) == 4 + 14
    assert simple.polygons[4][0] == (0.35, 0.4)
    assert hard.polygons[-1][-1] == (0.456, 0.668)
    env = PinBallEnv(2, "hard")
    assert env.ball_radius == 0.015 and env.start == (0.055, 0.95)
    assert env.target == (0.5, 0.06, 0.04)
    assert len(env.obstacles) == 18 and env.obstacles[8].shape == (4, 2)


def test_reaching_the_target_terminates_with_goal_reward(tmp_path: Path) -> None:
    path = tmp_path / "near.cfg"
    path.write_text("ball 0.02\ntarget 0.545 0.5 0.04\nstart 0.5 0.5\n")
    env = PinBallEnv(2, path, random_action_prob=0.0, goal_reward=100.0, thrust_penalty=-5.0, step_penalty=-1.0)
    td = env.reset()
    td["action"] = act(PLUS_X, MINUS_X)
    td, td = env.step_and_maybe_reset(td)
    assert not td["done"].any()
    td["action"] = act(PLUS_X, NONE)
    step, td = env.step_and_maybe_reset(td)
    assert step["next", "terminated"].squeeze(1).tolist() == [True, False]
    assert step["next", "done"].squeeze(1).tolist() == [True, False]
    assert not step["next", "truncated"].any()
    assert step["next", "reward"].squeeze(1).tolist() == [100.0 - 5.0, -1.0]
    # the ball stopped where it entered the target, within the target circle
    x = step["next", "observation"][0, 0].item()
    assert x == pytest.approx(0.504 + 3 * 0.000399, abs=1e-6)
    # the next root observation is the reset one for the finished ball only
    torch.testing.assert_close(td["observation"][0], torch.tensor([0.5, 0.5, 0.0, 0.0]))
    torch.testing.assert_close(td["observation"][1], step["next", "observation"][1])


def test_truncation_after_max_steps() -> None:
    env = PinBallEnv(3, max_steps=4, random_action_prob=0.0)
    td = env.reset()
    for t in range(1, 5):
        td["action"] = act(NONE, NONE, NONE)
        step, td = env.step_and_maybe_reset(td)
        assert step["next", "truncated"].all() == (t == 4)
        assert not step["next", "terminated"].any()


def test_partial_reset_only_resets_flagged_balls() -> None:
    env = PinBallEnv(4, max_steps=5, random_action_prob=0.0)
    td = env.reset()
    for _ in range(3):
        td["action"] = act(PLUS_X, MINUS_Y, PLUS_Y, MINUS_X)
        td = env.step(td)["next"]
    before = td["observation"].clone()
    flags = torch.tensor([[True], [False], [True], [False]])
    td["_reset"] = flags
    td = env.reset(td)
    start = torch.tensor([0.2, 0.9, 0.0, 0.0])
    torch.testing.assert_close(td["observation"][0], start)
    torch.testing.assert_close(td["observation"][2], start)
    torch.testing.assert_close(td["observation"][[1, 3]], before[[1, 3]])
    # inside the env too: the reset balls stay at rest, the others fly on
    td["action"] = act(NONE, NONE, NONE, NONE)
    td = env.step(td)["next"]
    torch.testing.assert_close(td["observation"][[0, 2]], start.expand(2, 4))
    drift = before[[1, 3], :2] + before[[1, 3], 2:] * 0.02
    torch.testing.assert_close(td["observation"][[1, 3], :2], drift)
    # the step counters: balls 1 and 3 reach max_steps (5), 0 and 2 do not
    td["action"] = act(NONE, NONE, NONE, NONE)
    td = env.step(td)["next"]
    assert td["truncated"].squeeze(1).tolist() == [False, True, False, True]


def fixed_actions(steps: int, n: int, seed: int) -> list[torch.Tensor]:
    generator = torch.Generator().manual_seed(seed)
    return [torch.randint(5, (n,), generator=generator) for _ in range(steps)]


def observations(env: PinBallEnv, actions: list[torch.Tensor]) -> torch.Tensor:
    td = env.reset()
    seen = []
    for action in actions:
        td["action"] = action
        step, td = env.step_and_maybe_reset(td)
        seen.append(step["next", "observation"])
    return torch.stack(seen)


def test_same_seed_same_trajectory() -> None:
    actions = fixed_actions(150, 8, seed=0)
    first = observations(PinBallEnv(8, random_action_prob=0.5, seed=3), actions)
    second = observations(PinBallEnv(8, random_action_prob=0.5, seed=3), actions)
    other = observations(PinBallEnv(8, random_action_prob=0.5, seed=4), actions)
    assert torch.equal(first, second)
    assert not torch.equal(first, other)
    env = PinBallEnv(8, random_action_prob=0.5, seed=11)
    env.set_seed(3)
    assert torch.equal(observations(env, actions), first)


def test_random_action_probability() -> None:
    n, p = 20_000, 0.25
    env = PinBallEnv(n, random_action_prob=p, seed=0)
    td = env.reset()
    td["action"] = torch.full((n,), NONE)
    velocity = env.step(td)["next", "observation"][:, 2:]
    # from rest at the start, only a random thrust (p * 4/5) moves the ball, one axis each
    moved = {
        "+x": velocity[:, 0] > 0,
        "+y": velocity[:, 1] > 0,
        "-x": velocity[:, 0] < 0,
        "-y": velocity[:, 1] < 0,
    }
    expected = n * p / 5
    sd = math.sqrt(n * (p / 5) * (1 - p / 5))
    for name, mask in moved.items():
        assert abs(mask.sum().item() - expected) < 5 * sd, name
    total = sum(mask.sum().item() for mask in moved.values())
    assert abs(total - 4 * expected) < 5 * math.sqrt(n * 0.2 * 0.8)
    # and with the probability at zero nothing moves
    still = PinBallEnv(n, random_action_prob=0.0, seed=0)
    td = still.reset()
    td["action"] = torch.full((n,), NONE)
    assert (still.step(td)["next", "observation"][:, 2:] == 0).all()


def test_action_order_is_documented() -> None:
    assert ACTION_NAMES == ("+x", "+y", "-x", "-y", "none")
    env = PinBallEnv(5, random_action_prob=0.0)
    td = env.reset()
    td["action"] = torch.arange(5)
    velocity = env.step(td)["next", "observation"][:, 2:] / DRAG
    expected = torch.tensor([[0.2, 0], [0, 0.2], [-0.2, 0], [0, -0.2], [0, 0]])
    torch.testing.assert_close(velocity, expected)


def make_env() -> PinBallEnv:
    return PinBallEnv(3, seed=0)


def test_check_env_specs() -> None:
    env = PinBallEnv(4, "hard", seed=0)
    check_env_specs(env)
    assert env.batch_locked and env.batch_size == torch.Size([4])
    assert env.action_spec.shape == (4,) and env.action_spec.dtype == torch.int64
    assert env.observation_spec["observation"].shape == (4, 4)
    check_env_specs(SerialEnv(2, make_env))


@pytest.mark.slow
def test_check_env_specs_parallel() -> None:
    env = ParallelEnv(2, make_env)
    try:
        check_env_specs(env)
    finally:
        env.close()


@pytest.mark.parametrize(
    ("text", "line", "message"),
    [
        (HEADER + "polygn 0 0 1 0 1 1\n", 4, "unknown keyword 'polygn'"),
        (HEADER + "polygon 0.1 0.1 0.2 0.1 0.2\n", 4, "odd number of coordinates"),
        (HEADER + "polygon 0.1 0.1 0.2 0.1\n", 4, "at least 3 vertices"),
        (HEADER + "polygon 0.1 0.1 0.2 nan 0.2 0.2\n", 4, "non-finite"),
        (HEADER + "polygon 0.1 0.1 0.2 x 0.2 0.2\n", 4, "expects numbers"),
        (HEADER + "polygon 0.1 0.1 0.1 0.1 0.2 0.2\n", 4, "zero-length edge"),
        ("ball 0.02 0.03\n", 1, "'ball' expects 1 number(s), got 2"),
        ("ball -0.02\ntarget 0.9 0.9 0.04\nstart 0.5 0.5\n", 1, "radius must be positive"),
        (HEADER + "ball 0.01\n", 4, "second 'ball' line"),
        (HEADER + "polygon 0.45 0.45 0.55 0.45 0.5 0.55\n", 3, "ball at start"),
        (HEADER + "polygon 0.8 0.8 1.0 0.8 0.9 1.0\n", 2, "target centre"),
    ],
)
def test_config_errors_name_file_and_line(tmp_path: Path, text: str, line: int, message: str) -> None:
    path = tmp_path / "broken.cfg"
    path.write_text(text)
    with pytest.raises(ValueError, match=re.escape(f"{path}, line {line}: ")) as error:
        PinBallEnv(1, path)
    assert message in str(error.value)


@pytest.mark.parametrize("missing", ["ball", "target", "start"])
def test_config_missing_lines(tmp_path: Path, missing: str) -> None:
    path = tmp_path / "short.cfg"
    path.write_text("".join(f"{line}\n" for line in HEADER.splitlines() if missing not in line))
    with pytest.raises(ValueError, match=re.escape(f"{path}: no '{missing}' line")):
        PinBallEnv(1, path)


def test_unknown_config_name() -> None:
    with pytest.raises(ValueError, match="neither one of"):
        PinBallEnv(1, "medium")


# -- agreement with the scalar reference ----------------------------------------


@pytest.mark.parametrize("backend", BACKENDS)
@pytest.mark.parametrize("name", ["simple", "hard"])
def test_physics_matches_reference(name: str, backend: str) -> None:
    """Random free starts with random velocities, random actions, resets at the goal."""
    n, steps = 24, 150
    sim = PinBallPhysics(name, backend=backend)  # type: ignore[arg-type]
    env = PinBallEnv(1, name)
    generator = torch.Generator().manual_seed(7)
    pos = env.sample_free_positions(n, generator).double()
    vel = torch.rand(n, 2, generator=generator, dtype=torch.float64) * 4.0 - 2.0
    refs = [ReferencePinBall(PinBallConfig.load(name).source) for _ in range(n)]
    for ref, p, v in zip(refs, pos.tolist(), vel.tolist(), strict=True):
        ref.set_state(*p, *v)
    goals = 0
    for action in fixed_actions(steps, n, seed=1):
        reached = sim.step(pos, vel, action)
        expected = [ref.step(int(a)) for ref, a in zip(refs, action, strict=True)]
        assert reached.tolist() == expected
        state = torch.tensor([ref.state for ref in refs], dtype=torch.float64)
        torch.testing.assert_close(torch.cat([pos, vel], 1), state, rtol=0, atol=1e-9)
        for i in torch.nonzero(reached).flatten().tolist():
            refs[i].reset()
            pos[i], vel[i] = torch.tensor(refs[i].state, dtype=torch.float64).view(2, 2)
            goals += 1
    # the run exercised the rules being compared
    assert sum(ref.reflections for ref in refs) > 200
    assert sum(ref.reversals for ref in refs) > 0
    assert sum(ref.extra_moves for ref in refs) > 0
    if name == "simple":
        assert goals > 0


@pytest.mark.parametrize("name", ["simple", "hard"])
def test_env_matches_reference(name: str) -> None:
    """The TorchRL path from the start position, thousands of ball-steps."""
    n, steps = 4, 750
    env = PinBallEnv(n, name, random_action_prob=0.0)
    refs = [ReferencePinBall(PinBallConfig.load(name).source) for _ in range(n)]
    td = env.reset()
    for action in fixed_actions(steps, n, seed=2):
        td["action"] = action
        step, td = env.step_and_maybe_reset(td)
        expected = [ref.step(int(a)) for ref, a in zip(refs, action, strict=True)]
        state = torch.tensor([ref.state for ref in refs], dtype=torch.float32)
        torch.testing.assert_close(step["next", "observation"], state, rtol=0, atol=1e-5)
        assert step["next", "terminated"].squeeze(1).tolist() == expected
        for ref, done in zip(refs, expected, strict=True):
            if done:
                ref.reset()
    assert sum(ref.reflections for ref in refs) > 50


# -- map helpers ----------------------------------------------------------------


@pytest.mark.parametrize("name", ["simple", "hard"])
def test_sample_free_positions(name: str) -> None:
    env = PinBallEnv(1, name)
    points = env.sample_free_positions(400, torch.Generator().manual_seed(0))
    assert points.shape == (400, 2) and points.dtype == torch.float32
    again = env.sample_free_positions(400, torch.Generator().manual_seed(0))
    assert torch.equal(points, again)
    radius = env.target[2]
    obstacles = [Obstacle(list(polygon)) for polygon in env.config.polygons]
    for x, y in points.double().tolist():
        for obstacle in obstacles:
            for p, q in obstacle.edges():
                cx, cy = closest_point(p, q, x, y)
                assert math.hypot(x - cx, y - cy) >= radius - 1e-6
    # spread over the map, not stuck in one region
    assert points[:, 0].min() < 0.25 and points[:, 0].max() > 0.75
    assert points[:, 1].min() < 0.25 and points[:, 1].max() > 0.75


def test_sample_free_positions_avoid_polygon_interiors() -> None:
    # a large square obstacle: no point may fall inside it even far from its edges
    config = PinBallConfig.parse(
        "ball 0.01\ntarget 0.05 0.05 0.01\nstart 0.05 0.9\npolygon 0.1 0.1 0.9 0.1 0.9 0.8 0.1 0.8\n"
    )
    env = PinBallEnv(1, config)
    points = env.sample_free_positions(300, torch.Generator().manual_seed(1))
    inside = (points > 0.1).all(1) & (points[:, 0] < 0.9) & (points[:, 1] < 0.8)
    assert not inside.any()


def test_draw_map() -> None:
    matplotlib = pytest.importorskip("matplotlib")
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots()
    circles = {
        "participant 1": [(0.5877, 0.6486, 0.04), (0.6442, 0.3202, 0.04)],
        "participant 2": [(0.28, 0.2551, 0.04), (0.6878, 0.3122, 0.04)],
    }
    assert draw_map(ax, "simple", circles) is ax
    # 10 polygons, the target and 4 subgoal circles
    assert len(ax.patches) == 10 + 1 + 4
    labels = sorted(text.get_text() for text in ax.texts)
    assert labels == ["1", "1", "2", "2"]
    assert ax.get_ylim() == (1.0, 0.0)
    _, legend_labels = ax.get_legend_handles_labels()
    assert {"participant 1", "participant 2", "target", "start"} <= set(legend_labels)
    plt.close(fig)


def test_check_subgoal() -> None:
    from torchrl_subgoal.subgoals import Cell, Circle

    assert check_subgoal(Circle((0.5877, 0.6486), 0.04)) is None
    assert "off the table" in (check_subgoal(Circle((1.2, 0.5), 0.04)) or "")
    assert "dims [0, 1]" in (check_subgoal(Circle((0.5, 0.5, 0.0), 0.04)) or "")
    assert "radius must be positive" in (check_subgoal(Circle((0.5, 0.5), 0.0)) or "")
    assert "not cell" in (check_subgoal(Cell(1, 1)) or "")
