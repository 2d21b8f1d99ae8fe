"""Batched four-rooms: env-steps per second with and without the shaping transform, and the two engines.

Part 1 steps ``FourRoomsEnv(num_envs=N)`` with uniformly random actions through
``step_and_maybe_reset`` (resets included) in four set-ups, interleaved and
repeated (the machine is shared, so ratios are taken within one run):

* ``bare``: the env alone;
* ``wrapper``: ``TransformedEnv(env, Compose())`` — what TorchRL's transform machinery
  costs before any transform does anything;
* ``shaping``: ``TransformedEnv(env, SubgoalPotentialTransform(...))`` as the recipe
  uses it (ten participants' patterns, tabular potential trained online);
* ``shaping+transitions``: the same writing the SMDP transitions into the TensorDict;
* ``keys-only``: a transform that does no work but writes the same entries
  (``subgoal_*`` zeros, ``env_reward``, ``reward``) — the floor that TorchRL's
  per-key bookkeeping (``step_mdp``, partial-reset merging) sets for any transform
  that keeps its state in the TensorDict.

Part 2 trains SARSA with HRS for a few episodes with ``engine="torchrl"`` and
``engine="fused"`` (identical results) and prints learner-steps per second.

    python benchmarks/four_rooms_step.py             # N = 1000
    python benchmarks/four_rooms_step.py --quick
"""

from __future__ import annotations

import argparse
import statistics
import time
from importlib.resources import files
from typing import ClassVar, Literal

import torch
from tensordict import TensorDictBase
from torchrl.data import Composite, TensorSpec, Unbounded
from torchrl.envs import Compose, EnvBase, Transform, TransformedEnv

from torchrl_subgoal import SubgoalPotentialTransform, TabularPotential, load_patterns
from torchrl_subgoal.envs import FourRoomsEnv
from torchrl_subgoal.fused import SARSA_PRESETS, SoftmaxSarsa, run_episodes
from torchrl_subgoal.potentials import INDEX
from torchrl_subgoal.transform import RETURN, STEPS, SubgoalKeys

PATTERNS = list(
    load_patterns(str(files("torchrl_subgoal") / "domains" / "four_rooms" / "four_rooms_participants.yaml")).values()
)


def shaping(n: int, write: bool) -> SubgoalPotentialTransform:
    return SubgoalPotentialTransform(
        [PATTERNS[i % len(PATTERNS)] for i in range(n)],
        TabularPotential(3, (n,)),
        gamma=0.99,
        observation_key="cell",
        value_update=0.25,
        keys=SubgoalKeys(transitions="smdp" if write else None),
    )


class KeysOnly(Transform):
    """Writes the entries the shaping transform writes, without computing anything.

    ``observations`` keeps only the first that many of its three carried entries
    (``subgoal_index``, ``subgoal_return``, ``subgoal_steps``): what a smaller entry
    format would cost TorchRL's per-entry bookkeeping (``env_reward`` and the shaped
    ``reward`` are always written).
    """

    DTYPES: ClassVar[dict[str, torch.dtype]] = {INDEX: torch.long, RETURN: torch.float32, STEPS: torch.long}

    def __init__(self, observations: int = 3) -> None:
        super().__init__()
        self.dtypes = dict(list(self.DTYPES.items())[:observations])

    def transform_observation_spec(self, observation_spec: TensorSpec) -> TensorSpec:
        assert isinstance(observation_spec, Composite)
        for key, dtype in self.dtypes.items():
            observation_spec[key] = Unbounded(shape=(*observation_spec.shape, 1), dtype=dtype)
        return observation_spec

    def transform_reward_spec(self, reward_spec: TensorSpec) -> TensorSpec:
        assert isinstance(reward_spec, Composite)
        reward_spec["env_reward"] = reward_spec["reward"].clone()
        return reward_spec

    def _zeros(self, batch_shape: torch.Size) -> dict[str, torch.Tensor]:
        return {key: torch.zeros((*batch_shape, 1), dtype=dtype) for key, dtype in self.dtypes.items()}

    def _step(self, tensordict: TensorDictBase, next_tensordict: TensorDictBase) -> TensorDictBase:
        reward = next_tensordict.get("reward")
        next_tensordict.update(
            {**self._zeros(next_tensordict.batch_size), "env_reward": reward, "reward": reward.clone()}
        )
        return next_tensordict

    def _reset(self, tensordict: TensorDictBase, tensordict_reset: TensorDictBase) -> TensorDictBase:
        if self.dtypes:
            tensordict_reset.update(self._zeros(tensordict_reset.batch_size))
        return tensordict_reset


