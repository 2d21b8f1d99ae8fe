"""Single-goal FetchPickAndPlace (gymnasium-robotics) as a TorchRL ``GymEnv``.

Potential-based shaping over subgoals needs one task per learning, so the
multi-goal ``FetchPickAndPlace-v4`` becomes a single-goal task: the goal and
the object's start position are drawn once from the learning's ``goal_seed``
and are the same at every reset (the gripper's start is fixed by the task
itself). The reward is gymnasium-robotics' sparse one, ``-1`` per step and
``0`` while the object lies within 0.05 of the goal; episodes last 50 steps
and never terminate early (a time-out is a truncation). The agent sees the
25-d ``"observation"`` only, as float32; ``"is_success"`` is kept for
evaluation.

The observation's components, by name (:data:`COMPONENTS`), are the single
place that says which entry means what; subgoal predicates, the random
subgoals of RRS and the SARSA-RS aggregation below are written with them.

Needs the ``fetch`` extra: ``pip install 'torchrl_subgoal[fetch]'`` (MuJoCo
3.3 to 3.11 and gymnasium-robotics 1.4.2; MuJoCo 3.12 breaks Fetch's reset).
"""

from __future__ import annotations

from importlib import metadata
from importlib.resources import files
from types import ModuleType
from typing import Any

import numpy as np
import torch
from tensordict import TensorDict, TensorDictBase
from torchrl.data import Binary, Bounded, Categorical, Composite, Unbounded
from torchrl.envs import EnvBase

from torchrl_subgoal.envs.gym_batch import import_robotics
from torchrl_subgoal.subgoals import Box, StateAggregation, SubgoalSeries, load_patterns

__all__ = [
    "COMPONENTS",
    "ENV_ID",
    "INSTALL_HINT",
    "OBSERVATION_SIZE",
    "PARTICIPANTS_FILE",
    "SUBGOAL_MARGIN",
    "FetchEnvs",
    "FetchUnavailableError",
    "LeanStep",
    "component_dims",
    "components_of",
    "human_patterns",
    "make_fetch_env",
    "make_fetch_envs",
    "random_patterns",
    "require_fetch",
    "three_state_aggregation",
]

#: Entries of the 25-d FetchPickAndPlace observation, by name.
COMPONENTS: dict[str, slice] = {
    "gripper_position": slice(0, 3),
    "object_position": slice(3, 6),
    "object_relative_position": slice(6, 9),  # object minus gripper
    "finger_joints": slice(9, 11),
    "object_rotation": slice(11, 14),
    "object_velocity": slice(14, 17),  # relative to the gripper
    "object_angular_velocity": slice(17, 20),
    "gripper_velocity": slice(20, 23),
    "finger_velocities": slice(23, 25),
}
OBSERVATION_SIZE = 25
ENV_ID = "torchrl_subgoal/SingleGoalFetchPickAndPlace-v0"
BASE_ENV_ID = "FetchPickAndPlace-v4"
MAX_EPISODE_STEPS = 50
SUBGOAL_MARGIN = 0.01
INSTALL_HINT = "pip install 'torchrl_subgoal[fetch]'  (or `make install` in a checkout)"
PARTICIPANTS_FILE = str(files("torchrl_subgoal") / "domains" / "pick_and_place" / "pick_and_place_participants.yaml")
_MUJOCO_RANGE = ((3, 3), (3, 12))  # >= 3.3, < 3.12


class FetchUnavailableError(ImportError):
    """The ``fetch`` extra (MuJoCo, gymnasium-robotics) is missing or has a broken version.

    Examples:
        >>> try:
        ...     raise FetchUnavailableError("pick-and-place needs MuJoCo")
        ... except ImportError as exc:
        ...     print(exc)
        pick-and-place needs MuJoCo
    """


