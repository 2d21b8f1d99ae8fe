"""The fused engine's per-record steps: generic functions that an env's or a learner's record implements.

:func:`~torchrl_subgoal.fused._kernels.engine.fused_run` steps any env with any learner. It names neither: it
calls the generic functions below, and an env's or a learner's record type (the NamedTuple its
``kernel_state()`` returns) joins the engine by implementing them, next to its own kernels, with
``@implements(generic, RecordType)`` (also importable from :mod:`torchrl_subgoal.fused.engine`, with
the generic functions):

- an env: env_scratch, env_observe, env_step, env_reset and env_shaping_observation
  (envs/four_rooms.py for GridKernelState, envs/pinball.py for BallKernelState);
- a learner: learner_scratch and learner_step (fused/sarsa.py, fused/actor_critic.py).

Numba picks the implementation when it compiles the loop for the records' types (``overload``, on the
record's class) and inlines it, so a call costs what the written-out step would. An implementation
should not pass its whole record to further inlined helpers per step when the record holds many arrays:
numba counts a reference per array each time (see the note above
:func:`~torchrl_subgoal._kernels.shaping.shaping_start`). Numba's on-disk cache of ``fused_run`` is keyed
on its own file only: after editing an implementation elsewhere, delete
``fused/_kernels/__pycache__/engine.fused_run-*.nb[ic]``.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numba
import numba.core.types
import numba.extending


def implements(generic: Callable[..., Any], record: type) -> Callable[[Callable[..., Any]], Callable[..., Any]]:
    """Register ``impl`` as the compiled ``generic`` (one of the functions below) for records of type
    ``record``: the loop calls ``impl`` where ``generic``'s first argument is such a record.

    ``impl`` takes ``generic``'s arguments and is compiled with numba (inlined into :func:`fused_run`).

    Args:
        generic: the function implemented, e.g. :func:`env_step`.
        record: the ``NamedTuple`` class the implementation is for (dispatch is on the exact class).

    Examples:
        >>> from typing import NamedTuple
        >>> import numpy as np
        >>> class Counter(NamedTuple):
        ...     count: np.ndarray
        >>> @implements(env_observe, Counter)
        ... def _observe(env, b, scratch):
        ...     return env.count[b]
        >>> @numba.njit
        ... def observe(env):
        ...     return env_observe(env, 1, ())
        >>> int(observe(Counter(np.array([3, 5]))))
        5
    """

    def register(impl: Callable[..., Any]) -> Callable[..., Any]:
        _IMPLEMENTED.setdefault(generic.__name__, set()).add(record)

        def typer(first: Any, *args: Any) -> Callable[..., Any] | None:
            if isinstance(first, numba.core.types.BaseNamedTuple) and first.instance_class is record:
                return impl
            return None

        numba.extending.overload(generic, inline="always", strict=False)(typer)
        return impl

    return register


_IMPLEMENTED: dict[str, set[type]] = {}  # generic function → the record types that implement it


def missing_steps(env: Any, learner: Any) -> list[str]:
    """The generic functions that ``env``'s or ``learner``'s record type does not implement (``[]``: they can
    run in :func:`fused_run`).

    Examples:
        >>> missing_steps((), ())[:2]
        ['env_scratch', 'env_observe']
    """
    wanted = [(name, env) for name in ENV_STEPS] + [(name, learner) for name in LEARNER_STEPS]
    return [name for name, record in wanted if type(record) not in _IMPLEMENTED.get(name, ())]


def _no_implementation(what: str, record: Any) -> TypeError:
    return TypeError(
        f"{what} runs only compiled, in fused_run, for the record types registered with "
        f"torchrl_subgoal.fused.engine.implements; called from Python with {type(record).__name__}"
    )


def env_scratch(env: Any) -> Any:
    """Scratch the env's steps share, allocated once per call of :func:`fused_run` (any numba value;
    ``()`` for none)."""
    raise _no_implementation("env_scratch", env)


def env_observe(env: Any, b: int, scratch: Any) -> Any:
    """Learner ``b``'s observation as its learner reads it (a state number, an array, …), before its step."""
    raise _no_implementation("env_observe", env)


def env_step(env: Any, b: int, a: int, scratch: Any) -> Any:
    """Learner ``b``'s env step with action ``a`` (``env`` updated in place):
    ``(observation, reward as float32, terminated, done)``, the observation as :func:`env_observe` gives it."""
    raise _no_implementation("env_step", env)


def env_reset(env: Any, b: int, scratch: Any) -> Any:
    """Put learner ``b`` back at the start of an episode; returns its observation there."""
    raise _no_implementation("env_reset", env)


def env_shaping_observation(env: Any, o: Any, scratch: Any) -> Any:
    """What the shaping transform reads of the observation ``o``: a 1-D array that a region aggregation or a
    subgoal series tests (its first entry is the index of a lookup aggregation)."""
    raise _no_implementation("env_shaping_observation", env)


def learner_scratch(learner: Any) -> Any:
    """Scratch of the learner's step, allocated once per call of :func:`fused_run`."""
    raise _no_implementation("learner_scratch", learner)


def learner_step(
    learner: Any,
    b: int,
    o: Any,
    z: int,
    a: int,
    reward: float,
    o_next: Any,
    z_next: int,
    terminated: bool,
    done: bool,
    o_root: Any,
    z_root: int,
    scratch: Any,
) -> int:
    """Learner ``b``'s update for the transition ``(o, z) --a, reward--> (o_next, z_next)``; returns its next
    action, drawn at ``(o_root, z_root)`` (the reset state where ``done``, else ``(o_next, z_next)``).
    ``z`` are abstract states (0 unshaped) for a learner whose table has a row per state and abstract state."""
    raise _no_implementation("learner_step", learner)


ENV_STEPS = ("env_scratch", "env_observe", "env_step", "env_reset", "env_shaping_observation")
LEARNER_STEPS = ("learner_scratch", "learner_step")
