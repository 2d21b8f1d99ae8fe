"""Four-rooms: what the shaping conventions leave in SARSA's Q table after learning.

Trains HRS learners (the paper's SARSA, Q over the cell only, released
preset) under each convention of the shaping transform, then inspects every
learner's table along its greedy walk from the start: the best value
``max_a Q(s)``, the action gap ``max_a Q(s) − second_a Q(s)`` (how decidedly a
τ = 0.01 softmax picks its best action), and whether the walk reaches the goal
in 20 steps or revisits a cell.
The numbers explain the asymptotes in docs/four_rooms.md.

    python recipes/four_rooms_greedy.py                      # 50 learners, 1,000 episodes, about a minute
    python recipes/four_rooms_greedy.py --reward step-cost
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from importlib.resources import files

import torch
from torchrl.envs import TransformedEnv

from torchrl_subgoal import load_patterns
from torchrl_subgoal.envs import FourRoomsEnv
from torchrl_subgoal.experiments.cli import check, setting
from torchrl_subgoal.experiments.recipe import config_main
from torchrl_subgoal.fused import SARSA_PRESETS, SoftmaxSarsa, run_episodes
from torchrl_subgoal.methods import paper_methods, shaping_transform

PARTICIPANTS = str(files("torchrl_subgoal") / "domains" / "four_rooms" / "four_rooms_participants.yaml")
CONVENTIONS = {  # name: (zero_terminal_potential, start_potential)
    "old default (Φ_T = 0, Φ = V)": (True, "value"),
    "authors (Φ_T = V(z_T), Φ = V)": (False, "value"),
    "library default (Φ_T = 0, nonpositive)": (True, "nonpositive"),
}


@dataclass
class Config:
    """Action gaps and greedy walks of HRS learners under each shaping convention."""

    learnings: int = setting(5, "learnings per participant's series (10 series)")
    episodes: int = setting(1000, "episodes per learning")
    reward: str = setting(
        "goal", "goal: +1 at the goal; step-cost: -1 per step, 0 at the goal", choices=["goal", "step-cost"]
    )
    seed: int = setting(0, "seed of the learners' draws")

    def __post_init__(self) -> None:
        check(self.learnings >= 1, "learnings", f"must be >= 1, got {self.learnings}")
        check(self.episodes >= 1, "episodes", f"must be >= 1, got {self.episodes}")


def greedy_walks(agent: SoftmaxSarsa, env: FourRoomsEnv, limit: int = 100) -> tuple[torch.Tensor, ...]:
    """Each learner's greedy walk from the start: its steps (``limit`` if it never arrives), whether it
    revisits a cell, and which cells it visits (``[n, S]``). Q is over the cell only: no abstract state."""
    n = agent.q.shape[0]
    state = torch.full((n,), env.start_state)
    steps = torch.full((n,), limit)
    seen = torch.zeros(n, env.num_states, dtype=torch.bool)
    revisits = torch.zeros(n, dtype=torch.bool)
    rows = torch.arange(n)
    for t in range(limit):
        walking = steps == limit
        revisits |= seen[rows, state] & walking
        seen[rows, state] |= walking
        state = env.transitions[state, agent.greedy(state)]
        steps = torch.where((state == env.goal_state) & walking, t + 1, steps)
    return steps, revisits, seen


def run(cfg: Config) -> int:
    """Train the learners of each convention and print one row of the table per convention."""
    patterns = list(load_patterns(PARTICIPANTS, domain="four_rooms").values())
    n = cfg.learnings * len(patterns)
    sarsa = SARSA_PRESETS["released"]
    goal_reward, step_reward = (1.0, 0.0) if cfg.reward == "goal" else (0.0, -1.0)
    print(
        f"| convention ({cfg.reward}, {n} HRS learners) | last 10 episodes | on the greedy walks: median "
        "max Q(s) | median gap | gap < τ | greedy walk of 20 steps | greedy walk revisits a cell |"
    )
    print("|---|---|---|---|---|---|---|")
    for name, (zero_terminal, start) in CONVENTIONS.items():
        env = FourRoomsEnv(n, goal_reward=goal_reward, step_reward=step_reward)
        shaping = shaping_transform(
            paper_methods("SARSA")["HRS"],
            env.batch_size,
            gamma=sarsa.gamma,
            value_lr=sarsa.value_lr,
            patterns=patterns,
            pattern_index=torch.arange(n) % len(patterns),
            observation_key="cell",
            zero_terminal_potential=zero_terminal,
            start_potential=start,
            expectile=0.5,
            bootstrap_truncated=True,  # the paper's mean target: the conventions alone differ
        )
        agent = SoftmaxSarsa(n, env.num_states, 4, sarsa, seed=cfg.seed)
        records = run_episodes(TransformedEnv(env, shaping), agent, cfg.episodes, engine="fused")
        steps, revisits, on_walk = greedy_walks(agent, env)
        top2 = agent.q.topk(2, dim=-1).values[on_walk]  # [cells on the walks, 2]
        gap = top2[:, 0] - top2[:, 1]
        print(
            f"| {name} | {records.steps[:, -10:].double().mean():.2f} | {top2[:, 0].median():.3f} | "
            f"{gap.median():.3f} | {(gap < sarsa.temperature).double().mean():.0%} | "
            f"{int((steps == 20).sum())} of {n} | {int(revisits.sum())} of {n} |"
        )
    return 0


def main(argv: list[str] | None = None) -> int:
    return config_main(Config, run, argv, description=__doc__.splitlines()[0] if __doc__ else None)


if __name__ == "__main__":
    sys.exit(main())