def component_dims(*names: str) -> tuple[int, ...]:
    """Observation entries of the named components, in order.

    Examples:
        >>> component_dims("object_relative_position", "finger_joints")
        (6, 7, 8, 9, 10)
    """
    unknown = [n for n in names if n not in COMPONENTS]
    if unknown:
        raise KeyError(f"unknown observation component(s) {unknown}; known: {list(COMPONENTS)}")
    return tuple(d for n in names for d in range(COMPONENTS[n].start, COMPONENTS[n].stop))


def components_of(dims: tuple[int, ...] | list[int]) -> tuple[str, ...] | None:
    """The whole components whose entries, in order, are ``dims``; ``None`` if there are none such.

    The inverse of :func:`component_dims`.

    Examples:
        >>> components_of((6, 7, 8, 9, 10))
        ('object_relative_position', 'finger_joints')
        >>> components_of((6, 7)) is None
        True
    """
    names: list[str] = []
    i = 0
    while i < len(dims):
        match = next(
            (
                n
                for n, part in COMPONENTS.items()
                if part.start == dims[i]
                and tuple(dims[i : i + part.stop - part.start]) == tuple(range(part.start, part.stop))
            ),
            None,
        )
        if match is None:
            return None
        names.append(match)
        i += COMPONENTS[match].stop - COMPONENTS[match].start
    return tuple(names)


def _version_tuple(version: str) -> tuple[int, int]:
    parts = [int("".join(c for c in p if c.isdigit()) or 0) for p in version.split(".")[:2]]
    return parts[0], parts[1] if len(parts) > 1 else 0


def require_fetch() -> ModuleType:
    """Import gymnasium with the robotics envs registered, or say how to install them.

    Raises:
        FetchUnavailableError: naming the install command.

    Examples:
        >>> INSTALL_HINT  # what the error tells to run when the extra is missing
        "pip install 'torchrl_subgoal[fetch]'  (or `make install` in a checkout)"
        >>> gymnasium = require_fetch()  # doctest: +SKIP
        >>> ENV_ID in gymnasium.registry  # doctest: +SKIP
        True
    """
    try:
        import gymnasium
        import mujoco  # noqa: F401

        gymnasium_robotics = import_robotics()
    except ImportError as exc:
        raise FetchUnavailableError(
            f"pick-and-place needs MuJoCo and gymnasium-robotics ({exc.name} is missing): {INSTALL_HINT}"
        ) from None
    low, high = _MUJOCO_RANGE
    version = metadata.version("mujoco")
    if not low <= _version_tuple(version) < high:
        raise FetchUnavailableError(
            f"mujoco {version} is installed; Fetch needs mujoco>=3.3,<3.12 (3.12 breaks its reset): {INSTALL_HINT}"
        )
    gymnasium.register_envs(gymnasium_robotics)
    if ENV_ID not in gymnasium.registry:
        gymnasium.register(ENV_ID, entry_point=f"{__name__}:_make_single_goal", max_episode_steps=MAX_EPISODE_STEPS)
    return gymnasium


def _make_single_goal(goal_seed: int = 0) -> Any:
    """The gymnasium env behind :data:`ENV_ID` (``gymnasium.make`` adds the 50-step limit)."""
    gymnasium = require_fetch()
    wrapper: Any = gymnasium.Wrapper

    class SingleGoal(wrapper):
        """Reset to the goal and object start of ``goal_seed``; 25-d float32 observation."""

        def __init__(self, env: Any, seed: int) -> None:
            super().__init__(env)
            self.goal_seed = int(seed)
            self.observation_space = gymnasium.spaces.Box(-np.inf, np.inf, (OBSERVATION_SIZE,), np.float32)

        def reset(self, *, seed: int | None = None, options: dict[str, Any] | None = None) -> Any:
            # Re-seeding the task's generator at every reset draws the same goal and object
            # start each time; the seed a caller passes (e.g. ParallelEnv.set_seed) is ignored.
            obs, info = self.env.reset(seed=self.goal_seed, options=options)
            self.goal = np.array(obs["desired_goal"], dtype=np.float32)
            return obs["observation"].astype(np.float32), {**info, "is_success": np.zeros(1, dtype=bool)}

        def step(self, action: Any) -> Any:
            obs, reward, terminated, truncated, info = self.env.step(action)
            info = {**info, "is_success": np.array([bool(info["is_success"])])}
            # +0.0 turns the task's -0.0 on success into 0.0
            return obs["observation"].astype(np.float32), float(reward) + 0.0, terminated, truncated, info

    return SingleGoal(gymnasium.make(BASE_ENV_ID).unwrapped, goal_seed)


