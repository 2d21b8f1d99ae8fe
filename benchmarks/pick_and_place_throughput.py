"""Pick and place throughput: collector env-steps/s, DDPG gradient steps/s, projected learning time.

Measures, in one run (the machine is shared: compare the ratios, not the absolute rates):

* the raw gymnasium ``FetchPickAndPlace-v4`` env stepped in this process under
  random actions (the reference rate);
* collection with the exploring DDPG policy and HRS shaping (neural potential), as the
  recipe collects: a ``Collector`` in this process over 1 env (everything on one core);
  the same over ``TransformedEnv(ParallelEnv(2), shaping)`` (MuJoCo in 2 processes,
  policy and shaping here); a ``MultiSyncCollector`` of 1 and 2 worker processes of one
  env each, and of 2 workers of 3 envs each (the paper preset's 6 envs, beside a
  ``Collector`` here over the same 6 envs), each worker
  stepping its envs through the shaping transform with the shared potential
  (``--collector-workers`` in the recipe); the 1-env, 2 × 1 and 2 × 3 layouts with the recipe's
  stack (:func:`~torchrl_subgoal.envs.fetch.make_fetch_envs` stepping its envs with
  :class:`~torchrl_subgoal.envs.fetch.LeanStep`, the shaping transform alone, the one-module
  exploring policy) and with gymnasium's own step (``make_fetch_envs(lean=False)``); and 2 workers
  of 6 envs each (twice the ``paper`` preset's envs: what more envs per worker would give);
* CPU time per env step (``time.process_time``, so a busy machine inflates it far less than the
  rates) of a ``Collector`` in this process over 3 envs (one ``paper`` worker's share) with
  ``LeanStep`` and with gymnasium's step, alternating with the raw env in the same process: on
  two idle cores, two such workers would step ``2 × raw / worker`` times the raw env's rate;
* DDPG gradient steps per CPU second (critic + actor, batch 256 and the paper preset's
  1,536, 3 × 256 hidden units, ``torch.set_num_threads(1)`` unless ``--threads``), beside a
  hand-written torch step of the same arithmetic (the floor in practice);
  the single-core matmul GFLOP/s of the layers' shape and the FLOPs of one step give the
  FLOP floor of the gradient steps of a learning;
* from these, the projected wall time of one learning on one core, every part run one
  after another in one process: the paper preset (the authors' 6 workers' data: 3×10^6
  env steps, 4×10^5 gradient steps of 1,536) and one worker's share of it (5×10^5 env
  steps, 4×10^5 gradient steps of 256), with 10 test episodes per epoch.

``--profile`` instead prints where a step of the one-process collector goes (cProfile,
cumulative time of the policy, the shaping transform, the env's step (``LeanStep``, then
gymnasium-robotics' own) and MuJoCo's ``mj_step``, as shares of the collector's time).

A collector that gives no batch for ``--timeout`` seconds (default 600) ends the run with a
one-line error naming the layout, every thread's stack, and its worker processes killed (exit
status 3), so that a hung ``MultiSyncCollector`` never keeps the benchmark waiting. Collectors are
closed with ``close_collector`` (``shutdown()`` alone can leave the process hanging at interpreter
exit, where no watchdog runs: TorchRL's weight-sync schemes; see ``close_collector``).

Every figure is the best of ``--repeats`` timings. The load average is printed
before and after: it says how busy the shared cores were.

Usage::

    python benchmarks/pick_and_place_throughput.py            # ~3 minutes on an idle machine
    python benchmarks/pick_and_place_throughput.py --quick    # fewer steps
    python benchmarks/pick_and_place_throughput.py --quick --collectors-only   # no DDPG steps, no projection
    python benchmarks/pick_and_place_throughput.py --interleaved 3   # the target's layouts, timed in turn
"""

from __future__ import annotations

import argparse
import copy
import cProfile
import faulthandler
import inspect
import multiprocessing
import os
import pstats
import sys
import threading
import time
from collections.abc import Callable, Iterator
from functools import partial

import torch
from tensordict import TensorDict
from torch import nn
from torchrl.collectors import Collector, MultiSyncCollector
from torchrl.data import Bounded

from torchrl_subgoal import NeuralPotential
from torchrl_subgoal.envs import fetch
from torchrl_subgoal.training import EnvFactory, Shaping, close_collector, shaped_env
from torchrl_subgoal.training.ddpg_parts import DDPGAgent, DDPGConfig, mlp

