"""The learners by name: each building block's settings class, its training function and the actions it needs.

``LEARNERS["ppo"].train(make_env, config, seeds=..., shaping=...)`` is
:func:`~torchrl_subgoal.training.train_ppo`; a sweep over learners (the
``torchrl-subgoal train`` recipe) reads its algorithm here and checks, before
anything runs, that the env's actions suit it (:func:`check_actions`).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Literal

import torch
from torch import nn
from torchrl.data import Bounded, Categorical, OneHot
from torchrl.envs import EnvBase

from torchrl_subgoal.training.a2c import A2CConfig, train_a2c
from torchrl_subgoal.training.batch import batch_shaping
from torchrl_subgoal.training.ddpg import DDPGTrainConfig, ddpg_modules, train_ddpg
from torchrl_subgoal.training.dqn import DQNConfig, dqn_modules, train_dqn
from torchrl_subgoal.training.envs import Shaping, close_probe, probe_env
from torchrl_subgoal.training.on_policy import actor_critic_modules
from torchrl_subgoal.training.ppo import PPOConfig, train_ppo
from torchrl_subgoal.training.recording import LearningCurve
from torchrl_subgoal.training.result import Trained

__all__ = ["LEARNERS", "Actions", "Learner", "action_kind", "check_actions", "load_trained"]

Actions = Literal["discrete", "continuous"]


@dataclass(frozen=True)
class Learner:
    """One building block, by name.

    Attributes:
        name: ``"a2c"``, ``"ppo"``, ``"dqn"`` or ``"ddpg"``.
        config: its settings class (:class:`~torchrl_subgoal.training.A2CConfig`, …).
        train: ``train(make_env, config, *, seeds, shaping, observation_key, loggers, progress, ...) -> Trained``,
            ``len(seeds)`` learners as one batch.
        actions: the action kinds it handles.
        modules: ``modules(env, config, observation_key, subgoal_states, seeds)``, the block's networks over
            ``len(seeds)`` learners (what :func:`load_trained` rebuilds).

    Examples:
        >>> LEARNERS["dqn"].actions, LEARNERS["ppo"].actions
        (('discrete',), ('discrete', 'continuous'))
    """

    name: str
    config: type
    train: Callable[..., Trained]
    actions: tuple[Actions, ...]
    modules: Callable[..., dict[str, nn.Module]]

    def has_setting(self, name: str) -> bool:
        """Whether the learner's settings have a field ``name``.

        Examples:
            >>> LEARNERS["dqn"].has_setting("reshape_samples"), LEARNERS["ppo"].has_setting("reshape_samples")
            (True, False)
        """
        return name in {f.name for f in dataclasses.fields(self.config)}

    @property
    def title(self) -> str:
        """The name the results and reports give the unshaped learner (``"PPO"``)."""
        return self.name.upper()


#: Every building block, by the name ``torchrl-subgoal train --algo`` takes.
LEARNERS: dict[str, Learner] = {
    learner.name: learner
    for learner in (
        Learner("a2c", A2CConfig, train_a2c, ("discrete",), actor_critic_modules),
        Learner("ppo", PPOConfig, train_ppo, ("discrete", "continuous"), actor_critic_modules),
        Learner("dqn", DQNConfig, train_dqn, ("discrete",), dqn_modules),
        Learner("ddpg", DDPGTrainConfig, train_ddpg, ("continuous",), ddpg_modules),
    )
}


def action_kind(env: EnvBase) -> Actions | None:
    """``"discrete"`` (``Categorical``, ``OneHot``), ``"continuous"`` (``Bounded`` floats) or ``None``.

    Examples:
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> action_kind(FourRoomsEnv(1))
        'discrete'
    """
    spec: Any = env.full_action_spec_unbatched[env.action_key]
    if isinstance(spec, Categorical | OneHot):
        return "discrete"
    if isinstance(spec, Bounded) and spec.dtype.is_floating_point:
        return "continuous"
    return None


def check_actions(algo: str, env: EnvBase, domain: str) -> None:
    """Refuse a learner whose action kind ``env`` does not have, in one line naming the learners that fit.

    Raises:
        ValueError: ``algo`` is unknown, or the env's actions do not suit it.

    Examples:
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> check_actions("ddpg", FourRoomsEnv(1), "four_rooms")
        Traceback (most recent call last):
        ...
        ValueError: ddpg needs continuous actions; four_rooms's are discrete: choose a2c, ppo or dqn
    """
    if algo not in LEARNERS:
        raise ValueError(f"unknown learner {algo!r}; known: {', '.join(LEARNERS)}")
    kind = action_kind(env)
    if kind in LEARNERS[algo].actions:
        return
    fits = [name for name, learner in LEARNERS.items() if kind in learner.actions]
    choose = (
        f"choose {', '.join(fits[:-1])} or {fits[-1]}"
        if len(fits) > 1
        else (f"choose {fits[0]}" if fits else "no learner here handles them")
    )
    raise ValueError(
        f"{algo} needs {' or '.join(LEARNERS[algo].actions)} actions; {domain}'s are "
        f"{kind or 'neither discrete nor bounded continuous'}: {choose}"
    )


def load_trained(path: str | Path, make_env: Callable[[int], EnvBase], *, shaping: Shaping | None = None) -> Trained:
    """What :meth:`Trained.save <torchrl_subgoal.training.Trained.save>` wrote, rebuilt on ``make_env``'s specs
    (on the CPU), by the learner's own ``modules``.

    Args:
        path: the saved file.
        make_env: the env factory the learners trained on (one learner's, for its specs).
        shaping: the shaping the learners trained with (its subgoals; the saved tables are loaded into it),
            needed to evaluate a policy that reads the subgoal index.

    Examples:
        >>> load_trained("no/such/file.pt", None)  # doctest: +ELLIPSIS
        Traceback (most recent call last):
        ...
        FileNotFoundError: ...
    """
    saved = torch.load(path, map_location="cpu", weights_only=True)
    learner = LEARNERS[saved["algo"]]
    config = learner.config(**{**saved["config"], "device": "cpu"})
    env, _ = probe_env(make_env)
    try:
        modules = learner.modules(env, config, saved["observation_key"], saved["subgoal_states"], saved["seeds"])
    finally:
        close_probe(env)
    for name, state in saved["modules"].items():
        modules[name].load_state_dict(state)
    if shaping is not None and saved["potential"] is not None:
        shaping = batch_shaping([shaping] * len(saved["seeds"]), config.num_envs)
        assert shaping is not None
        shaping.potential.load_state_dict(saved["potential"])
    curves = [LearningCurve(**c) for c in saved["curves"]]
    return Trained(
        saved["algo"], config, list(saved["seeds"]), curves, modules, saved["observation_key"], saved["subgoal_states"],
        shaping,
    )  # fmt: skip