def make_fetch_env(goal_seed: int, *, device: str | torch.device = "cpu", **kwargs: Any) -> Any:
    """One single-goal FetchPickAndPlace env, a TorchRL ``GymEnv`` (picklable via ``functools.partial``).

    Args:
        goal_seed: draws the goal and the object's start (the same for every episode).
        device: where the env's TensorDicts live.
        **kwargs: more keyword arguments for ``GymEnv``.

    Examples:
        >>> env = make_fetch_env(goal_seed=3)  # doctest: +SKIP
        >>> env.rollout(5)["next", "is_success"].shape  # doctest: +SKIP
        torch.Size([5, 1])
    """
    require_fetch()
    from torchrl.data import Binary
    from torchrl.envs import GymEnv
    from torchrl.envs.libs.gym import default_info_dict_reader

    env = GymEnv(ENV_ID, goal_seed=goal_seed, device=device, **kwargs)
    reader = default_info_dict_reader(["is_success"], spec=[Binary(n=1, shape=(1,), dtype=torch.bool)])
    env.set_info_dict_reader(reader)
    return env


def make_fetch_envs(goal_seed: int, num_envs: int, *, device: str | torch.device = "cpu", lean: bool = True) -> Any:
    """``num_envs`` single-goal FetchPickAndPlace envs stepped together in this process, one TorchRL env.

    The same task as ``num_envs`` copies of :func:`make_fetch_env` in a ``SerialEnv``
    (same keys, specs, goal and object start, 50-step truncation, bitwise the same
    observations for the same actions), without their per-env TorchRL plumbing: one
    step is one loop over the envs and one TensorDict (the collectors' fast path; see
    docs/pick_and_place.md, "Throughput"). By default each env takes :class:`LeanStep`
    (gymnasium-robotics' step, bit for bit, without its per-step name look-ups).

    Args:
        goal_seed: draws the goal and the object's start (the same for every env and episode).
        num_envs: envs in the batch (``batch_size == [num_envs]``).
        device: where the env's TensorDicts live.
        lean: step with :class:`LeanStep`; ``False``: through gymnasium's ``env.step``.

    Examples:
        >>> env = make_fetch_envs(goal_seed=3, num_envs=2)  # doctest: +SKIP
        >>> env.rollout(5)["next", "is_success"].shape  # doctest: +SKIP
        torch.Size([2, 5, 1])
    """
    return FetchEnvs(goal_seed, num_envs, device=device, lean=lean)