GRADIENT_STEPS = 200 * 50 * 40  # epochs x cycles x gradient steps per cycle, both presets
TEST_STEPS = 200 * 10 * 50  # epochs x test episodes x steps


def best(run: Callable[[], float], repeats: int) -> float:
    """The best of ``repeats`` rates returned by ``run``."""
    return max(run() for _ in range(repeats))


def raw_rate(steps: int) -> float:
    gymnasium = fetch.require_fetch()
    env = gymnasium.make(fetch.BASE_ENV_ID)
    env.reset(seed=0)
    env.action_space.seed(0)
    actions = [env.action_space.sample() for _ in range(64)]
    start = time.perf_counter()
    for i in range(steps):
        _, _, terminated, truncated, _ = env.step(actions[i % 64])
        if terminated or truncated:
            env.reset()
    rate = steps / (time.perf_counter() - start)
    env.close()
    return rate


#: Collection stacks: the recipe's (envs stepped by ``LeanStep``); the same with gymnasium's step.
STACKS = ("lean", "gymnasium step")


class Watchdog:
    """Ends the benchmark when no :meth:`beat` came for ``seconds`` (0: never): one line on stderr naming
    what was awaited, every thread's stack, the worker processes killed, exit status 3."""

    def __init__(self, seconds: float) -> None:
        self.seconds, self.what, self.last = seconds, "start-up", time.monotonic()
        if seconds > 0:
            threading.Thread(target=self._watch, name="watchdog", daemon=True).start()

    def beat(self, what: str) -> None:
        """Alive; next awaited: ``what``."""
        self.what, self.last = what, time.monotonic()

    def _watch(self) -> None:
        while True:
            time.sleep(min(1.0, self.seconds / 4))
            if time.monotonic() - self.last > self.seconds:
                print(
                    f"error: {self.what}: nothing for {self.seconds:.0f} s (--timeout); the stacks follow, "
                    "then the collectors' worker processes are killed",
                    file=sys.stderr,
                    flush=True,
                )
                faulthandler.dump_traceback(file=sys.stderr)
                for child in multiprocessing.active_children():
                    child.kill()
                os._exit(3)


#: the run's watchdog (``--timeout``); the collectors beat it at every batch
WATCHDOG = Watchdog(0)


def next_batch(batches: Iterator[TensorDict], name: str) -> TensorDict:
    """The next batch of the collector ``name``, under the watchdog."""
    WATCHDOG.beat(f"a batch of {name}")
    batch = next(batches)
    WATCHDOG.beat(f"after a batch of {name}")
    return batch


def make_collector(
    collector_workers: int,
    env_workers: int,
    envs: int,
    stack: str = "lean",
) -> Collector | MultiSyncCollector:
    """A ``MultiSyncCollector`` of ``collector_workers`` processes (0: a ``Collector`` here) stepping
    ``envs`` envs each (in ``env_workers`` ParallelEnv processes, 0: in the collecting process), HRS shaping.

    ``stack`` (:data:`STACKS`): ``"lean"``, the recipe's: :func:`fetch.make_fetch_envs` (each env stepped
    by :class:`fetch.LeanStep`), the shaping transform alone, the agent's one-module exploring policy;
    ``"gymnasium step"``: the same with ``make_fetch_envs(lean=False)``.
    """
    series = fetch.human_patterns()["participants"]
    shaping = Shaping([series], NeuralPotential(mlp(fetch.OBSERVATION_SIZE, 1, (256, 256, 256))))
    make_env = partial(fetch.make_fetch_envs, 0, lean=stack == "lean")
    factory = EnvFactory(
        shaped_env,
        make_env=make_env,
        num_envs=envs,
        env_workers=env_workers,
        shaping=shaping,
        potential=shaping.potential,
        gamma=0.98,
        episode_stats=False,
    )
    agent = DDPGAgent(
        fetch.OBSERVATION_SIZE, fetch.make_fetch_env(0).action_spec_unbatched, DDPGConfig(buffer_size=1000)
    )
    policy = agent.policy
    frames = 50 * envs * max(collector_workers, 1)
    return (
        Collector(factory(), policy, frames_per_batch=frames, total_frames=-1, auto_register_policy_transforms=False)
        if collector_workers == 0
        else MultiSyncCollector(
            [factory] * collector_workers,
            policy,
            frames_per_batch=frames,
            total_frames=-1,
            cat_results="stack",
            auto_register_policy_transforms=False,
        )
    )


