"""How much a batch of learners can gain on this CPU: the arithmetic a DQN or DDPG learner does per frame
against the rate this CPU multiplies matrices of its networks' shapes.

A batch of ``K`` learners pays each step's fixed cost once (the collector, the env, the Python of a loss and
an optimiser step) but does ``K`` times one learner's arithmetic. So however well the fixed cost is shared,
a batch cannot train more learner frames per CPU second than

    peak = (multiply rate of stacked matrices of the networks' shapes) / (FLOPs per learner frame),

and "batch / one at a time" cannot exceed ``peak`` divided by the one-at-a-time rate. This prints, for each
block:

* FLOPs per learner frame, counted (``torch.utils.flop_counter``'s formulas) over whole training runs of one
  learner: acting, the losses, their backward passes (optimiser steps are not matrix products); the
  difference of a run of ``2 × --frames`` frames and one of ``--frames``, so that set-up and the warm-up
  before the first update do not count;
* the multiply rate: a forward and backward pass of ``K`` stacked MLPs of the block's hidden layers at its
  sample batch size (``torch.vmap``, as the blocks stack learners), one torch thread;
* the one-at-a-time rate (learner frames per CPU second, from the same difference of uncounted runs);
* ``peak`` and the largest speed-up a batch can reach.

    python benchmarks/arithmetic_bound.py                      # DQN on MountainCar, DDPG on PointMaze UMaze
    python benchmarks/arithmetic_bound.py --blocks ddpg --frames 3000
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import time
from typing import Any

import torch
from torch import nn
from torch.func import functional_call, stack_module_state
from torch.utils._python_dispatch import TorchDispatchMode
from torch.utils.flop_counter import flop_registry

from torchrl_subgoal import domains as registry
from torchrl_subgoal import load_patterns
from torchrl_subgoal.training import LEARNERS, LearnerDomain


class CountFlops(TorchDispatchMode):
    """FLOPs of the matrix products and convolutions run inside it (``torch.utils.flop_counter``'s formulas;
    its ``FlopCounterMode`` also tracks modules, which TensorDict modules do not allow)."""

    def __init__(self) -> None:
        super().__init__()
        self.total = 0

    def __torch_dispatch__(self, func: Any, types: Any, args: Any = (), kwargs: Any = None) -> Any:
        kwargs = kwargs or {}
        out = func(*args, **kwargs)
        formula = flop_registry.get(func._overloadpacket)
        if formula is not None:
            self.total += formula(*args, **kwargs, out_val=out)
        return out


#: the domain each block is measured on
CELLS = {"dqn": "mountain_car", "ddpg": "point_maze_umaze"}


def config_for(block: str, frames: int) -> tuple[Any, LearnerDomain]:
    domain = registry.part(CELLS[block], LearnerDomain)
    config = dataclasses.replace(domain.defaults[block], total_frames=frames)
    return dataclasses.replace(config, learning_starts=config.frames_per_batch), domain


def one_learner(block: str, frames: int) -> tuple[int, float, float]:
    """Frames, CPU seconds and FLOPs of one learner trained for ``frames`` frames (each run twice: once
    counted, once timed)."""
    config, domain = config_for(block, frames)
    make_env = domain.env_for(domain_route(domain), 0)
    train = LEARNERS[block].train
    counter = CountFlops()
    with counter:
        train(make_env, config, seeds=[0], observation_key=domain.observation_key)
    start = time.process_time()
    trained = train(make_env, config, seeds=[0], observation_key=domain.observation_key)
    return trained.curve.frames[-1], time.process_time() - start, float(counter.total)


def domain_route(domain: LearnerDomain) -> str:
    return next(iter(load_patterns(domain.participants, domain=domain.name)))


def network_sizes(block: str) -> tuple[int, int]:
    """The observation's and the action's sizes of ``block``'s domain (the MLP's input and output)."""
    _, domain = config_for(block, 1)
    env = domain.env_for(domain_route(domain), 0)(1)
    observation = env.observation_spec[domain.observation_key].shape[-1]
    actions = env.action_spec.shape[-1] if env.action_spec.shape[-1:] != (1,) else int(env.action_spec.space.n)
    env.close()
    return observation, actions


def multiply_rate(block: str, learners: int, repeats: int) -> float:
    """FLOPs per CPU second of a forward and backward pass of ``learners`` stacked MLPs of ``block``'s shape."""
    config, _ = config_for(block, 1)
    inputs, outputs = network_sizes(block)
    sizes = [inputs, *config.hidden, outputs]
    nets = []
    for _ in range(learners):
        layers: list[nn.Module] = []
        for a, b in itertools.pairwise(sizes):
            layers += [nn.Linear(a, b), nn.ReLU()]
        nets.append(nn.Sequential(*layers[:-1]))
    params, buffers = stack_module_state(nets)
    base = nets[0].to("meta")
    x = torch.randn(learners, config.batch_size, inputs)

    def forward(p: dict[str, torch.Tensor], b: dict[str, torch.Tensor], xs: torch.Tensor) -> torch.Tensor:
        return functional_call(base, (p, b), (xs,))

    stacked = torch.vmap(forward)

    def step() -> None:
        out = stacked(params, buffers, x)
        out.square().mean().backward()

    step()
    counter = CountFlops()
    with counter:
        step()
    flops = float(counter.total)
    start = time.process_time()
    for _ in range(repeats):
        step()
    return flops * repeats / (time.process_time() - start)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--blocks", default="dqn,ddpg", help=f"comma-separated blocks ({', '.join(CELLS)})")
    parser.add_argument("--frames", type=int, default=4000, help="frames of the one-learner runs")
    parser.add_argument("--learners", type=int, default=10, help="K of the stacked networks")
    parser.add_argument("--repeats", type=int, default=200, help="passes timed for the multiply rate")
    args = parser.parse_args()
    torch.set_num_threads(1)
    print(
        f"one torch thread; runs of {args.frames:,} and {2 * args.frames:,} frames; "
        f"K = {args.learners} stacked networks\n"
    )
    print("| block | domain | FLOPs per learner frame | multiply rate (GFLOP/s) | one at a time (frames/s) "
          "| arithmetic at that rate | batch can reach at most | batch / one at a time at most |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|")
    for block in [b for b in args.blocks.split(",") if b]:
        if block not in CELLS:
            parser.error(f"--blocks: {block!r} is not one of {', '.join(CELLS)}")
        # the difference of a run of 2F frames and one of F: a learner's steady state (no set-up, no warm-up)
        frames_1, seconds_1, flops_1 = one_learner(block, args.frames)
        frames_2, seconds_2, flops_2 = one_learner(block, 2 * args.frames)
        per_frame = (flops_2 - flops_1) / (frames_2 - frames_1)
        one = (frames_2 - frames_1) / (seconds_2 - seconds_1)
        rate = multiply_rate(block, args.learners, args.repeats)
        peak = rate / per_frame
        share = one * per_frame / rate
        print(
            f"| {block.upper()} | {CELLS[block]} | {per_frame / 1e6:.1f} M | {rate / 1e9:.1f} | {one:,.0f} "
            f"| {share:.0%} of one learner's time | {peak:,.0f} frames/s | {peak / one:.1f} times |"
        )


if __name__ == "__main__":
    main()