class FetchEnvs(EnvBase):
    """``num_envs`` single-goal FetchPickAndPlace envs as one batched TorchRL env (:func:`make_fetch_envs`).

    Args:
        goal_seed: the seed that fixes the goal and the object's start of every env.
        num_envs: envs stepped together (the batch size).
        device: device of the returned tensors.
        lean: step every env with :class:`LeanStep` (the default; bitwise gymnasium's step);
            ``False``: with gymnasium's ``env.step`` through its wrappers. Resets always go
            through gymnasium.

    Examples:
        >>> env = FetchEnvs(goal_seed=3, num_envs=2)  # doctest: +SKIP
        >>> env.rollout(3)["next", "observation"].shape  # doctest: +SKIP
        torch.Size([2, 3, 25])
    """

    def __init__(self, goal_seed: int, num_envs: int, device: str | torch.device = "cpu", lean: bool = True) -> None:
        super().__init__(device=device, batch_size=torch.Size([num_envs]))
        gymnasium = require_fetch()
        self.goal_seed = int(goal_seed)
        self.envs = [gymnasium.make(ENV_ID, goal_seed=goal_seed) for _ in range(num_envs)]
        n = (num_envs,)
        self.observation_spec = Composite(
            observation=Unbounded((*n, OBSERVATION_SIZE), dtype=torch.float32, device=self.device),
            is_success=Binary(n=1, shape=(*n, 1), dtype=torch.bool, device=self.device),
            shape=n,
        )
        space = self.envs[0].action_space
        self.action_spec = Bounded(
            torch.as_tensor(space.low).expand(*n, -1).clone(),
            torch.as_tensor(space.high).expand(*n, -1).clone(),
            shape=(*n, space.shape[0]),
            dtype=torch.float32,
            device=self.device,
        )
        self.reward_spec = Unbounded((*n, 1), dtype=torch.float32, device=self.device)
        self.done_spec = Composite(
            {
                key: Categorical(2, (*n, 1), dtype=torch.bool, device=self.device)
                for key in ("done", "terminated", "truncated")
            },
            shape=n,
        )
        self._observation = np.zeros((num_envs, OBSERVATION_SIZE), dtype=np.float32)
        self._success = np.zeros((num_envs, 1), dtype=bool)
        self.lean_steps: list[LeanStep] | None = [LeanStep(env) for env in self.envs] if lean else None
        self._observation64 = np.zeros((num_envs, OBSERVATION_SIZE), dtype=np.float64)

    def _out(self, **extra: torch.Tensor) -> TensorDictBase:
        return TensorDict(
            {
                "observation": torch.from_numpy(self._observation.copy()),
                "is_success": torch.from_numpy(self._success.copy()),
                **extra,
            },
            batch_size=self.batch_size,
            device=self.device,
        )

    def _reset(self, tensordict: TensorDictBase | None = None, **kwargs: Any) -> TensorDictBase:
        mask = None if tensordict is None else tensordict.get("_reset", None)
        which = range(len(self.envs)) if mask is None else mask.reshape(-1).nonzero().flatten().tolist()
        for i in which:
            self._observation[i], _ = self.envs[i].reset()
            self._success[i] = False
            if self.lean_steps is not None:
                self.lean_steps[i].reset()
        false = torch.zeros((*self.batch_size, 1), dtype=torch.bool, device=self.device)
        return self._out(done=false, terminated=false.clone(), truncated=false.clone())

    def _step(self, tensordict: TensorDictBase) -> TensorDictBase:
        actions = tensordict.get("action").detach().cpu().numpy()
        if self.lean_steps is not None:
            return self._lean_step(actions)
        n = len(self.envs)
        reward = np.empty((n, 1), dtype=np.float32)
        terminated, truncated = np.empty((n, 1), dtype=bool), np.empty((n, 1), dtype=bool)
        for i, env in enumerate(self.envs):
            self._observation[i], reward[i], terminated[i], truncated[i], info = env.step(actions[i])
            self._success[i] = info["is_success"]
        term, trunc = torch.from_numpy(terminated), torch.from_numpy(truncated)
        return self._out(reward=torch.from_numpy(reward), done=term | trunc, terminated=term, truncated=trunc)

    def _lean_step(self, actions: np.ndarray) -> TensorDictBase:
        n = len(self.envs)
        reward, truncated = np.empty((n, 1), dtype=np.float32), np.empty((n, 1), dtype=bool)
        for i, lean in enumerate(self.lean_steps or ()):
            reward[i], self._success[i], truncated[i] = lean.step(actions[i], self._observation64[i])
        self._observation[:] = self._observation64  # float64 -> float32 as the wrapper's astype rounds
        trunc = torch.from_numpy(truncated)
        term = torch.zeros_like(trunc)  # Fetch never terminates
        return self._out(reward=torch.from_numpy(reward), done=trunc.clone(), terminated=term, truncated=trunc)

    def _set_seed(self, seed: int | None) -> None:
        """Nothing to seed: every reset draws the goal and object start of ``goal_seed``."""

    def close(self, *, raise_if_closed: bool = True) -> None:
        for env in self.envs:
            env.close()
        super().close(raise_if_closed=raise_if_closed)


