"""TorchRL collection with subgoal shaping: collector frames per second, and the transform's cost in A2C.

Part 1, collector throughput (four-rooms, random policy, 16 envs): frames per
second of the bare batched env stepped with ``step_and_maybe_reset``, of a
``Collector`` over that batched env, and of a ``Collector`` over a
``ParallelEnv`` of 1 and 2 env workers (8 + 8 envs with 2).

Part 2, the shaping transform's cost inside an A2C iteration at the recipe's
settings (``recipes/a2c.py --domain four_rooms``: 16 envs, 256 frames per
batch, one-hot policy): the time of one iteration — collect a batch, GAE, one
A2C step, and for HRS one step of the potential on the batch's SMDP
transitions — with and without the transform (the HRS potential trained
centrally, as the recipe does, and online). Every set-up collects with the
same policy (briefly trained, then kept with learning rate 0): a policy that
learns at a different speed would end episodes, and so reset envs, at a
different rate, which changes a step's cost more than the transform does.
Set-ups are interleaved and repeated; the best repeat of each is compared
(the machine is shared).

    python benchmarks/a2c_collection.py            # the figures in docs/torchrl.md
    python benchmarks/a2c_collection.py --quick
"""

from __future__ import annotations

import argparse
import copy
import functools
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path

import torch
from tensordict import TensorDictBase
from tensordict.nn import TensorDictModuleBase
from torchrl.collectors import Collector
from torchrl.envs import EnvBase, ParallelEnv
from torchrl.objectives import A2CLoss
from torchrl.objectives.value import GAE

from torchrl_subgoal import Cell, SubgoalSeries, SubgoalValueLoss, TabularPotential
from torchrl_subgoal.envs import FourRoomsEnv
from torchrl_subgoal.training import A2CConfig, Shaping, actor_critic, shaped_env, smdp_transitions
from torchrl_subgoal.training.domains import a2c_domain, four_rooms_env

HALLWAYS = SubgoalSeries([Cell(3, 6), Cell(7, 9)])


def best_rate(make_steps: dict[str, Callable[[], int]], repeats: int) -> dict[str, float]:
    """Interleave the set-ups ``repeats`` times; each call returns the frames it did: best frames/s."""
    best = dict.fromkeys(make_steps, 0.0)
    for _ in range(repeats):
        for name, run in make_steps.items():
            start = time.perf_counter()
            frames = run()
            best[name] = max(best[name], frames / (time.perf_counter() - start))
    return best


def bare_env_steps(env: EnvBase, steps: int) -> Callable[[], int]:
    td = env.reset()

    def run() -> int:
        nonlocal td
        for _ in range(steps):
            td["action"] = env.action_spec.rand()
            _, td = env.step_and_maybe_reset(td)
        return steps * env.batch_size.numel()

    return run


def collector_batches(collector: Collector, batches: int) -> Callable[[], int]:
    iterator: Iterator[TensorDictBase] = iter(collector)

    def run() -> int:
        return sum(next(iterator).numel() for _ in range(batches))

    return run


