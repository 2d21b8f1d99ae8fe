"""TorchRL collection with subgoal shaping: collector frames per second, and the transform's cost in A2C.

Part 1, collector throughput (four-rooms, random policy, 16 envs): frames per
second of the bare batched env stepped with ``step_and_maybe_reset``, of a
``Collector`` over that batched env, and of a ``Collector`` over a
``ParallelEnv`` of 1 and 2 env workers (8 + 8 envs with 2).

Part 2, the shaping transform's cost inside an A2C iteration at the recipe's
settings of ``--domain`` (``recipes/a2c.py --domain four_rooms``: 16 envs, 256
frames per batch, one-hot policy; ``--domain pinball``: 16 envs, 256 frames
per batch, order-3 Fourier policy, reward x 1e-4, HRS with the first
participant's subgoals): the time of one iteration — collect a batch, GAE, one
A2C step, and for HRS one step of the potential on the batch's SMDP
transitions — with and without the transform (the HRS potential trained
centrally, as the recipe does, and online). Every set-up collects with the
same policy (briefly trained, then kept with learning rate 0): a policy that
learns at a different speed would end episodes, and so reset envs, at a
different rate, which changes a step's cost more than the transform does.
The set-ups run in turn, in a rotating order, ``--repeats`` times; each round
gives every set-up's time over the plain iteration's of the same round, and
the cost reported is the median of those ratios (with their range), by the
process's CPU time (what other processes on a busy machine disturb least)
and by wall time. The load average is printed with them. ``--calls`` also
counts the Python function calls of one round of every set-up (cProfile's
count, over the same plain iteration): unlike times, the count does not move
with the machine's load, and its ratios track the quiet machine's CPU-time
ratios (see docs/torchrl.md).

    python benchmarks/a2c_collection.py            # the figures in docs/torchrl.md
    python benchmarks/a2c_collection.py --quick
    python benchmarks/a2c_collection.py --part 2 --repeats 15
    python benchmarks/a2c_collection.py --part 2 --quick --calls
    python benchmarks/a2c_collection.py --part 2 --domain pinball --calls
"""

from __future__ import annotations

import argparse
import copy
import cProfile
import functools
import os
import pstats
import statistics
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

from torchrl_subgoal import (
    Cell,
    SubgoalSeries,
    SubgoalValueLoss,
    TabularPotential,
    domains,
    load_patterns,
)
from torchrl_subgoal.envs import FourRoomsEnv
from torchrl_subgoal.methods import paper_methods, shaping_parts
from torchrl_subgoal.training import (
    A2CConfig,
    LearnerDomain,
    Shaping,
    actor_critic,
    shaped_env,
    smdp_transitions,
)

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


def paired_costs(
    setups: dict[str, Callable[[], int]], repeats: int, base: str
) -> tuple[dict[str, dict[str, tuple[float, float, float]]], dict[str, float]]:
    """Run the set-ups in turn ``repeats`` times (the order rotates every round); each round, every
    set-up's seconds per frame over ``base``'s of the same round, minus 1. Returns, per set-up and
    clock (``"cpu"``: this process's CPU time; ``"wall"``), the (median, lowest, highest) cost; and
    per clock ``base``'s median seconds per frame."""
    names = list(setups)
    ratios: dict[str, dict[str, list[float]]] = {n: {"cpu": [], "wall": []} for n in names}
    base_times: dict[str, list[float]] = {"cpu": [], "wall": []}
    for r in range(repeats):
        per_frame: dict[str, tuple[float, float]] = {}
        for name in names[r % len(names) :] + names[: r % len(names)]:
            cpu, wall = time.process_time(), time.perf_counter()
            frames = setups[name]()
            per_frame[name] = ((time.process_time() - cpu) / frames, (time.perf_counter() - wall) / frames)
        for i, clock in enumerate(("cpu", "wall")):
            base_times[clock].append(per_frame[base][i])
        for name in names:
            for i, clock in enumerate(("cpu", "wall")):
                ratios[name][clock].append(per_frame[name][i] / per_frame[base][i] - 1.0)
    costs = {n: {c: (statistics.median(v), min(v), max(v)) for c, v in clocks.items()} for n, clocks in ratios.items()}
    return costs, {c: statistics.median(v) for c, v in base_times.items()}


def call_counts(setups: dict[str, Callable[[], int]]) -> dict[str, float]:
    """Python function calls per frame of one call of each set-up (cProfile's count: it does not depend on
    the machine's load, only on the work done; calls into C count one each)."""
    counts = {}
    for name, run in setups.items():
        profile = cProfile.Profile()
        profile.enable()
        frames = run()
        profile.disable()
        counts[name] = pstats.Stats(profile).total_calls / frames  # type: ignore[attr-defined]
    return counts