class LeanStep:
    """gymnasium-robotics' ``FetchPickAndPlace-v4`` step, bit for bit, without its per-step Python utilities.

    gymnasium-robotics' step looks up every site and joint by name at every step
    (``robot_get_obs`` alone reads the 15 robot joints' positions and velocities by
    name, about 40% of a step's Python time) and builds its observation through
    dictionaries and copies. This step does the same arithmetic on the same MuJoCo
    ``model`` and ``data`` with the addresses found once: clip the action, set the
    gripper's position actuators and the mocap (the welded body's pose plus
    ``0.05 · Δpos`` and the fixed quaternion increment), ``mj_step`` ``n_substeps``
    times, then the 25-d observation (site positions, ``mat2euler`` of the object,
    site Jacobians times ``qvel`` times ``dt``, the fingers' joints), the sparse reward
    and success from the object's distance to the goal, and the time limit's
    truncation. Reset stays gymnasium's (call :meth:`reset` after it). Bitwise
    equality with gymnasium's step over random-action rollouts across resets is
    tested (``tests/envs/test_fetch.py``).

    Args:
        env: a gymnasium env of :data:`ENV_ID` (``gymnasium.make``); its unwrapped Fetch
            env provides the model, data, goal and settings.

    Examples:
        >>> gymnasium = require_fetch()  # doctest: +SKIP
        >>> env = gymnasium.make(ENV_ID, goal_seed=3)  # doctest: +SKIP
        >>> _ = env.reset(); lean = LeanStep(env); lean.reset()  # doctest: +SKIP
        >>> out = np.empty(OBSERVATION_SIZE)  # doctest: +SKIP
        >>> lean.step(np.zeros(4, dtype=np.float32), out)  # doctest: +SKIP
        (-1.0, False, False)
    """

    def __init__(self, env: Any) -> None:
        import mujoco
        from gymnasium_robotics.envs.fetch.fetch_env import goal_distance
        from gymnasium_robotics.utils import rotations

        fetch_env = env.unwrapped
        model, data = fetch_env.model, fetch_env.data
        unsupported = {
            "block_gripper": fetch_env.block_gripper,
            "has_object": not fetch_env.has_object,
            "reward_type": fetch_env.reward_type != "sparse",
            "render_mode": fetch_env.render_mode,
            "nmocap != 1": model.nmocap != 1,
        }
        if any(unsupported.values()):
            raise ValueError(
                f"LeanStep replicates FetchPickAndPlace only; this env differs in "
                f"{[k for k, v in unsupported.items() if v]}"
            )
        self.env, self.fetch_env, self.model, self.data = env, fetch_env, model, data
        self._mj_step, self._jac_site = mujoco.mj_step, mujoco.mj_jacSite
        self._mat2euler, self._distance = rotations.mat2euler, goal_distance
        names = fetch_env._model_names
        self.grip, self.object = names.site_name2id["robot0:grip"], names.site_name2id["object0"]
        # robot_get_obs: the robot's joints in id order, of which the observation keeps the last two
        fingers = [names.joint_name2id[n] for n in names.joint_names if n.startswith("robot")][-2:]
        slide_or_hinge = (mujoco.mjtJoint.mjJNT_SLIDE, mujoco.mjtJoint.mjJNT_HINGE)
        if any(model.jnt_type[j] not in slide_or_hinge for j in fingers):
            raise ValueError("LeanStep expects the gripper's last two robot joints to be one-dimensional")
        self.finger_qpos = np.array([model.jnt_qposadr[j] for j in fingers])
        self.finger_dof = np.array([model.jnt_dofadr[j] for j in fingers])
        # ctrl_set_action: a position actuator (bias) targets its joint's position plus the action
        self.actuators = [
            (i, None if model.actuator_biastype[i] == 0 else int(model.jnt_qposadr[model.actuator_trnid[i, 0]]))
            for i in range(model.nu)
        ]
        # reset_mocap2body_xpos: every weld puts its mocap at the body welded to it
        self.welds = []
        for eq_type, a, b in zip(model.eq_type, model.eq_obj1id, model.eq_obj2id, strict=True):
            if eq_type == mujoco.mjtEq.mjEQ_WELD:
                mocap = model.body_mocapid[a]
                self.welds.append((int(mocap), int(b)) if mocap != -1 else (int(model.body_mocapid[b]), int(a)))
        self.quat_delta = np.array([[1.0, 0.0, 1.0, 0.0]])  # the fixed end-effector rotation, as in _set_action
        self.low, self.high = fetch_env.action_space.low, fetch_env.action_space.high
        self.n_substeps = fetch_env.n_substeps
        self.dt = fetch_env.n_substeps * model.opt.timestep
        self.threshold = fetch_env.distance_threshold
        self.max_steps = env.spec.max_episode_steps
        self.jacp_grip, self.jacp_object, self.jacr_object = (np.zeros((3, model.nv)) for _ in range(3))
        self.steps = 0

    def reset(self) -> None:
        """Call after gymnasium's ``env.reset()``: restart the episode's step count."""
        self.steps = 0

    def step(self, action: np.ndarray, out: np.ndarray) -> tuple[float, bool, bool]:
        """One step of ``action`` (float32 ``[4]``): the float64 observation into ``out`` ``[25]``;
        returns the reward (``-1.0`` or ``0.0``), success and the time limit's truncation."""
        model, data, dt = self.model, self.data, self.dt
        action = np.clip(action, self.low, self.high)
        pos_ctrl = action[:3].copy()
        pos_ctrl *= 0.05
        gripper = float(action[3])
        for i, qpos_address in self.actuators:
            data.ctrl[i] = gripper if qpos_address is None else data.qpos[qpos_address] + gripper
        for mocap, body in self.welds:
            data.mocap_pos[mocap][:] = data.xpos[body]
            data.mocap_quat[mocap][:] = data.xquat[body]
        data.mocap_pos[:] = data.mocap_pos + pos_ctrl.astype(np.float64)
        data.mocap_quat[:] = data.mocap_quat + self.quat_delta
        self._mj_step(model, data, nstep=self.n_substeps)

        grip_pos, object_pos = data.site_xpos[self.grip], data.site_xpos[self.object]
        self._jac_site(model, data, self.jacp_grip, None, self.grip)
        grip_velp = (self.jacp_grip @ data.qvel) * dt
        self._jac_site(model, data, self.jacp_object, self.jacr_object, self.object)
        object_velp = (self.jacp_object @ data.qvel) * dt
        object_velp -= grip_velp
        object_velr = (self.jacr_object @ data.qvel) * dt
        object_rot = self._mat2euler(data.site_xmat[self.object].reshape(3, 3))
        np.concatenate(
            [
                grip_pos,
                object_pos,
                object_pos - grip_pos,
                data.qpos[self.finger_qpos],
                object_rot,
                object_velp,
                object_velr,
                grip_velp,
                data.qvel[self.finger_dof] * dt,
            ],
            out=out,
        )
        distance = self._distance(object_pos, self.fetch_env.goal)
        self.steps += 1
        return -float(distance > self.threshold) + 0.0, bool(distance < self.threshold), self.steps >= self.max_steps


