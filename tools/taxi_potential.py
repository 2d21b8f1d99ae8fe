"""The learned potential on Taxi against the optimal values: why the mean target pays the agent to wander.

Trains tabular Q-learners on Taxi (−1 per step, −10 per illegal pick-up or drop-off, +20 at
delivery; subgoals: the passenger in the taxi, then the taxi at the destination) with HRS under
the library's target (0.9-expectile, no update on a time-out inside ``z``) and under the paper's
mean target (time-outs bootstrapped), then prints, per abstract state ``z``:

* the optimal value ``V*(z)``: value iteration on Taxi's transition model (``γ``), averaged over
  the states in which the optimal policy enters ``z`` from gymnasium's start distribution;
* the learned ``V(z)`` (mean and s.d. over learners);
* the shaping a step inside ``z`` earns, ``(γ − 1)Φ(z)``, against the step cost of −1
  (``Φ = V`` here: every learned ``V(z_0)`` is negative, so ``"nonpositive"`` keeps ``Φ = V``);
* the success rate and steps of the last 50 episodes.

    python tools/taxi_potential.py                 # 10 learners per target, 400 episodes (a few minutes)
"""

from __future__ import annotations

import argparse
import sys

import numpy as np
import torch
from torchrl.envs import TransformedEnv

from torchrl_subgoal import (
    SubgoalPotentialTransform,
    SubgoalValueLoss,
    TabularPotential,
    ValueUpdate,
)
from torchrl_subgoal.envs.gym_batch import require_gymnasium
from torchrl_subgoal.envs.taxi import ENV_ID, STANDS, make_taxi, taxi_subgoals
from torchrl_subgoal.training import SuccessSignal
from torchrl_subgoal.training.qlearning import QLearningConfig, train_qlearning

TARGETS = {
    "library (0.9-expectile, no time-out update)": {},
    "paper's mean (time-outs bootstrapped)": {"expectile": 0.5, "bootstrap_truncated": True},
}


def optimal_values(gamma: float) -> tuple[float, float, float]:
    """``V*(z)`` for z = 0 (start), 1 (just picked up), 2 (at the destination with the passenger)."""
    env = require_gymnasium("Taxi").make(ENV_ID).unwrapped
    transitions, states, actions = env.P, env.observation_space.n, env.action_space.n
    v = np.zeros(states)
    for _ in range(2000):
        q = np.array(
            [
                [
                    sum(p * (r + gamma * v[s2] * (not done)) for p, s2, r, done in transitions[s][a])
                    for a in range(actions)
                ]
                for s in range(states)
            ]
        )
        new = q.max(1)
        if np.abs(new - v).max() < 1e-9:
            break
        v = new
    starts, picked, arrived = [], [], []
    for row in range(5):
        for col in range(5):
            for passenger in range(4):
                for destination in range(4):
                    if passenger == destination:
                        continue
                    starts.append(v[env.encode(row, col, passenger, destination)])
    for passenger in range(4):
        for destination in range(4):
            if passenger != destination:
                prow, pcol = STANDS[passenger].tolist()
                drow, dcol = STANDS[destination].tolist()
                picked.append(v[env.encode(prow, pcol, 4, destination)])
                arrived.append(v[env.encode(drow, dcol, 4, destination)])
    return float(np.mean(starts)), float(np.mean(picked)), float(np.mean(arrived))


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--learners", type=int, default=10)
    parser.add_argument("--episodes", type=int, default=400)
    parser.add_argument("--value-lr", type=float, default=0.25)
    parser.add_argument("--seed", type=int, default=0)
    opts = parser.parse_args(argv)
    torch.set_num_threads(1)
    gamma = 0.99
    optimal = optimal_values(gamma)
    print(
        f"Taxi, {opts.learners} tabular Q-learners over (s, z) per target, {opts.episodes} episodes, "
        f"gamma = {gamma}, alpha_v = {opts.value_lr}\n"
    )
    print(
        "| target | z | optimal V*(z) | learned V(z) | (gamma - 1) Phi(z) per step inside z | last 50: success, steps |"
    )
    print("|---|---|---|---|---|---|")
    for name, target in TARGETS.items():
        series = taxi_subgoals()
        potential = TabularPotential(series.num_abstract_states, (opts.learners,))
        loss = SubgoalValueLoss(potential, **target).make_value_estimator(gamma=gamma)  # type: ignore[arg-type]
        env = TransformedEnv(
            make_taxi(opts.learners),
            SubgoalPotentialTransform(series, potential, gamma=gamma, value_update=ValueUpdate(opts.value_lr, loss)),
        )
        records = train_qlearning(
            env,
            QLearningConfig(episodes=opts.episodes, lr=0.25, epsilon=0.1, gamma=gamma),
            seed=opts.seed,
            success=SuccessSignal(final_reward=20.0),  # the delivery's reward
        ).records
        table = potential.table.detach()
        level = table[:, :1].clamp(min=0.0)  # "nonpositive": Φ = V − max(V(z_0), 0)
        phi = table - level
        success = float(records.success[:, -50:].float().mean())
        steps = float(records.steps[:, -50:].float().mean())
        for z in range(3):
            last = f"{success:.2f}, {steps:.1f}" if z == 0 else ""
            print(
                f"| {name if z == 0 else ''} | {z} | {optimal[z]:.1f} | {float(table[:, z].mean()):.1f} "
                f"({float(table[:, z].std()):.1f}) | {float(((gamma - 1) * phi[:, z]).mean()):+.2f} | {last} |"
            )
    return 0


if __name__ == "__main__":
    sys.exit(main())