def collector_rate(
    collector_workers: int, env_workers: int, envs: int, steps: int, repeats: int, stack: str = "lean"
) -> float:
    """Env steps/s of :func:`make_collector`'s collector (the best of ``repeats`` timings of ``steps``)."""
    name = f"{collector_workers} collector worker(s) x {envs} env(s), {stack}"
    WATCHDOG.beat(f"starting {name}")
    collector = make_collector(collector_workers, env_workers, envs, stack)
    batches = iter(collector)
    next_batch(batches, name)  # warm-up: workers started, first reset done

    def run() -> float:
        start = time.perf_counter()
        done = 0
        while done < steps:
            done += next_batch(batches, name).numel()
        return done / (time.perf_counter() - start)

    rate = best(run, repeats)
    close_collector(collector)
    return rate


def interleaved(steps: int, rounds: int) -> None:
    """The raw env and the ``MultiSyncCollector`` layouts of the target, every one alive at once and timed
    in turn, ``rounds`` times: on a shared machine each round's ratios to that round's raw rate hold up
    better than rates timed minutes apart."""
    layouts = {
        "MultiSyncCollector, 1 worker x 3 envs": (1, 0, 3, "lean"),
        "MultiSyncCollector, 2 workers x 3 envs": (2, 0, 3, "lean"),
        "MultiSyncCollector, 2 workers x 3 envs, gymnasium step": (2, 0, 3, "gymnasium step"),
        "MultiSyncCollector, 2 workers x 6 envs": (2, 0, 6, "lean"),
    }
    WATCHDOG.beat("starting the collectors")
    collectors = {name: make_collector(*layout) for name, layout in layouts.items()}
    iterators = {name: iter(collector) for name, collector in collectors.items()}
    for name, batches in iterators.items():
        next_batch(batches, name)
    rates: dict[str, list[float]] = {"raw gymnasium env, 1 process": [], **{name: [] for name in collectors}}
    for _ in range(rounds):
        WATCHDOG.beat("the raw env")
        rates["raw gymnasium env, 1 process"].append(raw_rate(steps))
        for name, batches in iterators.items():
            start, done = time.perf_counter(), 0
            while done < steps:
                done += next_batch(batches, name).numel()
            rates[name].append(done / (time.perf_counter() - start))
    for collector in collectors.values():
        close_collector(collector)
    raw = rates["raw gymnasium env, 1 process"]
    for name, values in rates.items():
        label = name + (":" if values is raw else ", HRS shaping:")
        print(
            f"{label:66s} best {max(values):5.0f} env-steps/s ({max(values) / max(raw):.2f}x the "
            f"best raw); per round, x that round's raw: "
            + ", ".join(f"{v / r:.2f}" for v, r in zip(values, raw, strict=True))
        )


def cpu_per_step(envs: int, steps: int, repeats: int) -> dict[str, float]:
    """CPU µs per env step of the raw env and of a ``Collector`` here over ``envs`` envs with ``LeanStep``
    and with gymnasium's step (HRS), the three alternating ``repeats`` times (the least of each is kept).

    One torch thread, as in a collector worker (a ``MultiSyncCollector``'s shutdown hands this process its
    workers' threads back, whose spinning would count as CPU time here)."""
    torch.set_num_threads(1)
    gymnasium = fetch.require_fetch()
    env = gymnasium.make(fetch.BASE_ENV_ID)
    env.reset(seed=0)
    env.action_space.seed(0)
    actions = [env.action_space.sample() for _ in range(64)]
    WATCHDOG.beat("starting the collectors")
    collectors = {stack: make_collector(0, 0, envs, stack) for stack in STACKS}
    iterators = {stack: iter(collector) for stack, collector in collectors.items()}
    for stack, batches in iterators.items():
        next_batch(batches, stack)
    costs: dict[str, list[float]] = {"raw gymnasium env": [], **{stack: [] for stack in collectors}}
    for _ in range(repeats):
        start = time.process_time()
        for i in range(steps):
            _, _, terminated, truncated, _ = env.step(actions[i % 64])
            if terminated or truncated:
                env.reset()
        costs["raw gymnasium env"].append((time.process_time() - start) / steps)
        for stack, batches in iterators.items():
            start, done = time.process_time(), 0
            while done < steps:
                done += next_batch(batches, stack).numel()
            costs[stack].append((time.process_time() - start) / done)
    for collector in collectors.values():
        close_collector(collector)
    env.close()
    return {name: 1e6 * min(values) for name, values in costs.items()}