def four_rooms_a2c() -> LearnerDomain:
    """The A2C recipe's four-rooms set-up (the four-rooms plugin's registration).

    Examples:
        >>> four_rooms_a2c().a2c.features
        'one_hot'
    """
    return domains.part("four_rooms", LearnerDomain)


def load_average() -> str:
    """The 1-, 5- and 15-minute load averages (``"n/a"`` where the OS has none)."""
    try:
        return "/".join(f"{x:.1f}" for x in os.getloadavg())
    except OSError:
        return "n/a"


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


def hrs_shaping(domain: LearnerDomain) -> Shaping:
    """The HRS shaping part 2 times: four-rooms, the two hallways (a tabular potential over 3
    states); PinBall, the recipe's HRS learner of the first participant's pattern.

    Examples:
        >>> hrs_shaping(domains.part("four_rooms", LearnerDomain)).options
        {'observation_key': 'cell'}
        >>> shaping = hrs_shaping(domains.part("pinball", LearnerDomain))
        >>> type(shaping.potential).__name__, shaping.options["start_potential"]
        ('TabularPotential', 'value')
    """
    if domain.name == "four_rooms":
        return Shaping(HALLWAYS, TabularPotential(3), {"observation_key": "cell"})
    patterns = list(load_patterns(domain.participants, domain=domain.name).values())[:1]
    parts = shaping_parts(
        paper_methods(baseline="A2C")["HRS"],
        (),
        patterns=patterns,
        eta=domain.eta,
        observation_key=domain.subgoal_key,
        aggregation_key=domain.aggregation_key,
        start_potential="value",
    )  # recipes/a2c.py's default
    assert parts is not None
    return Shaping(*parts)


def a2c_iterations(
    shaping: Shaping | None,
    domain: LearnerDomain,
    config: A2CConfig,
    batches: int,
    online: bool,
    networks: tuple[TensorDictModuleBase, TensorDictModuleBase] | None = None,
    lr: float | None = None,
    keys_only: bool = False,
    kept: int = 3,
) -> tuple[Callable[[], int], tuple[TensorDictModuleBase, TensorDictModuleBase]]:
    """One A2C learner as ``train_a2c`` runs it, ``batches`` iterations per call (and its networks).

    With ``networks`` the learner starts from copies of them; ``lr=0`` keeps the policy as it is
    (every set-up then collects with the same policy, so episodes end as often in each).
    ``keys_only`` appends a transform that writes the shaping transform's entries without
    computing them: what TorchRL's per-entry bookkeeping costs any such transform (``kept``: how many of
    the three carried entries it writes).
    """
    env = shaped_env(
        domain.make_env,
        config.num_envs,
        shaping=shaping,
        gamma=config.gamma,
        value_lr=config.value_lr if online else None,
        reward_scale=config.reward_scale,
    )
    if keys_only:
        sys.path.insert(0, str(Path(__file__).resolve().parent))
        from four_rooms_step import KeysOnly

        env.transform.insert(1, KeysOnly(kept))
    actor, critic = (
        (copy.deepcopy(networks[0]), copy.deepcopy(networks[1]))
        if networks
        else actor_critic(
            env,
            domain.observation_key,
            features=config.features,
            hidden=config.hidden,
            fourier_order=config.fourier_order,
        )
    )
    advantage = GAE(gamma=config.gamma, lmbda=config.gae_lambda, value_network=critic)
    loss = A2CLoss(
        actor, critic, entropy_coeff=config.entropy_coeff, critic_coeff=config.critic_coeff, loss_critic_type="l2"
    )
    optimizer = torch.optim.Adam(loss.parameters(), lr=config.lr if lr is None else lr)
    keeper, value_loss, value_optimizer = None, None, None
    if shaping is not None and not online:
        keeper = shaping.transform(shaping.potential, config.gamma, None)
        value_loss = SubgoalValueLoss(shaping.potential, reduction="mean").make_value_estimator(gamma=config.gamma)
        value_optimizer = torch.optim.Adam(shaping.potential.parameters(), lr=config.value_lr)
    collector = Collector(
        env, actor, frames_per_batch=config.frames_per_batch, total_frames=-1, auto_register_policy_transforms=False
    )
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
    parser.add_argument("--repeats", type=int, default=0, help="rounds (default 7, --quick 3; part 2: 11 / 5)")
    parser.add_argument(
        "--domain",
        choices=["four_rooms", "pinball"],
        default="four_rooms",
        help="part 2: the A2C recipe's domain whose settings are timed",
    )
    parser.add_argument(
        "--calls",
        action="store_true",
        help="part 2: also count Python function calls per iteration (independent of the load)",
    )
    args = parser.parse_args()
    if args.repeats < 0:
        parser.error(f"--repeats must be >= 0, got {args.repeats}")
    torch.set_num_threads(1)
    repeats, batches = (3, 10) if args.quick else (7, 30)
    domain = domains.part(args.domain, LearnerDomain)

    if args.part != "2":
        collector_throughput(args.repeats or repeats, batches)
    if args.part != "1":
        transform_cost(domain, args.repeats or (5 if args.quick else 11), batches, args.calls)


