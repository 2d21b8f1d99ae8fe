"""The entries the shaping transform keeps and reads: their names, the env keys resolved from the parent
env, their specs, and the unchecked reads and writes of the per-step path."""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any, NamedTuple

import torch
from tensordict import TensorDictBase
from tensordict.utils import NestedKey
from torchrl.data import Binary, Bounded, Composite, TensorSpec, Unbounded
from torchrl.envs import EnvBase

__all__ = [
    "EnvKeys",
    "SubgoalKeys",
    "add_env_reward",
    "at",
    "declare",
    "kept_specs",
    "observation",
    "read",
    "state_specs",
    "transition_spec",
    "write",
]

RETURN = "subgoal_return"
STEPS = "subgoal_steps"
ENV_REWARD = "env_reward"


def _named(role: str, doc: str) -> functools.cached_property[str]:
    """The entry of ``role``: ``f"{prefix}_{role}"``, computed once per :class:`SubgoalKeys`."""
    entry: functools.cached_property[str] = functools.cached_property(lambda keys: f"{keys.prefix}_{role}")
    entry.__doc__ = doc
    return entry


@dataclass(frozen=True)
class SubgoalKeys:
    """Names of the abstract-state entries one transform keeps: ``f"{prefix}_{role}"``.

    Give a second transform on the same env another prefix (and its potential
    the matching keys) so that the two do not share entries.

    Args:
        prefix: the names' prefix (``"subgoal"``).

    Examples:
        >>> SubgoalKeys("room").index
        'room_index'
    """

    prefix: str = "subgoal"

    index = _named("index", "``z``, the node of the subgoal series reached.")
    ret = _named("return", "``r_h``, the discounted reward since ``z`` was entered.")
    steps = _named("steps", "``k``, the steps since ``z`` was entered.")
    achieved = _named("achieved", "Whether ``z`` was entered on this step.")
    anchor = _named("anchor", "The observation at which ``z`` was entered.")
    learner = _named("learner", "Which env of the batch the row belongs to (its learner).")
    start = _named(
        "start", "The potential's input at reset (``z_0`` of an aggregation, ``o_0`` of a neural potential)."
    )

    @functools.cached_property
    def optional(self) -> tuple[str, ...]:
        """The entries kept only when the potential reads them."""
        return (self.achieved, self.anchor, self.learner)


def at(group: tuple[str, ...], name: str) -> NestedKey:
    """The entry ``name`` of the group ``group`` (``()``: the root).

    Examples:
        >>> at((), "subgoal_index"), at(("agents",), "subgoal_index")
        ('subgoal_index', ('agents', 'subgoal_index'))
    """
    return (*group, name) if group else name


def _root(key: NestedKey) -> tuple[str, ...]:
    return tuple(key[:-1]) if isinstance(key, tuple) else ()


def _last(key: NestedKey) -> str:
    return key[-1] if isinstance(key, tuple) else key


class EnvKeys(NamedTuple):
    """The env's entries one transform reads and writes, resolved from its parent env as TorchRL's
    ``RewardSum`` and ``StepCounter`` resolve theirs: the reward, and the done and terminated entries
    of the reset group the reward belongs to (``group``: ``()`` at the root, ``("agents",)`` for
    nested, multi-agent keys). The kept abstract state lives in that group.

    Examples:
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> EnvKeys.resolve(FourRoomsEnv(2))
        EnvKeys(group=(), reward='reward', env_reward='env_reward', done='done', terminated='terminated', ...)
    """

    group: tuple[str, ...]  #: where the kept entries live
    reward: NestedKey  #: the reward shaped
    env_reward: NestedKey  #: where the unshaped reward is kept
    done: NestedKey
    terminated: NestedKey  #: the done entry when the env has no terminated one
    shaped_before: bool  #: an earlier shaping transform keeps the unshaped reward already

    @classmethod
    def resolve(cls, parent: EnvBase | None) -> EnvKeys:
        """The keys of ``parent`` (``None``: the defaults, for stored data without an env).

        Raises:
            ValueError: the env has several rewards, or none whose done entry this transform can read.
        """
        if parent is None:
            return cls((), "reward", ENV_REWARD, "done", "terminated", False)
        rewards = [k for k in parent.reward_keys if _last(k) != ENV_REWARD]
        if len(rewards) != 1:
            raise ValueError(
                f"SubgoalPotentialTransform shapes one reward; the env has {rewards}: combine them into "
                "one entry first (a transform before this one)"
            )
        reward = rewards[0]
        roots = [_root(k) for k in parent._filtered_reset_keys]
        group = max((r for r in roots if _root(reward)[: len(r)] == r), key=len, default=None)
        if group is None:
            raise ValueError(
                f"SubgoalPotentialTransform: no done entry of the env ({parent.done_keys}) covers the reward {reward!r}"
            )
        done, terminated = at(group, "done"), at(group, "terminated")
        done_keys = [k if isinstance(k, str) or len(k) > 1 else k[0] for k in parent.done_keys]
        if done not in done_keys:
            raise ValueError(
                f"SubgoalPotentialTransform reads the done entry {done!r}, which the env lacks; "
                f"its done entries: {parent.done_keys}"
            )
        env_reward = at(_root(reward), ENV_REWARD)
        shaped_before = env_reward in [k if isinstance(k, str) or len(k) > 1 else k[0] for k in parent.reward_keys]
        return cls(group, reward, env_reward, done, terminated if terminated in done_keys else done, shaped_before)