# --------------------------------------------------------------------------- subgoals


def human_patterns(path: str = PARTICIPANTS_FILE) -> dict[str, SubgoalSeries]:
    """The participants' subgoal series (all five gave the same): gripper at the object, then grasped.

    Examples:
        >>> patterns = human_patterns()
        >>> len(patterns) >= 1, [len(series) for series in patterns.values()][0]
        (True, 2)
    """
    return load_patterns(path)


def random_patterns(human: SubgoalSeries, num_patterns: int, seed: int) -> list[SubgoalSeries]:
    """RRS: chains of random boxes over the same components as ``human``'s, with its margins.

    Each random subgoal keeps the entries and the margin of the human subgoal at the
    same position; its centre is drawn uniformly per component from
    :data:`RANDOM_CENTRE_RANGE` (relative positions within ±0.1, finger joints in
    [0, 0.05]), reproducibly from ``seed``.

    Examples:
        >>> series = random_patterns(human_patterns()["participants"], 2, seed=0)
        >>> [p.predicates[1].box_dims for p in series]
        [(6, 7, 8, 9, 10), (6, 7, 8, 9, 10)]
    """
    generator = torch.Generator().manual_seed(seed)
    out = []
    for i in range(num_patterns):
        boxes = []
        for predicate in human.predicates:
            if not isinstance(predicate, Box):
                raise ValueError(f"random_patterns needs box subgoals, got {type(predicate).__name__}")
            low = torch.tensor([RANDOM_CENTRE_RANGE[_component_of(d)][0] for d in predicate.box_dims])
            high = torch.tensor([RANDOM_CENTRE_RANGE[_component_of(d)][1] for d in predicate.box_dims])
            centre = low + (high - low) * torch.rand(len(predicate.box_dims), generator=generator)
            boxes.append(Box(tuple(round(float(c), 4) for c in centre), predicate.margin, predicate.box_dims))
        out.append(SubgoalSeries(boxes, name=f"random_{i + 1}"))
    return out


