"""Four-rooms A2C, PPO or DQN with the learned potential against the optimal one: is the potential the limit?

Trains the ``recipes/train.py`` set-up of A2C, PPO or DQN on four-rooms (the domain's defaults for
the learner; one learner per shipped participant pattern) three ways:

* **unshaped**;
* **HRS, learned**: the library's shaping, ``V(z)`` learned online in the transform (as
  ``recipes/train.py`` does; ``--per-batch-potential``: one Adam step per batch instead);
* **HRS, optimal**: the same transform over a frozen table holding the optimal values
  ``V*(z)``: the value of the state where the agent enters ``z`` (the start for ``z = 0``,
  subgoal ``z``'s cell after it), from shortest paths to the goal (moves are deterministic).

Under ``--task goal`` (the paper's +1 at the goal, 0 otherwise) ``V*(c) = γ^(d(c) − 1)``; under
``--task step`` (−1 per step, 0 at the goal) ``V*(c) = −(1 − γ^(d(c) − 1)) / (1 − γ)``, with
``d(c)`` the shortest number of steps from cell ``c`` to the goal. Prints frames until the mean
episode length first falls below 100 and 50 steps (mean and s.d. over learners; a learner that
never does counts as the budget), how many never did, Holm-corrected Welch tests against the
unshaped learner, the final episode length, and the learned tables beside the optimal ones.

    python tools/four_rooms_optimal_potential.py --algo a2c --task goal     # 30 learnings, ~5 CPU-minutes
    python tools/four_rooms_optimal_potential.py --algo a2c --task step    # 300,032 frames: the four_rooms_step default
    python tools/four_rooms_optimal_potential.py --algo ppo --task step --learners 5
    python tools/four_rooms_optimal_potential.py --task step --conditions learned --sees-subgoal yes
    python tools/four_rooms_optimal_potential.py --algo ppo --task step --conditions learned --per-batch-potential
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import sys

import numpy as np
import torch
from scipy import stats
from statsmodels.stats.multitest import multipletests

from torchrl_subgoal import SubgoalSeries, domains, load_patterns
from torchrl_subgoal.envs import four_rooms
from torchrl_subgoal.methods import Method, shaping_parts
from torchrl_subgoal.training import LEARNERS, LearnerDomain, Shaping

CONDITIONS = ("unshaped", "HRS, learned", "HRS, optimal")
#: the ``--conditions`` names (``monotone``: learned, shaped with the table made non-decreasing along the series)
SHORT = {"unshaped": "unshaped", "learned": "HRS, learned", "optimal": "HRS, optimal", "monotone": "HRS, monotone"}
THRESHOLDS = (100.0, 50.0)


def optimal_values(series: SubgoalSeries, task: str, gamma: float) -> list[float]:
    """``V*(z)`` for z = 0 (the start) and each subgoal's cell, under ``task`` (``"goal"`` or ``"step"``)."""
    distance = four_rooms.goal_distances()
    cells = [four_rooms.START] + [(int(p.row), int(p.col)) for p in series.predicates]  # type: ignore[attr-defined]
    if task == "goal":
        return [gamma ** (distance[c] - 1) for c in cells]
    return [-(1 - gamma ** (distance[c] - 1)) / (1 - gamma) for c in cells]


def learner_domain(task: str) -> LearnerDomain:
    """The registered set-up of ``task``: ``four_rooms`` (the paper's goal reward) or ``four_rooms_step``."""
    return domains.part("four_rooms" if task == "goal" else "four_rooms_step", LearnerDomain)


