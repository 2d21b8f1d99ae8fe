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
    "StepInputs",
    "SubgoalKeys",
    "add_env_reward",
    "at",
    "declare",
    "declare_observations",
    "declare_state",
    "kept_specs",
    "observation",
    "observation_of",
    "read",
    "read_step",
    "state_specs",
    "step_in_keys",
    "step_out_keys",
    "transition_spec",
    "write",
    "write_step",
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
    """Names of the entries one transform writes: the abstract-state entries it keeps, ``f"{prefix}_{role}"``,
    and where each step's SMDP transition goes, if anywhere.

    Give a second transform on the same env another prefix (and its potential
    the matching keys) so that the two do not share entries.

    Args:
        prefix: the kept entries' prefix (``"subgoal"``).
        transitions: if given, every step also writes its SMDP transition under ``("next", transitions)``
            (``"mask"`` tells the real ones); ``None``: rebuild them from collected data with
            :meth:`~torchrl_subgoal.SubgoalPotentialTransform.transitions`.

    Examples:
        >>> SubgoalKeys("room").index
        'room_index'
        >>> SubgoalKeys(transitions="smdp").transitions
        'smdp'
    """

    prefix: str = "subgoal"
    transitions: NestedKey | None = None

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


class StepInputs(NamedTuple):
    """One step's entries of ``"next"`` that the shaping reads.

    Examples:
        >>> one = torch.ones(2, 1)
        >>> StepInputs(None, one, one, one.bool(), one.bool(), None).reward.shape
        torch.Size([2, 1])
    """

    obs: torch.Tensor | None  #: the observation the region predicates read (``None``: not read)
    reward: torch.Tensor  #: the reward to shape
    env_reward: torch.Tensor  #: the env's reward, which ``r_h`` accumulates (``reward`` itself but after a shaping)
    done: torch.Tensor
    terminated: torch.Tensor
    td: TensorDictBase | None  #: the step's ``"next"`` entries, for the conditions
    obs_before: torch.Tensor | None = None  #: the observation the step started from (an interpolating potential)


def read_step(
    td: TensorDictBase,
    nxt: TensorDictBase,
    env: EnvKeys,
    kept: tuple[str, ...],
    obs_key: NestedKey | None,
    before: bool = False,
) -> tuple[dict[str, torch.Tensor], StepInputs, torch.Size]:
    """What a shaping step reads: the kept entries of its input ``td`` (a clear ``KeyError`` for one missing),
    what the shaping reads of its ``"next"`` entries ``nxt`` (``obs_key``: the observation read, ``None``:
    none; ``before``: that of ``td`` too) and the batch shape of the reward's group.

    Examples:
        >>> from tensordict import TensorDict
        >>> td = TensorDict({"subgoal_index": torch.zeros(2, 1)}, [2])
        >>> nxt = TensorDict({"reward": torch.ones(2, 1), "done": torch.zeros(2, 1, dtype=torch.bool)}, [2])
        >>> current, step, shape = read_step(td, nxt, EnvKeys.resolve(None), ("subgoal_index",), None)
        >>> list(current), shape
        (['subgoal_index'], torch.Size([2]))
    """
    root = td.get(env.group) if env.group else td
    current = {}
    for name in kept:
        value = root._get_str(name, None)
        if value is None:
            raise KeyError(
                f"SubgoalPotentialTransform: {name!r} is missing from the step's input: reset the "
                "env through the transform (env.reset()) before stepping"
            )
        current[name] = value
    reward, done = read(nxt, env.reward), read(nxt, env.done)
    step = StepInputs(
        read(nxt, obs_key) if obs_key is not None else None,
        reward,
        read(nxt, env.env_reward) if env.shaped_before else reward,
        done,
        done if env.terminated == env.done else read(nxt, env.terminated),
        nxt,
        read(td, obs_key) if before and obs_key is not None else None,
    )
    return current, step, (nxt.get(env.group) if env.group else nxt).batch_size


def write_step(
    nxt: TensorDictBase,
    env: EnvKeys,
    kept: tuple[str, ...],
    out: dict[str, Any],
    reward: torch.Tensor,
    transitions_key: NestedKey | None,
) -> TensorDictBase:
    """Write a step's outputs ``out`` (a backend's) into its ``"next"`` entries ``nxt``: the kept entries, the
    shaped reward, the env's ``reward`` (unless an earlier shaping keeps it) and the SMDP transition.

    Examples:
        >>> from tensordict import TensorDict
        >>> nxt = TensorDict({"reward": torch.ones(2, 1)}, [2])
        >>> out = {"subgoal_index": torch.ones(2, 1, dtype=torch.long), "reward": torch.zeros(2, 1)}
        >>> write_step(nxt, EnvKeys.resolve(None), ("subgoal_index",), out, nxt["reward"], None)["env_reward"].sum()
        tensor(2.)
    """
    root = nxt.get(env.group) if env.group else nxt
    for name in kept:
        root._set_str(name, out[name], inplace=False, validated=True)
    write(nxt, env.reward, out["reward"])
    if not env.shaped_before:
        write(nxt, env.env_reward, reward)
    if transitions_key is not None:
        write(nxt, transitions_key, out["transition"])
    return nxt


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