def read(td: TensorDictBase, key: NestedKey) -> Any:
    """``td``'s entry ``key``, or ``None``: TensorDict's unchecked read, as TorchRL's ``step_mdp`` reads.

    Examples:
        >>> from tensordict import TensorDict
        >>> td = TensorDict({"a": torch.zeros(2, 1)}, [2])
        >>> read(td, "a").shape, read(td, ("b", "c"))
        (torch.Size([2, 1]), None)
    """
    return td._get_str(key, None) if type(key) is str else td._get_tuple(key, None)


def write(td: TensorDictBase, key: NestedKey, value: torch.Tensor) -> None:
    """Set ``td[key] = value`` without TensorDict's checks (``value`` fits by construction), as TorchRL's
    ``step_mdp`` writes.

    Examples:
        >>> from tensordict import TensorDict
        >>> td = TensorDict({}, [2])
        >>> write(td, "a", torch.ones(2, 1))
        >>> td["a"].sum().item()
        2.0
    """
    if type(key) is str:
        td._set_str(key, value, inplace=False, validated=True)
    else:
        td._set_tuple(key, value, inplace=False, validated=True)


def state_specs(
    keys: SubgoalKeys,
    kept: tuple[str, ...],
    num_states: int,
    shape: torch.Size,
    anchor: TensorSpec | None,
) -> dict[str, TensorSpec]:
    """The specs of the ``kept`` abstract-state entries, each ``[*shape, 1]`` (the anchor ``[*shape, D]``),
    ``anchor`` the spec of the observation the anchor snapshots.

    Examples:
        >>> specs = state_specs(SubgoalKeys(), ("subgoal_index", "subgoal_return"), 3, torch.Size([4]), None)
        >>> specs["subgoal_index"].shape, specs["subgoal_return"].dtype
        (torch.Size([4, 1]), torch.float32)
    """
    col = (*shape, 1)
    specs: dict[str, TensorSpec] = {
        keys.index: Bounded(0, num_states - 1, shape=col, dtype=torch.long),
        keys.ret: Unbounded(shape=col, dtype=torch.float32),
        keys.steps: Unbounded(shape=col, dtype=torch.long),
    }
    if keys.achieved in kept:
        specs[keys.achieved] = Binary(n=1, shape=col, dtype=torch.bool)
    if keys.learner in kept:
        specs[keys.learner] = Bounded(0, max(shape.numel() - 1, 0), shape=col, dtype=torch.long)
    if keys.anchor in kept:
        assert anchor is not None
        size = anchor.shape[len(shape) :].numel() if len(anchor.shape) > len(shape) else 1
        specs[keys.anchor] = Unbounded(shape=(*shape, size), dtype=torch.float32)
    if keys.start in kept:  # what the potential reads at reset: the anchor or z_0
        specs[keys.start] = specs[keys.anchor if keys.anchor in kept else keys.index].clone()
    return specs