def collector_throughput(repeats: int, batches: int) -> None:
    """Part 1."""
    print("Part 1: collector frames per second (four-rooms, 16 envs, random policy, 256 frames per batch)")
    envs: dict[str, EnvBase] = {
        "Collector, batched env": FourRoomsEnv(16),
        "Collector, ParallelEnv 1 worker": ParallelEnv(1, functools.partial(FourRoomsEnv, 16), mp_start_method="spawn"),
        "Collector, ParallelEnv 2 workers": ParallelEnv(2, functools.partial(FourRoomsEnv, 8), mp_start_method="spawn"),
    }
    collectors = {
        name: Collector(env, None, frames_per_batch=256, total_frames=-1, auto_register_policy_transforms=False)
        for name, env in envs.items()
    }
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


def transform_cost(domain: LearnerDomain, repeats: int, batches: int, calls: bool = False) -> None:
    """Part 2."""
    config = domain.a2c
    print(
        f"Part 2: A2C iteration (collect {config.frames_per_batch} frames + GAE + A2C step [+ potential step]), "
        f"recipe settings of {domain.name} ({config.num_envs} envs, {config.features} features),"
    )
    print("        every set-up with the same policy (trained briefly by plain A2C, then kept: lr 0)")
    torch.manual_seed(0)
    pretrain, networks = a2c_iterations(None, domain, config, 120, online=False)
    pretrain()  # ~30k frames (four-rooms: episodes of ~50-100 steps, so resets happen as in training)
    setups = {
        "plain A2C": a2c_iterations(None, domain, config, batches, False, networks, lr=0.0)[0],
        "keys-only transform (floor)": a2c_iterations(
            None, domain, config, batches, False, networks, lr=0.0, keys_only=True
        )[0],
        "HRS, potential trained per batch": a2c_iterations(
            hrs_shaping(domain), domain, config, batches, False, networks, lr=0.0
        )[0],
        "HRS, potential trained online": a2c_iterations(
            hrs_shaping(domain), domain, config, batches, True, networks, lr=0.0
        )[0],
    }
    print(f"        {repeats} rounds; load average before {load_average()}")
    costs, plain = paired_costs(setups, repeats, "plain A2C")
    print(
        f"        load average after {load_average()}; plain A2C iteration (median): CPU "
        f"{1e3 * plain['cpu'] * config.frames_per_batch:.1f} ms, "
        f"wall {1e3 * plain['wall'] * config.frames_per_batch:.1f} ms"
    )
    print("        cost = time over the plain iteration's in the same round - 1, median [lowest, highest]")
    for name, clocks in costs.items():
        if name == "plain A2C":
            continue
        cpu, wall = clocks["cpu"], clocks["wall"]
        print(
            f"  {name:34s} CPU {100 * cpu[0]:+5.1f}% [{100 * cpu[1]:+5.1f}, {100 * cpu[2]:+5.1f}]   "
            f"wall {100 * wall[0]:+5.1f}% [{100 * wall[1]:+5.1f}, {100 * wall[2]:+5.1f}]"
        )
    if calls:
        # the floor of smaller entry formats: env_reward and the shaped reward, and 0-2 carried entries
        setups |= {
            f"keys-only, {kept} of 3 carried entries": a2c_iterations(
                None, domain, config, batches, False, networks, lr=0.0, keys_only=True, kept=kept
            )[0]
            for kept in (2, 1, 0)
        }
        counts = call_counts(setups)
        per_iteration = config.frames_per_batch
        print(f"        Python function calls per iteration ({per_iteration} frames), one call of every set-up:")
        for name, count in counts.items():
            print(f"  {name:34s} {count * per_iteration:8.0f}   {100 * (count / counts['plain A2C'] - 1):+5.1f}%")


if __name__ == "__main__":
    main()