def a2c_iterations(
    shaping: Shaping | None, config: A2CConfig, batches: int, online: bool,
    networks: tuple[TensorDictModuleBase, TensorDictModuleBase] | None = None, lr: float | None = None,
    keys_only: bool = False,
) -> tuple[Callable[[], int], tuple[TensorDictModuleBase, TensorDictModuleBase]]:
    """One A2C learner as ``train_a2c`` runs it, ``batches`` iterations per call (and its networks).

    With ``networks`` the learner starts from copies of them; ``lr=0`` keeps the policy as it is
    (every set-up then collects with the same policy, so episodes end as often in each).
    ``keys_only`` appends a transform that writes the shaping transform's entries without
    computing them: what TorchRL's per-entry bookkeeping costs any such transform.
    """
    env = shaped_env(four_rooms_env, config.num_envs, shaping=shaping, gamma=config.gamma,
                     value_lr=config.value_lr if online else None)
    if keys_only:
        sys.path.insert(0, str(Path(__file__).resolve().parent))
        from four_rooms_step import KeysOnly

        env.transform.insert(1, KeysOnly())
    actor, critic = (copy.deepcopy(networks[0]), copy.deepcopy(networks[1])) if networks else actor_critic(
        env, features=config.features, hidden=config.hidden)
    advantage = GAE(gamma=config.gamma, lmbda=config.gae_lambda, value_network=critic)
    loss = A2CLoss(actor, critic, entropy_coeff=config.entropy_coeff, critic_coeff=config.critic_coeff,
                   loss_critic_type="l2")
    optimizer = torch.optim.Adam(loss.parameters(), lr=config.lr if lr is None else lr)
    keeper, value_loss, value_optimizer = None, None, None
    if shaping is not None and not online:
        keeper = shaping.transform(shaping.potential, config.gamma, None)
        value_loss = SubgoalValueLoss(shaping.potential, gamma=config.gamma, reduction="mean")
        value_optimizer = torch.optim.Adam(shaping.potential.parameters(), lr=config.value_lr)
    collector = Collector(env, actor, frames_per_batch=config.frames_per_batch, total_frames=-1,
                          auto_register_policy_transforms=False)
    iterator = iter(collector)

    def run() -> int:
        frames = 0
        for _ in range(batches):
            data = next(iterator)
            frames += data.numel()
            with torch.no_grad():
                advantage(data)
            losses = loss(data)
            optimizer.zero_grad()
            (losses["loss_objective"] + losses["loss_critic"] + losses["loss_entropy"]).backward()
            optimizer.step()
            if value_loss is not None and value_optimizer is not None:
                real = smdp_transitions(data, keeper)
                if real.numel():
                    value_optimizer.zero_grad()
                    value_loss(real)["loss_value"].backward()
                    value_optimizer.step()
        return frames

    return run, (actor, critic)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--quick", action="store_true", help="fewer repeats")
    parser.add_argument("--part", choices=["1", "2", "both"], default="both", help="which part to run")
    args = parser.parse_args()
    torch.set_num_threads(1)
    repeats, batches = (3, 10) if args.quick else (7, 30)
    config = a2c_domain("four_rooms").a2c

    if args.part != "2":
        collector_throughput(repeats, batches)
    if args.part != "1":
        transform_cost(config, repeats, batches)


def collector_throughput(repeats: int, batches: int) -> None:
    """Part 1."""
    print("Part 1: collector frames per second (four-rooms, 16 envs, random policy, 256 frames per batch)")
    envs: dict[str, EnvBase] = {
        "Collector, batched env": FourRoomsEnv(16),
        "Collector, ParallelEnv 1 worker": ParallelEnv(1, functools.partial(FourRoomsEnv, 16), mp_start_method="spawn"),
        "Collector, ParallelEnv 2 workers": ParallelEnv(2, functools.partial(FourRoomsEnv, 8), mp_start_method="spawn"),
    }
    collectors = {name: Collector(env, None, frames_per_batch=256, total_frames=-1,
                                  auto_register_policy_transforms=False) for name, env in envs.items()}
    try:
        setups = {"bare batched env": bare_env_steps(FourRoomsEnv(16), 16 * batches)}
        setups |= {name: collector_batches(c, batches) for name, c in collectors.items()}
        rates = best_rate(setups, repeats)
    finally:
        for c in collectors.values():
            c.shutdown()
    base = rates["bare batched env"]
    for name, rate in rates.items():
        print(f"  {name:34s} {rate:9.0f} frames/s   {rate / base:5.2f} x bare")



def transform_cost(config: A2CConfig, repeats: int, batches: int) -> None:
    """Part 2."""
    print("Part 2: A2C iteration (collect 256 frames + GAE + A2C step [+ potential step]), recipe settings,")
    print("        every set-up with the same policy (trained briefly by plain A2C, then kept: lr 0)")
    torch.manual_seed(0)
    pretrain, networks = a2c_iterations(None, config, 120, online=False)
    pretrain()  # ~30k frames: episodes of ~50-100 steps, so resets happen as in training
    hrs = Shaping(HALLWAYS, TabularPotential(3), {"observation_key": "cell"})
    hrs_online = Shaping(HALLWAYS, TabularPotential(3), {"observation_key": "cell"})
    setups = {
        "plain A2C": a2c_iterations(None, config, batches, False, networks, lr=0.0)[0],
        "keys-only transform (floor)": a2c_iterations(None, config, batches, False, networks, lr=0.0,
                                                      keys_only=True)[0],
        "HRS, potential trained per batch": a2c_iterations(hrs, config, batches, False, networks, lr=0.0)[0],
        "HRS, potential trained online": a2c_iterations(hrs_online, config, batches, True, networks, lr=0.0)[0],
    }
    rates = best_rate(setups, repeats)
    plain = rates["plain A2C"]
    for name, rate in rates.items():
        cost = plain / rate - 1.0
        print(f"  {name:34s} {rate:9.0f} frames/s   transform cost {100 * cost:+5.1f}% of the plain iteration")


if __name__ == "__main__":
    main()