def transition_spec(inputs: dict[str, TensorSpec], shape: torch.Size) -> Composite:
    """The spec of one step's SMDP transition entry (the potential's ``inputs`` at ``z`` and ``z'``).

    Examples:
        >>> from torchrl.data import Bounded
        >>> inputs = {"subgoal_index": Bounded(0, 2, shape=(4, 1), dtype=torch.long)}
        >>> sorted(transition_spec(inputs, torch.Size([4]))["next"].keys())
        ['done', 'reward', 'subgoal_index', 'terminated']
    """
    col = (*shape, 1)
    flag = Binary(n=1, shape=col, dtype=torch.bool)
    nxt = Composite(
        **{k: s.clone() for k, s in inputs.items()},
        reward=Unbounded(shape=col, dtype=torch.float32),
        done=flag.clone(),
        terminated=flag.clone(),
        shape=shape,
    )
    return Composite(
        **{k: s.clone() for k, s in inputs.items()},
        steps_to_next_obs=Unbounded(shape=col, dtype=torch.long),
        mask=flag.clone(),
        achieved=flag.clone(),
        next=nxt,
        shape=shape,
    )


def observation(spec: Composite, key: NestedKey, what: str) -> TensorSpec:
    """The spec of the observation ``key`` (named ``what`` in the error when the env lacks it).

    Examples:
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> observation(FourRoomsEnv(2).full_observation_spec, "cell", "observation_key").shape
        torch.Size([2, 2])
    """
    if key not in spec.keys(True, True):
        raise KeyError(
            f"SubgoalPotentialTransform: {what} {key!r} is not an observation of the env; "
            f"available: {sorted(map(str, spec.keys(True, True)))}"
        )
    return spec[key]


def kept_specs(
    parent: EnvBase, env: EnvKeys, keys: SubgoalKeys, kept: tuple[str, ...], num_states: int, observation_key: NestedKey
) -> dict[str, TensorSpec]:
    """The specs of the ``kept`` entries in ``parent``'s group ``env.group`` (names relative to the group).

    Examples:
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> base = FourRoomsEnv(2)
        >>> specs = kept_specs(base, EnvKeys.resolve(base), SubgoalKeys(), ("subgoal_index",), 3, "cell")
        >>> specs["subgoal_index"].shape
        torch.Size([2, 1])
    """
    shape = parent.full_done_spec[env.done].shape[:-1]
    anchor = (
        observation(parent.full_observation_spec, observation_key, "observation_key") if keys.anchor in kept else None
    )
    return state_specs(keys, kept, num_states, shape, anchor)


def add_env_reward(reward_spec: Composite, parent: EnvBase, env: EnvKeys) -> None:
    """Declare the unshaped reward beside the reward (unless an earlier shaping did), after checking
    that the reward has one entry per episode row.

    Examples:
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> base = FourRoomsEnv(2)
        >>> spec = base.full_reward_spec.clone()
        >>> add_env_reward(spec, base, EnvKeys.resolve(base))
        >>> sorted(spec.keys())
        ['env_reward', 'reward']
    """
    done = parent.full_done_spec[env.done]
    if reward_spec[env.reward].shape != done.shape:
        raise ValueError(
            f"SubgoalPotentialTransform: the reward {env.reward!r} has shape "
            f"{tuple(reward_spec[env.reward].shape)} but episodes end by {env.done!r} of shape "
            f"{tuple(done.shape)}: one reward per episode row is needed (combine the rewards first)"
        )
    if not env.shaped_before:
        reward_spec[env.env_reward] = reward_spec[env.reward].clone()


def declare(spec: Composite, parent: EnvBase, env: EnvKeys, specs: dict[str, TensorSpec], refuse_taken: bool) -> None:
    """Add the kept entries' ``specs`` to ``spec`` in the group ``env.group`` (its levels made with the batch
    shapes they have in ``parent``); with ``refuse_taken``, an entry already there (another transform's) is
    a ``ValueError`` saying what to change.

    Examples:
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> base = FourRoomsEnv(2)
        >>> env = EnvKeys.resolve(base)
        >>> spec = base.full_observation_spec.clone()
        >>> declare(spec, base, env, kept_specs(base, env, SubgoalKeys(), ("subgoal_index",), 3, "cell"), True)
        >>> spec["subgoal_index"].shape
        torch.Size([2, 1])
    """
    for depth in range(1, len(env.group) + 1):
        if env.group[:depth] not in spec.keys(True):
            spec[env.group[:depth]] = parent.full_done_spec[env.group[:depth]].empty()
    for name, value in specs.items():
        key = at(env.group, name)
        if refuse_taken and key in spec.keys(True, True):
            raise ValueError(
                f"SubgoalPotentialTransform: {key!r} is kept already by another transform on this env; "
                "give this one another prefix (prefix='room') and its potential matching keys"
            )
        spec[key] = value
