"""Tutorial: add a domain (a 1-D corridor) and shape SARSA on it from a subgoal file.

A domain is one :func:`torchrl_subgoal.domains.register` call: an env factory,
the check a subgoal file's subgoals must pass, and the parts other layers read
(here the report's map: a :class:`~torchrl_subgoal.experiments.plots.ReportMap`).
With that, a subgoal file that says ``domain: corridor`` is checked against the
corridor, the method runs on it like on four-rooms, and the report draws its map.

    python docs/tutorials/adding_a_domain.py            # the budget of the docs' figure
    python docs/tutorials/adding_a_domain.py --tiny     # seconds: what CI runs

It writes ``adding_a_domain.png`` and ``adding_a_domain.txt`` into ``--out``
(default ``docs/tutorials/output``). ``TUTORIAL_TINY=1`` is the same as ``--tiny``.
"""

from __future__ import annotations

import argparse
import os
from collections.abc import Mapping
from pathlib import Path
from typing import Any, NamedTuple

import numpy as np
import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.data import Categorical, Composite, Unbounded
from torchrl.envs import EnvBase, TransformedEnv

from torchrl_subgoal import State, domains, load_patterns
from torchrl_subgoal.experiments.plots import ReportMap, plot_pattern_maps
from torchrl_subgoal.fused import SARSA_PRESETS, SoftmaxSarsa, engine, run_episodes
from torchrl_subgoal.methods import paper_methods, shaping_transform
from torchrl_subgoal.subgoals import Predicate


# --8<-- [start:env]
class CorridorEnv(EnvBase):
    """A corridor of cells 0..length, batched: start at 0, action 1 moves right, 0 left;
    reward 1 on reaching ``length`` (terminated), else 0; truncated after ``max_steps``."""

    def __init__(self, num_envs: int = 1, length: int = 12, max_steps: int = 500):
        super().__init__(batch_size=torch.Size([num_envs]))
        self.length, self.max_steps = length, max_steps
        self.observation_spec = Composite(
            observation=Categorical(length + 1, shape=(num_envs,), dtype=torch.long), shape=(num_envs,)
        )
        self.action_spec = Categorical(2, shape=(num_envs,), dtype=torch.long)
        self.reward_spec = Unbounded(shape=(num_envs, 1))
        self.position = torch.zeros(num_envs, dtype=torch.long)
        self.t = torch.zeros(num_envs, dtype=torch.long)

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs: Any) -> TensorDictBase:
        reset = tensordict.get("_reset", None) if tensordict is not None else None
        fresh = reset.reshape(-1) if reset is not None else torch.ones_like(self.position, dtype=torch.bool)
        self.position.masked_fill_(fresh, 0)
        self.t.masked_fill_(fresh, 0)
        false = torch.zeros(*self.batch_size, 1, dtype=torch.bool)
        return TensorDict(
            {
                "observation": self.position.clone(),
                "done": false,
                "terminated": false.clone(),
                "truncated": false.clone(),
            },
            self.batch_size,
        )

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        self.position = (self.position + tensordict["action"] * 2 - 1).clamp(0, self.length)
        self.t += 1
        terminated = (self.position == self.length).unsqueeze(-1)
        truncated = (self.t >= self.max_steps).unsqueeze(-1) & ~terminated
        return TensorDict(
            {
                "observation": self.position.clone(),
                "reward": terminated.float(),
                "done": terminated | truncated,
                "terminated": terminated,
                "truncated": truncated,
            },
            self.batch_size,
        )

    def _set_seed(self, seed: int | None) -> None:
        pass

    def kernel_state(self, observation_key: str = "observation") -> CorridorKernelState:
        """The corridor as the fused engine reads it, the shaping reading ``observation_key`` (optional; see
        "The fused engine" below)."""
        if observation_key != "observation":
            raise TypeError(f"the corridor's compiled steps read 'observation', not {observation_key!r}")
        return CorridorKernelState(self.position.numpy(), self.t.numpy(), self.length, self.max_steps)


# --8<-- [end:env]


# --8<-- [start:register]
LENGTH = 12


def check_subgoal(predicate: Predicate) -> str | None:
    """Why ``predicate`` is not a corridor subgoal (``None``: it is one): a cell short of the goal."""
    if not isinstance(predicate, State):
        return f"corridor subgoals are states (cells 0 to {LENGTH - 1}), not {predicate.kind}"
    if not 0 <= predicate.state < LENGTH:
        return f"state {predicate.state} is not a cell short of the goal (0 to {LENGTH - 1})"
    return None


