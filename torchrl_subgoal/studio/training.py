"""The studio's "Try it": a short learning with one drawn pattern against the unshaped baseline.

Everything the studio trains goes through :func:`try_pattern`, built from the
library's pieces: the domain's batched env and the paper's learner, both from
its registration (the ``learner`` of its :class:`~torchrl_subgoal.studio.domains.StudioDomain`: SARSA on
four-rooms, the Fourier actor-critic on PinBall), the shaping transform of the chosen method
(HRS-D, the default, HRS, SRS or NRS) from :func:`torchrl_subgoal.methods.shaping_transform` and
:func:`torchrl_subgoal.fused.run_episodes` on the fused engine. Both runs use
the same seeds, so the two curves differ only by the shaping. This is the one
place to update when the engine's interface changes.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import torch
from torchrl.envs import TransformedEnv

from torchrl_subgoal import registry
from torchrl_subgoal.fused import run_episodes
from torchrl_subgoal.methods import HRS_D, SRS, paper_methods, shaping_transform
from torchrl_subgoal.potentials import TabularPotential
from torchrl_subgoal.studio.domains import studio_domain
from torchrl_subgoal.subgoals import SubgoalSeries
from torchrl_subgoal.transform import SubgoalPotentialTransform

__all__ = ["METHODS", "Curve", "TryResult", "TrySettings", "try_pattern"]

#: The shaped methods a "Try it" offers: HRS-D (the library's default potential: learned, and rising towards the
#: next subgoal within each segment), HRS (learned, over the subgoals reached alone), SRS (the progress prior,
#: fixed) and NRS (the naive pulse).
METHODS = {
    HRS_D.name: HRS_D,
    "HRS": paper_methods(baseline="none")["HRS"],
    "SRS": SRS,
    "NRS": paper_methods(baseline="none")["NRS"],
}
Progress = Callable[[int], None]


@dataclass(frozen=True)
class TrySettings:
    """How long a "Try it" learns.

    Attributes:
        episodes: episodes per learner.
        learners: independent learners per method (the batch).
        seed: seed of the envs and learners (the same for both methods).
        max_steps: episode cap (``None``: the domain's default).

    Examples:
        >>> settings = TrySettings(episodes=50, learners=4)
        >>> settings.seed, settings.max_steps
        (0, None)
    """

    episodes: int
    learners: int
    seed: int = 0
    max_steps: int | None = None


@dataclass
class Curve:
    """Steps per episode, mean and standard error over the learners, one entry per episode.

    Examples:
        >>> curve = Curve.of(torch.tensor([[3, 5], [5, 7]]), torch.tensor([[True, True], [False, True]]))
        >>> curve.mean, curve.sem, curve.success
        ([4.0, 6.0], [1.0, 1.0], 0.75)
    """

    mean: list[float]
    sem: list[float]
    success: float  # fraction of episodes that reached the goal

    @classmethod
    def of(cls, steps: torch.Tensor, success: torch.Tensor) -> Curve:
        """From ``[learners, episodes]`` records."""
        s = steps.double()
        n = s.shape[0]
        sem = s.std(0, unbiased=True) / math.sqrt(n) if n > 1 else torch.zeros(s.shape[1], dtype=s.dtype)
        return cls(s.mean(0).tolist(), sem.tolist(), float(success.double().mean()))


@dataclass
class TryResult:
    """What the page draws: both learning curves and the learned potential ``V(z)``.

    Attributes:
        shaped: steps per episode with the drawn subgoals.
        baseline: steps per episode without shaping.
        potential: mean over learners of the table ``V(z)`` at the end (learned for HRS, the fixed
            prior for SRS; empty for NRS), ``z = 0..n`` (``z = 0`` before any subgoal, ``z = i + 1``
            once subgoal ``i`` is achieved).
        potential_sem: its standard error over learners.
        method: the shaped learners' method.
        settings: the settings of the run.
        seconds: wall time of both runs.

    Examples:
        >>> curve = Curve([4.0, 6.0], [1.0, 1.0], 1.0)
        >>> result = TryResult(curve, curve, potential=[0.0, 0.5], potential_sem=[0.0, 0.1])
        >>> result.to_json()["shaped"]["mean"]
        [4.0, 6.0]
    """

    shaped: Curve
    baseline: Curve
    potential: list[float]
    potential_sem: list[float]
    settings: dict[str, Any] = field(default_factory=dict)
    seconds: float = 0.0
    method: str = "HRS-D"

    def to_json(self) -> dict[str, Any]:
        """A JSON-ready dict."""
        return asdict(self)


def try_pattern(
    domain: str,
    series: SubgoalSeries,
    settings: TrySettings,
    *,
    method: str = "HRS-D",
    map: str | Path | None = None,
    progress: Progress | None = None,
) -> TryResult:
    """Learn with ``series`` (shaped by ``method``) and without shaping, same seeds, on the fused engine.

    Args:
        domain: a registered domain whose studio part has a learner:
            ``"four_rooms"``, ``"pinball"``.
        series: the drawn pattern.
        settings: episodes, learners, seed, episode cap.
        method: ``"HRS-D"`` (default), ``"HRS"``, ``"SRS"`` or ``"NRS"`` (:data:`METHODS`).
        map: the PinBall map (``"simple"``, ``"hard"`` or a file); ignored by four-rooms.
        progress: called with the number of learner-episodes just finished
            (``2 * learners * episodes`` in all); it may raise to cancel.

    Returns:
        Both curves and the learned potential.

    Examples:
        >>> from torchrl_subgoal.subgoals import Cell
        >>> series = SubgoalSeries([Cell(3, 6), Cell(7, 9)], name="hallways")
        >>> result = try_pattern("four_rooms", series, TrySettings(episodes=3, learners=2))
        >>> len(result.shaped.mean), len(result.potential)
        (3, 3)
        >>> [round(v, 3) for v in try_pattern("four_rooms", series, TrySettings(3, 2), method="SRS").potential]
        [0.0, 0.333, 0.667]
    """
    if method not in METHODS:
        raise ValueError(f"method: expected one of {list(METHODS)}, got {method!r}")
    found = studio_domain(domain)
    if found is None or found.learner is None:
        problem = "unknown domain" if registry.find(domain) is None else "no learner (StudioDomain.learner) for domain"
        with_learner = [name for name in registry.names() if (view := studio_domain(name)) and view.learner]
        raise ValueError(f"{problem} {domain!r}; known: {with_learner}")
    learner = found.learner
    start = time.perf_counter()
    curves: dict[str, Curve] = {}
    transform: SubgoalPotentialTransform | None = None
    for label in ("baseline", "shaped"):
        env, agent, shaping = learner(
            settings.learners, settings.seed, settings.max_steps, None if map is None else str(map)
        )
        if label == "shaped":
            transform = shaping_transform(
                METHODS[method],
                env.batch_size,
                gamma=shaping["gamma"],
                value_lr=shaping["value_lr"],
                patterns=[series],
                pattern_index=torch.zeros(settings.learners, dtype=torch.long),
                observation_key=shaping["observation_key"],
                eta=shaping.get("goal_reward", 1.0),
                progress_scale=shaping.get("goal_reward", 1.0),
            )
            assert transform is not None
            env = TransformedEnv(env, transform)
        records = run_episodes(env, agent, settings.episodes, progress=progress, engine="fused")
        curves[label] = Curve.of(records.steps, records.success)
    assert transform is not None
    if isinstance(transform.potential, TabularPotential):
        table = transform.potential.table.detach().double().reshape(settings.learners, -1)
    else:  # NRS: no table
        table = torch.zeros(settings.learners, 0, dtype=torch.double)
    sem = table.std(0) / math.sqrt(settings.learners) if settings.learners > 1 else torch.zeros(table.shape[1])
    return TryResult(
        shaped=curves["shaped"],
        baseline=curves["baseline"],
        potential=table.mean(0).tolist(),
        potential_sem=sem.tolist(),
        settings={**asdict(settings), "domain": domain, "map": str(map or "")},
        seconds=time.perf_counter() - start,
        method=method,
    )
