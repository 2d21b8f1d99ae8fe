"""One potential for envs in collector worker processes (shared memory)."""

from __future__ import annotations

import pickle

import cloudpickle
import torch
from torchrl.collectors import MultiSyncCollector
from torchrl.envs import TransformedEnv

from torchrl_subgoal import Cell, SubgoalPotentialTransform, SubgoalSeries, TabularPotential
from torchrl_subgoal.envs import FourRoomsEnv
from torchrl_subgoal.training import EnvFactory, close_collector

SERIES = SubgoalSeries([Cell(1, 2), Cell(1, 3)])


def shaped_four_rooms(potential: TabularPotential) -> TransformedEnv:
    """Module level: what each collector worker builds."""
    t = SubgoalPotentialTransform(SERIES, potential, gamma=0.9, observation_key="cell")
    return TransformedEnv(FourRoomsEnv(3, max_steps=25), t)


def test_factory_sends_modules_as_shared_memory_even_through_cloudpickle() -> None:
    potential = TabularPotential(3)
    factory = EnvFactory(dict, potential=potential, label="x")
    copy = pickle.loads(cloudpickle.dumps(factory))  # as TorchRL's CloudpickleWrapper sends it
    received = copy()["potential"]
    with torch.no_grad():
        potential.table.add_(2.0)
    assert received is not potential and torch.equal(received.table, potential.table)
    assert copy()["label"] == "x"


def test_multisync_collector_workers_shape_with_the_trained_potential() -> None:
    """Two worker processes; the potential is trained (here: set) in the main process between
    batches. Every worker's shaping F = γΦ(z') − Φ(z) uses the table as updated before the batch
    (a MultiSyncCollector's workers wait while the main process trains: no staleness)."""
    potential = TabularPotential(3)
    collector = MultiSyncCollector(
        [EnvFactory(shaped_four_rooms, potential=potential)] * 2,
        None,
        frames_per_batch=150,
        total_frames=750,
        cat_results="stack",
    )
    seen_shaping = 0
    try:
        for i, data in enumerate(collector):
            table = potential.table.detach().clone()
            nxt = data["next"]
            z, z_next = data["subgoal_index"], nxt["subgoal_index"]
            expected = nxt["env_reward"] + 0.9 * table[z_next].masked_fill(nxt["terminated"], 0) - table[z]
            assert torch.allclose(nxt["reward"], expected, atol=1e-6), f"batch {i}: workers shaped with a stale table"
            for worker in range(2):  # every worker shaped, with the trained values
                moved = (z_next != z)[worker]
                seen_shaping += int(moved.any() and i > 0)
            with torch.no_grad():  # "train": a new table for the next batch
                potential.table.copy_(torch.tensor([0.0, 1.0 + i, 3.0 * (i + 1)]))
    finally:
        close_collector(collector)
    assert seen_shaping >= 2