def declare_observations(
    spec: Composite, parent: EnvBase, env: EnvKeys, specs: dict[str, TensorSpec], read: NestedKey | None, settings: Any
) -> None:
    """Declare the kept entries (``specs``) as observations, after checking the observation ``read`` (``None``:
    none is read) exists, and the SMDP transition entry when ``settings.keys.transitions`` names one.

    Examples:
        >>> from torchrl.envs import TransformedEnv
        >>> from torchrl_subgoal import State, SubgoalPotentialTransform, SubgoalSeries, TabularPotential
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> t = SubgoalPotentialTransform(SubgoalSeries([State(1)]), TabularPotential(2), gamma=0.9,
        ...                               keys=SubgoalKeys(transitions="smdp"))
        >>> env = TransformedEnv(FourRoomsEnv(2), t)  # transform_observation_spec calls it
        >>> "smdp" in env.observation_spec.keys(), "subgoal_index" in env.observation_spec.keys()
        (True, True)
    """
    if read is not None:
        observation(spec, read, "observation_key")
    declare(spec, parent, env, specs, refuse_taken=True)
    key = settings.keys.transitions
    if key is not None:
        inputs = {k: s for k, s in specs.items() if k in settings.inputs}
        spec[key] = transition_spec(inputs, specs[settings.keys.index].shape[:-1])


def declare_state(input_spec: Composite, parent: EnvBase, env: EnvKeys, specs: dict[str, TensorSpec]) -> None:
    """Declare the kept entries (``specs``) as state carried from step to step, as ``RewardSum``'s and
    ``StepCounter``'s are.

    Examples:
        >>> from torchrl.envs import TransformedEnv
        >>> from torchrl_subgoal import State, SubgoalPotentialTransform, SubgoalSeries, TabularPotential
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> t = SubgoalPotentialTransform(SubgoalSeries([State(1)]), TabularPotential(2), gamma=0.9)
        >>> env = TransformedEnv(FourRoomsEnv(2), t)  # transform_input_spec calls it
        >>> "subgoal_steps" in env.full_state_spec.keys()
        True
    """
    state = input_spec["full_state_spec"]
    if state is None:
        state = Composite(shape=input_spec.shape, device=input_spec.device)
    declare(state, parent, env, specs, refuse_taken=False)
    input_spec["full_state_spec"] = state


def step_in_keys(env: EnvKeys, observation_key: NestedKey | None) -> list[NestedKey]:
    """A shaping step's entries read: the reward, an earlier shaping's env reward, the done and terminated
    entries, and the observation (``None``: not read).

    Examples:
        >>> step_in_keys(EnvKeys.resolve(None), "cell")
        ['reward', 'done', 'terminated', 'cell']
    """
    done = [env.done] if env.terminated == env.done else [env.done, env.terminated]
    obs = [observation_key] if observation_key is not None else []
    return [env.reward, *([env.env_reward] if env.shaped_before else []), *done, *obs]


def step_out_keys(env: EnvKeys, kept: tuple[str, ...], transitions: NestedKey | None) -> list[NestedKey]:
    """A shaping step's entries written: the shaped reward, the env reward (unless an earlier shaping keeps it),
    the ``kept`` entries in the reward's group, and the transition entry (``None``: none).

    Examples:
        >>> step_out_keys(EnvKeys.resolve(None), ("subgoal_index",), None)
        ['reward', 'env_reward', 'subgoal_index']
    """
    written = [env.reward, *([] if env.shaped_before else [env.env_reward])]
    written += [at(env.group, name) for name in kept]
    return written + ([transitions] if transitions is not None else [])


def observation_of(parent: EnvBase | None, key: NestedKey) -> TensorSpec | None:
    """The spec of the observation ``key`` of ``parent`` (``None`` without a parent env yet).

    Examples:
        >>> from torchrl_subgoal.envs import FourRoomsEnv
        >>> observation_of(FourRoomsEnv(2), "cell").shape, observation_of(None, "cell")
        (torch.Size([2, 2]), None)
    """
    return None if parent is None else observation(parent.full_observation_spec, key, "observation_key")