def profile_collector(steps: int, lean: bool) -> None:
    """Shares of a one-process collector's time (1 env, HRS shaping, exploring policy; ``lean``: the env
    steps with :class:`fetch.LeanStep`, else with gymnasium's step)."""
    series = fetch.human_patterns()["participants"]
    shaping = Shaping([series], NeuralPotential(mlp(fetch.OBSERVATION_SIZE, 1, (256, 256, 256))))
    env = shaped_env(partial(fetch.make_fetch_envs, 0, lean=lean), 1, shaping=shaping, gamma=0.98, episode_stats=False)
    agent = DDPGAgent(fetch.OBSERVATION_SIZE, env.action_spec_unbatched, DDPGConfig(buffer_size=1000))
    explore = agent.policy.forward

    def policy_forward(tensordict: TensorDict) -> TensorDict:  # a name cProfile can find
        return explore(tensordict)

    agent.policy.forward = policy_forward
    collector = Collector(
        env, agent.policy, frames_per_batch=50, total_frames=-1, auto_register_policy_transforms=False
    )
    batches = iter(collector)
    next(batches)
    profiler = cProfile.Profile()
    profiler.enable()
    for _ in range(steps // 50):
        next(batches)
    profiler.disable()
    close_collector(collector)
    stats = pstats.Stats(profiler).stats  # type: ignore[attr-defined]
    total = sum(tt for (_, _, _), (_, _, tt, _, _) in stats.items())
    lean_line = inspect.getsourcelines(fetch.LeanStep.step)[1]
    parts: dict[str, Callable[[str, int, str], bool]] = {
        "policy (actor 3x256 + exploration)": lambda f, line, n: n == "policy_forward",
        "shaping transform (+ neural potential)": lambda f, line, n: (
            n == "_step" and f.endswith("torchrl_subgoal/transform.py")
        ),
        "batched Fetch env (make_fetch_envs)": lambda f, line, n: n == "_step" and f.endswith("envs/fetch.py"),
        "gymnasium-robotics step (incl. MuJoCo)": lambda f, line, n: (
            n == "step" and f.endswith("gymnasium_robotics/envs/robot_env.py")
        ),
        "LeanStep.step (incl. MuJoCo)": lambda f, line, n: line == lean_line and f.endswith("envs/fetch.py"),
        "MuJoCo mj_step": lambda f, line, n: "mj_step" in n,
    }
    print(
        f"profile of {steps} collector steps, {'LeanStep' if lean else 'gymnasium step'} "
        f"({total:.2f} s profiled; cumulative shares):"
    )
    for label, match in parts.items():
        cumulative = sum(ct for (f, line, n), (_, _, _, ct, _) in stats.items() if match(f, line, n))
        print(f"  {label:42s} {100 * cumulative / total:5.1f}%")


def _filled_agent(batch_size: int, spec: Bounded) -> DDPGAgent:
    agent = DDPGAgent(fetch.OBSERVATION_SIZE, spec, DDPGConfig(buffer_size=20_000, batch_size=batch_size))
    n = 10_000
    agent.extend(
        TensorDict(
            {
                "observation": torch.randn(n, fetch.OBSERVATION_SIZE),
                "action": spec.rand((n,)),
                "next": {
                    "observation": torch.randn(n, fetch.OBSERVATION_SIZE),
                    "reward": -torch.ones(n, 1),
                    "done": torch.zeros(n, 1, dtype=torch.bool),
                    "terminated": torch.zeros(n, 1, dtype=torch.bool),
                },
            },
            [n],
        )
    )
    return agent


def _hand_written_update(batch_size: int) -> Callable[[], None]:
    """The floor: the same networks, targets, clip, penalty and fused Adam in plain torch, no TorchRL."""

    def net(inputs: int, outputs: int) -> nn.Module:
        return mlp(inputs, outputs, (256, 256, 256))

    actor, critic = net(fetch.OBSERVATION_SIZE, 4), net(fetch.OBSERVATION_SIZE + 4, 1)
    target_actor, target_critic = (
        copy.deepcopy(actor).requires_grad_(False),
        copy.deepcopy(critic).requires_grad_(False),
    )
    actor_opt = torch.optim.Adam(actor.parameters(), lr=1e-3, fused=True)
    critic_opt = torch.optim.Adam(critic.parameters(), lr=1e-3, fused=True)
    n = 10_000
    obs, act, next_obs = torch.randn(n, fetch.OBSERVATION_SIZE), torch.rand(n, 4) * 2 - 1, torch.randn(n, 25)
    reward, terminated = -torch.ones(n, 1), torch.zeros(n, 1)

    def update() -> None:
        i = torch.randint(0, n, (batch_size,))
        o, a, o2 = obs[i], act[i], next_obs[i]
        with torch.no_grad():
            q_next = target_critic(torch.cat([o2, torch.tanh(target_actor(o2))], -1))
            target = (reward[i] + 0.98 * (1 - terminated[i]) * q_next).clamp(-50.0, 0.0)
        loss_value = (critic(torch.cat([o, a], -1)) - target).square().mean()
        pi = torch.tanh(actor(o))
        detached = {k: v.detach() for k, v in critic.named_parameters()}
        q_pi = torch.func.functional_call(critic, detached, (torch.cat([o, pi], -1),))
        critic_opt.zero_grad(set_to_none=True)
        actor_opt.zero_grad(set_to_none=True)
        (loss_value - q_pi.mean() + pi.square().mean()).backward()
        critic_opt.step()
        actor_opt.step()

    return update


def update_rates(updates: int, repeats: int, batch_size: int, threads: int) -> dict[str, float]:
    """Gradient steps per CPU second (this process's CPU time: on a shared machine, what one core costs)
    of the agent's update and the hand-written floor, interleaved."""
    torch.set_num_threads(threads)  # a MultiSyncCollector's shutdown hands its workers' threads back
    spec = fetch.make_fetch_env(0).action_spec_unbatched
    agent = _filled_agent(batch_size, spec)
    steps = {"agent.update": agent.update, "hand-written torch step": _hand_written_update(batch_size)}
    rates: dict[str, float] = {}
    for step in steps.values():
        for _ in range(5):
            step()
    for _ in range(repeats):  # interleaved, so that a change of load hits both alike
        for name, step in steps.items():
            start = time.process_time()
            for i in range(updates):
                step()
                if name == "agent.update" and i % 40 == 39:
                    agent.soft_update()
            rates[name] = max(rates.get(name, 0.0), updates / (time.process_time() - start))
    return rates


def matmul_gflops(rows: int, repeats: int = 200) -> float:
    """Single-thread fp32 GFLOP per CPU second of ``[rows, 256] @ [256, 256]``, the layers' shape."""
    x, w = torch.randn(rows, 256), torch.randn(256, 256)
    for _ in range(10):
        x @ w
    start = time.process_time()
    for _ in range(repeats):
        x @ w
    return 2 * rows * 256 * 256 * repeats / (time.process_time() - start) / 1e9


def update_flops(batch_size: int, hidden: int = 256) -> float:
    """Floating-point operations of one gradient step (matmuls only): 2 actor and 3 critic forward
    passes (target actor and critic on o', critic on (o, a), actor on o, critic on (o, π(o))), the
    critic's backward through weights and activations (2×), the actor loss's backward through the
    critic's activations only (1×) and the actor's weights and activations (2×)."""
    actor = fetch.OBSERVATION_SIZE * hidden + 2 * hidden * hidden + hidden * 4
    critic = (fetch.OBSERVATION_SIZE + 4) * hidden + 2 * hidden * hidden + hidden
    return 2.0 * batch_size * (4 * actor + 6 * critic)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--quick", action="store_true", help="fewer steps per timing")
    parser.add_argument("--repeats", type=int, default=3, help="timings per figure (best is kept)")
    parser.add_argument("--threads", type=int, default=1, help="torch threads for the gradient steps")
    parser.add_argument("--profile", action="store_true", help="only profile the one-process collector")
    parser.add_argument(
        "--interleaved",
        type=int,
        default=0,
        metavar="ROUNDS",
        help="only the raw env and the 1 x 3, 2 x 3 and 2 x 6 collectors, timed in turn ROUNDS times",
    )
    parser.add_argument(
        "--collectors-only", action="store_true", help="env-steps only: no DDPG gradient steps, no projection"
    )
    parser.add_argument(
        "--timeout",
        type=float,
        default=600.0,
        metavar="SECONDS",
        help="end the run when a collector gives no batch for this long (0: wait forever)",
    )
    args = parser.parse_args()
    if args.timeout < 0:
        parser.error(f"--timeout: seconds >= 0 (got {args.timeout})")
    global WATCHDOG
    WATCHDOG = Watchdog(args.timeout)
    torch.set_num_threads(args.threads)
    steps = 1_000 if args.quick else 3_000
    if args.profile:
        for lean in (True, False):
            profile_collector(steps, lean)
        return
    print(f"load average before: {os.getloadavg()[0]:.2f} on {os.cpu_count()} cores")
    if args.interleaved:
        interleaved(steps, args.interleaved)
        print(f"load average after: {os.getloadavg()[0]:.2f}")
        return
    WATCHDOG.beat("the raw env")
    raw = best(lambda: raw_rate(steps), args.repeats)
    print(f"raw gymnasium env, 1 process:        {raw:8.0f} env-steps/s  (1.00x)")
    rates = {}
    for name, collector_workers, env_workers, envs, stack in (
        ("Collector, this process, 1 env", 0, 0, 1, "lean"),
        ("Collector, this process, 1 env, gymnasium step", 0, 0, 1, "gymnasium step"),
        ("Collector over ParallelEnv(2), shaping here", 0, 2, 2, "lean"),
        ("MultiSyncCollector, 1 worker x 1 env", 1, 0, 1, "lean"),
        ("MultiSyncCollector, 1 worker x 3 envs", 1, 0, 3, "lean"),
        ("MultiSyncCollector, 2 workers x 1 env", 2, 0, 1, "lean"),
        ("MultiSyncCollector, 2 workers x 1 env, gymnasium step", 2, 0, 1, "gymnasium step"),
        ("Collector, this process, 6 envs", 0, 0, 6, "lean"),
        ("MultiSyncCollector, 2 workers x 3 envs", 2, 0, 3, "lean"),
        ("MultiSyncCollector, 2 workers x 3 envs, gymnasium step", 2, 0, 3, "gymnasium step"),
        ("MultiSyncCollector, 2 workers x 6 envs", 2, 0, 6, "lean"),
    ):
        rate = rates[name] = collector_rate(collector_workers, env_workers, envs, steps, args.repeats, stack)
        print(f"{name + ', HRS shaping:':66s} {rate:8.0f} env-steps/s  ({rate / raw:.2f}x raw)")
    costs = cpu_per_step(3, steps, max(args.repeats, 2))
    raw_cpu = costs.pop("raw gymnasium env")
    print(
        f"CPU per env step, this process, alternating: raw gymnasium env {raw_cpu:.0f} µs; a Collector over "
        "3 envs, HRS: "
        + "; ".join(
            f"{stack} {cost:.0f} µs ({cost / raw_cpu:.2f}x raw, 2 such workers on "
            f"2 idle cores: {2 * raw_cpu / cost:.2f}x raw)"
            for stack, cost in costs.items()
        )
    )
    if args.collectors_only:
        print(f"load average after: {os.getloadavg()[0]:.2f}")
        return
    updates = {}
    for batch in (256, 1536):
        WATCHDOG.beat(f"the DDPG gradient steps of batch {batch}")
        rates_b = update_rates((200 if args.quick else 600) * 256 // batch, args.repeats, batch, args.threads)
        updates[batch] = rates_b["agent.update"]
        flop = update_flops(batch)
        gflops = matmul_gflops(batch)
        print(
            f"DDPG gradient steps, batch {batch}, {args.threads} thread(s): "
            + "; ".join(f"{name} {1e3 / rate:.1f} ms" for name, rate in rates_b.items())
            + f" (agent.update {rates_b['hand-written torch step'] / rates_b['agent.update']:.2f}x the hand-written)"
        )
        print(
            f"  FLOP floor: {flop / 1e9:.2f} GFLOP per step / {gflops:.0f} GFLOP/s single-thread matmul "
            f"[{batch}x256]@[256x256] = {1e3 * flop / gflops / 1e9:.1f} ms"
        )
        floor_minutes = GRADIENT_STEPS * flop / gflops / 1e9 / 60
        print(f"  {GRADIENT_STEPS:.0e} gradient steps of {batch} at that floor: {floor_minutes:.0f} min on one core")
    one_core = rates["Collector, this process, 1 env"]
    for preset, env_steps, batch in (("paper (6 workers' data)", 3_000_000, 1536), ("paper-1worker", 500_000, 256)):
        env_seconds = (env_steps + TEST_STEPS) / one_core
        update_seconds = GRADIENT_STEPS / updates[batch]
        print(
            f"projected {preset} learning on one core: {(env_seconds + update_seconds) / 60:.0f} min = "
            f"{env_seconds / 60:.0f} min collecting and testing ({env_steps:.0e} + {TEST_STEPS:.0e} steps) + "
            f"{update_seconds / 60:.0f} min of {GRADIENT_STEPS:.0e} gradient steps of {batch}"
        )
    print(f"load average after: {os.getloadavg()[0]:.2f}")


if __name__ == "__main__":
    main()