#: Per component, the range RRS draws subgoal centres from.
RANDOM_CENTRE_RANGE: dict[str, tuple[float, float]] = {
    "gripper_position": (1.05, 1.55),
    "object_position": (1.05, 1.55),
    "object_relative_position": (-0.1, 0.1),
    "finger_joints": (0.0, 0.05),
}


def _component_of(dim: int) -> str:
    for name, part in COMPONENTS.items():
        if part.start <= dim < part.stop:
            if name not in RANDOM_CENTRE_RANGE:
                raise ValueError(
                    f"RRS has no range to draw random centres from for observation component {name!r} "
                    f"(entry {dim}); it draws over {', '.join(RANDOM_CENTRE_RANGE)}"
                )
            return name
    raise ValueError(f"entry {dim} is outside the {OBSERVATION_SIZE}-d observation")


def three_state_aggregation(near: float = 0.05) -> StateAggregation:
    """SARSA-RS's hand-given ``z = g(s)`` over three states.

    ``z = 0``: the object is grasped (the second subgoal's box); ``z = 1``: the
    gripper is within ``near`` of the object in every axis; ``z = 2``: anything else.

    Examples:
        >>> g = three_state_aggregation()
        >>> obs = torch.zeros(3, OBSERVATION_SIZE)
        >>> obs[0, 9:11] = 0.02      # at the object, fingers closed on it
        >>> obs[1, 6] = 0.03         # near the object, fingers open (0 here)
        >>> obs[2, 6] = 0.3          # far away
        >>> g.initial(obs, torch.Size([3])).flatten().tolist()
        [0, 1, 2]
    """
    rel, fingers = component_dims("object_relative_position"), component_dims("finger_joints")
    grasped = Box((0.0, 0.0, 0.0, 0.02, 0.02), (SUBGOAL_MARGIN,) * 5, rel + fingers)
    close = Box((0.0, 0.0, 0.0), (near,) * 3, rel)
    anywhere = Box((0.0,), (float("inf"),), (0,))
    return StateAggregation.from_regions([grasped, close, anywhere], OBSERVATION_SIZE)