def draw_map(ax: Any, patterns: Mapping[str, Any], options: Mapping[str, Any]) -> None:
    """The corridor as a row of cells; each pattern's subgoals numbered in order."""
    ax.set_xlim(-0.5, LENGTH + 0.5)
    ax.set_ylim(-1, 1)
    ax.scatter(range(LENGTH + 1), [0] * (LENGTH + 1), marker="s", color="lightgrey")
    ax.scatter([LENGTH], [0], marker="s", color="tab:red")  # the goal
    for series in patterns.values():
        for i, predicate in enumerate(series.predicates, start=1):
            ax.annotate(str(i), (predicate.state, 0), ha="center", va="center")


domains.register(
    domains.Domain(
        "corridor",
        "Corridor",
        make_env=CorridorEnv,
        check_subgoal=check_subgoal,
        parts=(ReportMap(draw_map),),
    )
)
# --8<-- [end:register]


# --8<-- [start:fused]
class CorridorKernelState(NamedTuple):
    """The corridor for compiled loops: numpy views of its tensors (updated in place) and its settings."""

    position: np.ndarray  # [N] cell of every learner
    t: np.ndarray  # [N] steps into the episode
    length: int
    max_steps: int


@engine.implements(engine.env_scratch, CorridorKernelState)
def _scratch(env: CorridorKernelState) -> np.ndarray:
    return np.empty(1, np.int64)  # the observation the shaping reads: [cell]


@engine.implements(engine.env_observe, CorridorKernelState)
def _observe(env: CorridorKernelState, b: int, scratch: np.ndarray) -> int:
    return env.position[b]  # SoftmaxSarsa's learner step reads the cell number


@engine.implements(engine.env_step, CorridorKernelState)
def _step(env: CorridorKernelState, b: int, a: int, scratch: np.ndarray) -> tuple[int, np.float32, bool, bool]:
    cell = min(max(env.position[b] + 2 * a - 1, 0), env.length)
    env.position[b] = cell
    env.t[b] += 1
    terminated = cell == env.length
    return cell, np.float32(1.0 if terminated else 0.0), terminated, terminated or env.t[b] >= env.max_steps


@engine.implements(engine.env_reset, CorridorKernelState)
def _reset(env: CorridorKernelState, b: int, scratch: np.ndarray) -> int:
    env.position[b] = 0
    env.t[b] = 0
    return env.position[b]


@engine.implements(engine.env_shaping_observation, CorridorKernelState)
def _shaping_observation(env: CorridorKernelState, cell: int, scratch: np.ndarray) -> np.ndarray:
    scratch[0] = cell
    return scratch


# --8<-- [end:fused]


# --8<-- [start:file]
SUBGOAL_FILE = """\
format: torchrl_subgoal/v1
domain: corridor
patterns:
  thirds:
    subgoals:
      - state: 4
      - state: 8
"""
# --8<-- [end:file]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--tiny", action="store_true", help="a few seconds' budget (what CI runs)")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "output")
    args = parser.parse_args()
    learners, episodes = (8, 20) if args.tiny or os.environ.get("TUTORIAL_TINY") else (100, 50)
    args.out.mkdir(parents=True, exist_ok=True)

    # --8<-- [start:train]
    path = args.out / "corridor.yaml"
    path.write_text(SUBGOAL_FILE)
    patterns = list(load_patterns(path).values())  # checked by the corridor's check_subgoal
    sarsa = SARSA_PRESETS["released"]
    lines = []
    for name, method in paper_methods("SARSA").items():
        if name not in ("SARSA", "HRS"):
            continue
        env = domains.get("corridor").make_env(learners)  # type: ignore[misc]
        shaping = shaping_transform(
            method,
            env.batch_size,
            gamma=sarsa.gamma,
            value_lr=sarsa.value_lr,
            patterns=patterns,
            pattern_index=torch.zeros(learners, dtype=torch.long),
        )
        learning_env = TransformedEnv(env, shaping) if shaping is not None else env
        agent = SoftmaxSarsa(learners, LENGTH + 1, 2, sarsa, seed=0)
        steps = run_episodes(learning_env, agent, episodes).steps.double()
        lines.append(
            f"{name}: mean steps per episode {steps.mean():.1f} over {episodes} episodes of "
            f"{learners} learners; last episode {steps[:, -1].mean():.1f}"
        )
    # --8<-- [end:train]
    figure = plot_pattern_maps("corridor", {p.name: p.to_dict() for p in patterns}, args.out / "adding_a_domain.png")
    assert figure.path is not None, figure.note
    text = "\n".join(lines)
    print(text)
    (args.out / "adding_a_domain.txt").write_text(text + "\n")


if __name__ == "__main__":
    main()
