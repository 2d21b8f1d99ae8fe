"""A2C on TorchRL collectors with subgoal shaping: four-rooms or PinBall, against the paper's baselines.

Each learner is one A2C agent (TorchRL's ``A2CLoss`` with ``GAE``; policy and
value ``TensorDictModule`` s: a one-hot table for four-rooms, a Fourier basis
for PinBall) trained on batches from a ``Collector`` over ``--num-envs`` envs
(a ``ParallelEnv`` with ``--env-workers``; a ``MultiSyncCollector`` with
``--collector-workers``; every field of ``A2CConfig`` is a flag). The shaping transform sits on the outer env; its
potential is shared with the main process, where ``SubgoalValueLoss`` trains
it from each batch's SMDP transitions with its own optimiser (``--online-potential``:
the transform's per-step update instead). Methods: plain A2C, HRS, RRS, NRS and
SARSA-RS from the same subgoal files as the SARSA / actor-critic recipes.

Learners run through the experiment engine (resumable; the same report and
statistics); one report column is one A2C update (a collected batch of
``--frames-per-batch`` frames), whose metric is the mean episode length (frames per
finished episode over the last 8 batches); the report gives times to threshold in
updates and in frames. ``recipes/train.py --algo a2c`` runs the same learners on any
domain with the library's shaping defaults; this recipe keeps the A2C flags and the
settings of the figures in docs/torchrl.md.
Each learner's TorchRL log goes to ``RESULTS/logs`` (``--logger csv``, ``tensorboard``, ``wandb`` or ``none``).

    python recipes/a2c.py --domain four_rooms                 # plain vs HRS vs SARSA-RS, 10 learners each
    python recipes/a2c.py --domain pinball --total-frames 2000000
"""

from __future__ import annotations

import sys
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, ClassVar

from torchrl_subgoal.experiments.cli import setting
from torchrl_subgoal.experiments.learners import LearnerRecipeConfig, learner_methods, learner_plan
from torchrl_subgoal.experiments.recipe import Plan, recipe_main

METHODS = learner_methods("a2c")


@dataclass
class Config(LearnerRecipeConfig):
    """A2C with subgoal shaping on TorchRL collectors."""

    domain: str = setting("four_rooms", "four_rooms or pinball", choices=["four_rooms", "pinball"])
    methods: str = setting("A2C,HRS,SARSA-RS", "comma-separated methods: " + ", ".join(METHODS))
    learnings: int = setting(1, "learnings per subgoal pattern (10 patterns: 10 learners per method)")
    start_potential: str = setting(
        "value",
        "level of Φ: value (Φ = V; docs/torchrl.md's figures), zero or "
        "nonpositive (the library default; docs/shaping_defaults.md)",
        choices=["value", "zero", "nonpositive"],
    )
    results: str = setting("", "results directory (re-run to resume)", shown_default="results/a2c_<domain>")

    ALGO: ClassVar[str | None] = "a2c"
    #: the settings of docs/torchrl.md's figures: 16 envs, 256-frame updates, the potential trained per batch
    LEARNER_DEFAULTS: ClassVar[Mapping[str, Any]] = {
        "num_envs": 16,
        "frames_per_batch": 256,
        "normalize_advantage": False,
        "online_potential": False,
    }


def plan(cfg: Config) -> Plan:
    """The sweep of ``cfg``: one chunk per learner, the stored configuration, the report's thresholds."""
    return learner_plan(cfg, "a2c", final_updates=10)


def main(argv: list[str] | None = None) -> int:
    return recipe_main(Config, plan, argv, description=__doc__.splitlines()[0] if __doc__ else None, threads=None)


if __name__ == "__main__":
    sys.exit(main())