def setups(n: int) -> dict[str, EnvBase]:
    return {
        "bare": FourRoomsEnv(n),
        "wrapper": TransformedEnv(FourRoomsEnv(n), Compose()),
        "shaping": TransformedEnv(FourRoomsEnv(n), shaping(n, False)),
        "shaping+transitions": TransformedEnv(FourRoomsEnv(n), shaping(n, True)),
        "keys-only": TransformedEnv(FourRoomsEnv(n), KeysOnly()),
    }


def time_steps(env: EnvBase, actions: torch.Tensor) -> float:
    """Seconds per batched step over ``actions`` (one row per step)."""
    td = env.reset()
    start = time.perf_counter()
    for row in actions:
        td["action"] = row
        _, td = env.step_and_maybe_reset(td)
    return (time.perf_counter() - start) / len(actions)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--num-envs", type=int, default=1000)
    parser.add_argument("--steps", type=int, default=1500)
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--episodes", type=int, default=30, help="episodes per learner in part 2")
    parser.add_argument("--quick", action="store_true")
    args = parser.parse_args()
    if args.quick:
        args.steps, args.repeats, args.episodes = 300, 2, 5
    torch.set_num_threads(1)
    n = args.num_envs
    envs = setups(n)
    actions = torch.randint(0, 4, (args.steps, n), generator=torch.Generator().manual_seed(0))
    for env in envs.values():  # warm up: kernels compiled, tables built
        time_steps(env, actions[:50])
    times: dict[str, list[float]] = {name: [] for name in envs}
    for _ in range(args.repeats):
        for name, env in envs.items():
            times[name].append(time_steps(env, actions))
    best = {name: min(t) for name, t in times.items()}
    print(f"Part 1: FourRoomsEnv, N = {n} learners, {args.steps} random-action steps x {args.repeats} repeats")
    print(f"{'set-up':<22}{'us/step (best)':>16}{'median':>10}{'env-steps/s':>14}")
    for name, t in times.items():
        print(f"{name:<22}{best[name] * 1e6:>16.0f}{statistics.median(t) * 1e6:>10.0f}{n / best[name]:>14,.0f}")
    for name in ("keys-only", "shaping", "shaping+transitions"):
        print(
            f"{name}: +{best[name] / best['wrapper'] - 1:.0%} over the wrapper alone, "
            f"+{best[name] / best['bare'] - 1:.0%} over the bare env"
        )

    print(f"\nPart 2: SARSA + HRS, {args.episodes} episodes per learner, N = {n}")
    rates = {}
    engines: tuple[Literal["torchrl", "fused"], ...] = ("torchrl", "fused")
    for engine in engines:  # warm up: numba compiles (or loads) the kernels once
        run_episodes(
            TransformedEnv(FourRoomsEnv(4, max_steps=20), shaping(4, False)),
            SoftmaxSarsa(4, 104, 4, SARSA_PRESETS["released"]),
            1,
            engine=engine,
        )
    for engine in engines:
        env = TransformedEnv(FourRoomsEnv(n), shaping(n, False))
        agent = SoftmaxSarsa(n, 104, 4, SARSA_PRESETS["released"], seed=0)
        start = time.perf_counter()
        records = run_episodes(env, agent, args.episodes, engine=engine)
        seconds = time.perf_counter() - start
        rates[engine] = records.env_steps * n / seconds
        print(
            f"{engine:<8} {seconds:6.1f} s, {records.env_steps} batched steps, "
            f"{rates[engine]:,.0f} learner-steps/s, mean episode {records.steps.float().mean():.0f} steps"
        )
    print(f"fused / torchrl: {rates['fused'] / rates['torchrl']:.1f}x")


if __name__ == "__main__":
    main()