def run(
    algo: str,
    task: str,
    learners: int,
    total_frames: int,
    conditions: tuple[str, ...] = CONDITIONS,
    sees: str = "default",
    value_lr: float = 0.0,
    per_batch: bool = False,
) -> dict[str, list[dict]]:
    """Every condition's learners: frames to each threshold, final length, learned table (``sees``: whether
    the shaped learners' networks also read ``z``: ``"yes"``, ``"no"`` or the learner's ``"default"``)."""
    domain = learner_domain(task)
    learner = LEARNERS[algo]
    config = domain.defaults[algo]
    if total_frames:
        config = dataclasses.replace(config, total_frames=total_frames)
    if value_lr:
        config = dataclasses.replace(config, value_lr=value_lr)
    if per_batch:
        config = dataclasses.replace(config, online_potential=False)
    patterns = list(load_patterns(domain.participants, domain="four_rooms").values())
    results: dict[str, list[dict]] = {name: [] for name in conditions}
    for condition in conditions:
        for i in range(learners):
            series = patterns[i % len(patterns)]
            # in the learner's reward units, as its table is (the env's reward times its reward_scale)
            optimal = [config.reward_scale * v for v in optimal_values(series, task, config.gamma)]
            shaping = None
            if condition != "unshaped":
                parts = shaping_parts(
                    Method("HRS", "subgoals", "human"),
                    (),
                    patterns=[series],
                    observation_key=domain.subgoal_key,
                    monotone_potential=condition == "HRS, monotone",
                )
                assert parts is not None
                _, potential, options = parts
                if condition == "HRS, optimal":
                    potential.freeze(optimal)
                shaping = Shaping(series, potential, options)
            curve = learner.train(
                domain.make_env,
                config
                if sees == "default"
                else dataclasses.replace(config, sees_subgoal=sees == "yes" and shaping is not None),
                shaping=shaping,
                observation_key=domain.observation_key,
                seeds=[1000 + i],
            ).curve
            final = max(1, len(curve.frames) // 20)
            results[condition].append(
                {
                    "frames": [curve.frames_to(t) for t in THRESHOLDS],
                    "final": float(np.mean(curve.episode_length[-final:])),
                    "table": shaping.potential.table.detach().view(-1).tolist() if shaping else None,
                    "optimal": optimal,
                }
            )
            print(f"{condition} {i}: {results[condition][-1]}", file=sys.stderr, flush=True)
    return results


def report(results: dict[str, list[dict]], budget: int) -> None:
    """The comparison as markdown tables on stdout."""
    print("| condition | " + " | ".join(f"frames to < {t:g} (never)" for t in THRESHOLDS) + " | final length |")
    print("|---|" + "---|" * (len(THRESHOLDS) + 1))
    frames = {
        name: np.array([[f if f is not None else budget for f in r["frames"]] for r in rows])
        for name, rows in results.items()
    }
    for name, rows in results.items():
        cells = []
        for k in range(len(THRESHOLDS)):
            never = sum(r["frames"][k] is None for r in rows)
            cells.append(f"{frames[name][:, k].mean():,.0f} ({frames[name][:, k].std(ddof=1):,.0f}; {never})")
        final = [r["final"] for r in rows]
        print(f"| {name} | " + " | ".join(cells) + f" | {np.mean(final):.1f} ({np.std(final, ddof=1):.1f}) |")
    print()
    shaped = [name for name in results if name != "unshaped"] if "unshaped" in results else []
    raw = [
        stats.ttest_ind(frames["unshaped"][:, k], frames[name][:, k], equal_var=False).pvalue
        for name in shaped
        for k in range(len(THRESHOLDS))
    ]
    holm = multipletests(np.nan_to_num(raw, nan=1.0), method="holm")[1] if raw else []
    for j, name in enumerate(shaped):
        ratios = [frames["unshaped"][:, k].mean() / frames[name][:, k].mean() for k in range(len(THRESHOLDS))]
        line = ", ".join(
            f"< {t:g}: {ratio:.2f}x (Holm p = {holm[j * len(THRESHOLDS) + k]:.2g})"
            for k, (t, ratio) in enumerate(zip(THRESHOLDS, ratios, strict=True))
        )
        print(f"* unshaped / {name}: {line}")
    if "HRS, learned" not in results:
        return
    learned = np.array([r["table"] for r in results["HRS, learned"]])
    optimal = np.array([r["optimal"] for r in results["HRS, learned"]])
    print("\n| z | optimal V*(z), mean | learned V(z) at the end, mean (s.d.) |\n|---|---|---|")
    for z in range(learned.shape[1]):
        print(f"| {z} | {optimal[:, z].mean():.3f} | {learned[:, z].mean():.3f} ({learned[:, z].std(ddof=1):.3f}) |")


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0] if __doc__ else None)
    parser.add_argument("--algo", choices=("a2c", "ppo", "dqn"), default="a2c")
    parser.add_argument("--task", choices=("goal", "step"), default="goal")
    parser.add_argument("--learners", type=int, default=10, help="learners per condition (one per pattern, cycled)")
    parser.add_argument("--total-frames", type=int, default=0, help="frames per learner (0: the domain's default)")
    parser.add_argument(
        "--conditions", default="unshaped,learned,optimal", help="any of unshaped, learned, optimal, monotone"
    )
    parser.add_argument(
        "--sees-subgoal",
        choices=("default", "yes", "no"),
        default="default",
        help="the shaped learners' networks also read z (default: the learner's: DQN's Q-network, A2C's and PPO's "
        "critic)",
    )
    parser.add_argument(
        "--value-lr", type=float, default=0.0, help="the potential's step size (0: the learner's default)"
    )
    parser.add_argument(
        "--per-batch-potential",
        action="store_true",
        help="train V(z) by one Adam step of value_lr per batch (default: online, value_lr x the error per transition)",
    )
    opts = parser.parse_args(argv)
    names = [name.strip() for name in opts.conditions.split(",") if name.strip()]
    unknown = [name for name in names if name not in SHORT]
    if unknown or not names:
        parser.error(f"--conditions: expected some of {', '.join(SHORT)}, got {opts.conditions!r}")
    if opts.learners < 2:
        parser.error(f"--learners: at least 2 (the tests need a spread), got {opts.learners}")
    torch.set_num_threads(1)
    logging.getLogger("torchrl").setLevel(logging.WARNING)  # its buffers' set-up notes would mix into the tables
    budget = opts.total_frames or learner_domain(opts.task).defaults[opts.algo].total_frames
    sees = {"yes": ", the shaped learners see z", "no": ", the shaped learners do not see z"}.get(opts.sees_subgoal, "")
    print(
        f"four-rooms ({opts.task} reward), {opts.algo.upper()}, {opts.learners} learners per condition, "
        f"{budget:,} frames each{sees}\n"
    )
    conditions = tuple(SHORT[name] for name in names)
    if opts.value_lr < 0:
        parser.error(f"--value-lr: must be >= 0, got {opts.value_lr}")
    results = run(
        opts.algo,
        opts.task,
        opts.learners,
        opts.total_frames,
        conditions,
        opts.sees_subgoal,
        opts.value_lr,
        opts.per_batch_potential,
    )
    report(results, budget)
    return 0


if __name__ == "__main__":
    sys.exit(main())
