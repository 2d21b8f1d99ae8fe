"""Pick and place: how often policies reach the subgoals and the goal of a learning's single-goal task.

For the goal seed of each learning (as ``recipes/pick_and_place.py`` draws it from ``--seed``
and the learning's index) prints where the gripper, the object and the goal are, then, over
``--episodes`` 50-step episodes per policy, the fraction of episodes that reach subgoal 1
(the gripper at the object: ``|obs[6:9]| ≤ 0.01`` per component), subgoal 2 (also the
fingers at 0.02 ± 0.01: grasped) and success (object within 0.05 of the goal) at any step,
success at the last step (the recipe's test), and the closest the gripper came to the object:

* ``scripted``: a hand-written controller (above the object, down, close, carry to the
  goal), which shows the task can be solved in this env;
* ``uniform random``: actions uniform in [−1, 1]^4;
* ``untrained + exploration``: a freshly initialised DDPG actor through the recipe's
  exploration (Gaussian s.d. 0.2, then a uniform action with probability 0.3), i.e. the
  first epoch's behaviour;
* with ``--checkpoints DIR`` (a results directory's ``checkpoints/<METHOD>``, learning
  ``k`` in ``0000k``): the trained actor, greedy (one episode: the env and the policy are
  deterministic) and with the exploration.

With ``--replay`` the same counts are read from the stored transitions of those checkpoints
(every step the learning collected), together with how often the object moved and the mean
stored reward of each epoch (the shaped reward for a shaped method: while no subgoal is
reached it is ``−1 − (1 − γ) Φ(z_0)``).

``--tasks SEEDS`` instead lists the tasks of sweep seeds ``0 .. SEEDS-1`` (learnings ``0 ..
--learnings-1``): the goal's height above the object's start (0: on the table, where pushing
reaches it), object to goal and gripper to object, to choose the seeds of a run.

Usage::

    python tools/pick_and_place_reach.py --episodes 60
    python tools/pick_and_place_reach.py --tasks 16      # which sweep seeds put both goals on the table
    python tools/pick_and_place_reach.py --checkpoints results/pick_and_place/checkpoints/HRS --replay
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch
from torchrl.data import Bounded

from torchrl_subgoal.envs import fetch
from torchrl_subgoal.training.ddpg_parts import DDPGAgent, DDPGConfig

Policy = Callable[[np.ndarray, np.ndarray, dict[str, Any]], np.ndarray]
MARGIN = fetch.SUBGOAL_MARGIN
SUCCESS_DISTANCE = 0.05


def goal_seed(seed: int, learning: int) -> int:
    """The recipe's goal seed of ``learning`` in a sweep of ``--seed seed``.

    Examples:
        >>> goal_seed(0, 0)
        2968811710
    """
    return int(np.random.SeedSequence([seed, learning]).generate_state(1)[0])


def subgoal_1(obs: np.ndarray) -> np.ndarray:
    """The gripper at the object (the participants' first box), per row of ``obs[..., 25]``.

    Examples:
        >>> obs = np.zeros((2, 25)); obs[1, 6] = 0.02
        >>> subgoal_1(obs).tolist()
        [True, False]
    """
    return np.all(np.abs(obs[..., 6:9]) <= MARGIN, axis=-1)


def subgoal_2(obs: np.ndarray) -> np.ndarray:
    """The object grasped (the participants' second box), per row of ``obs[..., 25]``.

    Examples:
        >>> obs = np.zeros((2, 25)); obs[:, 9:11] = 0.02; obs[1, 9] = 0.04
        >>> subgoal_2(obs).tolist()
        [True, False]
    """
    return subgoal_1(obs) & np.all(np.abs(obs[..., 9:11] - 0.02) <= MARGIN, axis=-1)


def scripted(obs: np.ndarray, goal: np.ndarray, state: dict[str, Any]) -> np.ndarray:
    """Above the object with the gripper open, down to it, close for 4 steps, carry it to the goal.

    Examples:
        >>> obs = np.zeros(25); obs[3:6] = [0.1, 0.0, 0.0]
        >>> scripted(obs, np.zeros(3), {}).tolist()  # towards 5 cm above the object, open
        [1.0, 0.0, 1.0, 1.0]
    """
    gripper, obj = obs[0:3], obs[3:6]
    if state.get("phase", 0) == 0:
        target, fingers = obj + np.array([0.0, 0.0, 0.05]), 1.0
        if np.linalg.norm(target - gripper) < 0.01:
            state["phase"] = 1
    if state.get("phase") == 1:
        target, fingers = obj, 1.0
        if np.linalg.norm(obj - gripper) < 0.008:
            state["phase"], state["closing"] = 2, 0
    if state.get("phase") == 2:
        target, fingers = obj, -1.0
        state["closing"] += 1
        if state["closing"] >= 4:
            state["phase"] = 3
    if state.get("phase") == 3:
        target, fingers = goal, -1.0
    # an action moves the gripper by up to 5 cm per step: 20 × the error reaches the target in one
    return np.clip(np.append(20.0 * (target - gripper), fingers), -1.0, 1.0)


def actor_policy(agent: DDPGAgent, explore: bool) -> Policy:
    """The agent's actor on the normalised observation, optionally through the recipe's exploration."""
    exploration = agent.policy.module[2]

    def act(obs: np.ndarray, goal: np.ndarray, state: dict[str, Any]) -> np.ndarray:
        with torch.no_grad():
            action = agent.actor.module(agent.norm(torch.as_tensor(obs, dtype=torch.float32)[None]))
            if explore:
                action = exploration(action)
        return action[0].numpy()

    return act


def run(name: str, act: Policy, seed: int, episodes: int) -> None:
    """Run ``episodes`` episodes of ``act`` and print the rates."""
    gymnasium = fetch.require_fetch()
    env = gymnasium.make(fetch.ENV_ID, goal_seed=seed)
    reached = np.zeros(4)
    closest, steps_1 = [], 0
    start = time.process_time()
    for _ in range(episodes):
        obs, _ = env.reset()
        goal = env.unwrapped.goal.copy()
        state: dict[str, Any] = {}
        seen = np.zeros(3, dtype=bool)
        nearest = np.inf
        for _ in range(fetch.MAX_EPISODE_STEPS):
            obs, _, _, _, info = env.step(act(obs, goal, state))
            success = bool(info["is_success"][0])
            seen |= [bool(subgoal_1(obs)), bool(subgoal_2(obs)), success]
            steps_1 += int(subgoal_1(obs))
            nearest = min(nearest, float(np.linalg.norm(obs[6:9])))
        reached += [*seen, success]
        closest.append(nearest)
    env.close()
    rate = reached / episodes
    print(
        f"  {name:32s} {episodes:4d} episodes: subgoal 1 {rate[0]:.3f} ({steps_1} steps), subgoal 2 "
        f"{rate[1]:.3f}, success any step {rate[2]:.3f}, last step {rate[3]:.3f}; closest gripper-object "
        f"median {np.median(closest):.3f} m, min {np.min(closest):.3f} m  [{time.process_time() - start:.0f} s CPU]",
        flush=True,
    )


def replay_counts(learning_dir: Path, goal: np.ndarray) -> None:
    """Subgoal, success and object-moved counts over every stored transition of one learning."""
    parts = sorted((learning_dir / "transitions").glob("*.pt"))
    counts = np.zeros(4, dtype=np.int64)
    total, closest, rewards = 0, [], []
    for part in parts:
        data = torch.load(part, weights_only=False)
        rewards.append(float(data["next", "reward"].mean()))
        obs = data["next", "observation"].numpy()
        start = data["observation"][0, 3:6].numpy()
        counts += [
            subgoal_1(obs).sum(),
            subgoal_2(obs).sum(),
            (np.linalg.norm(obs[:, 3:6] - goal, axis=-1) < SUCCESS_DISTANCE).sum(),
            (np.linalg.norm(obs[:, 3:6] - start, axis=-1) > 0.01).sum(),
        ]
        total += obs.shape[0]
        closest.append(float(np.linalg.norm(obs[:, 6:9], axis=-1).min()))
    print(
        f"  stored transitions ({len(parts)} epochs, {total} steps): subgoal 1 on {counts[0]} steps, "
        f"subgoal 2 on {counts[1]}, success on {counts[2]}, object moved > 1 cm on {counts[3]}; "
        f"closest gripper-object per epoch {np.round(closest, 3).tolist()} m; mean stored (shaped) reward per "
        f"epoch {np.round(rewards, 4).tolist()}",
        flush=True,
    )


def task(seed: int) -> tuple[np.ndarray, np.ndarray]:
    """The first observation and the goal of the task of goal seed ``seed``."""
    gymnasium = fetch.require_fetch()
    env = gymnasium.make(fetch.ENV_ID, goal_seed=seed)
    obs, _ = env.reset()
    goal = env.unwrapped.goal.copy()
    env.close()
    return obs, goal


def list_tasks(seeds: int, learnings: int) -> None:
    """One line per sweep seed: each learning's goal height, object-goal and gripper-object distances."""
    print(
        "sweep seed | "
        + " | ".join(f"learning {k}: goal height, object-goal, gripper-object (m)" for k in range(learnings))
    )
    for seed in range(seeds):
        cells = []
        for learning in range(learnings):
            obs, goal = task(goal_seed(seed, learning))
            height = goal[2] - obs[5]
            cells.append(
                f"{'table' if height < 0.005 else 'air  '} {height:.3f}, {np.linalg.norm(goal - obs[3:6]):.3f}, "
                f"{np.linalg.norm(obs[6:9]):.3f}"
            )
        print(f"{seed:10d} | " + " | ".join(cells), flush=True)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--seed", type=int, default=0, help="the sweep's --seed (goal seeds)")
    parser.add_argument("--learnings", type=int, default=2, help="learnings 0 .. N-1")
    parser.add_argument("--episodes", type=int, default=60, help="episodes per random policy")
    parser.add_argument(
        "--checkpoints",
        type=Path,
        default=None,
        help="checkpoints/<METHOD> of a results directory: also the trained actors",
    )
    parser.add_argument("--replay", action="store_true", help="also count over the stored transitions")
    parser.add_argument(
        "--tasks", type=int, default=0, metavar="SEEDS", help="only list the tasks of sweep seeds 0 .. SEEDS-1"
    )
    args = parser.parse_args(argv)
    if args.tasks < 0 or args.learnings < 1:
        parser.error(f"--tasks: >= 0 (got {args.tasks}); --learnings: >= 1 (got {args.learnings})")
    if args.tasks:
        list_tasks(args.tasks, args.learnings)
        return 0
    fetch.require_fetch()
    torch.set_num_threads(1)
    torch.manual_seed(args.seed)
    rng = np.random.default_rng(args.seed)
    spec = Bounded(-1.0, 1.0, shape=(4,))
    for learning in range(args.learnings):
        seed = goal_seed(args.seed, learning)
        obs, goal = task(seed)
        gripper, obj = (np.round(obs[part].astype(np.float64), 3).tolist() for part in (slice(0, 3), slice(3, 6)))
        print(
            f"learning {learning} (goal seed {seed}): gripper {gripper}, object {obj}, goal "
            f"{np.round(goal, 3).tolist()} ({goal[2] - obs[5]:.3f} m above the "
            f"object's start, {np.linalg.norm(goal - obs[3:6]):.3f} m from it; gripper-object "
            f"{np.linalg.norm(obs[6:9]):.3f} m)",
            flush=True,
        )
        run("scripted", scripted, seed, 3)
        run("uniform random", lambda o, g, s: rng.uniform(-1.0, 1.0, 4), seed, args.episodes)
        run("untrained actor + exploration", actor_policy(DDPGAgent(25, spec, DDPGConfig()), True), seed, args.episodes)
        if args.checkpoints is not None:
            learning_dir = args.checkpoints / f"{learning:05d}"
            stored = args.checkpoints.parent.parent / "config.json"  # RESULTS/config.json: the networks' sizes
            hidden = json.loads(stored.read_text())["config"]["ddpg"]["hidden"] if stored.exists() else (256,) * 3
            trained = DDPGAgent(25, spec, DDPGConfig(hidden=tuple(hidden)))
            trained.load_training_state(torch.load(learning_dir / "state.pt", weights_only=False)["agent"])
            run("trained actor, greedy", actor_policy(trained, False), seed, 1)
            run("trained actor + exploration", actor_policy(trained, True), seed, args.episodes)
            if args.replay:
                replay_counts(learning_dir, goal)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
