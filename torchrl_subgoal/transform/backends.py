"""How the shaping transform shapes one step: a small protocol and its two implementations.

* :class:`TorchShaping`, the reference: torch operations only, any potential, any device, conditions;
* :class:`CompiledShaping`: the numba kernels, for a tabular or naive potential on the CPU (a batch
  off the CPU steps in torch).

The transform keeps the specs, resets, steps and transitions; each batch it sets up holds the backend
that shapes it (:func:`backend_for` picks one).
"""

from __future__ import annotations

from typing import Any, Literal, Protocol

import torch
from tensordict.nn import TensorDictModuleBase

from torchrl_subgoal._kernels import NUMBA
from torchrl_subgoal.loss import ValueUpdate
from torchrl_subgoal.transform import setup
from torchrl_subgoal.transform.cache import ValueCache
from torchrl_subgoal.transform.compiled import compiled_step
from torchrl_subgoal.transform.eager import torch_step
from torchrl_subgoal.transform.keys import StepInputs
from torchrl_subgoal.transform.setup import BatchSetup, Settings, Subgoals

__all__ = [
    "Backend",
    "CompiledShaping",
    "ShapingBackend",
    "TorchShaping",
    "backend_for",
    "batch_for",
]

Backend = Literal["auto", "compiled", "torch"]


class ShapingBackend(Protocol):
    """What the transform asks of a backend.

    ``prepare(batch, online)`` once, when a batch is set up (``online``: the env's batch, whose rows are the
    learners, in order; else stored rows); ``step(batch, current, step, learn)`` at every step: from the kept
    entries ``current`` (every one), the next ones (names as in
    :class:`~torchrl_subgoal.SubgoalKeys`), ``"reward"`` the shaped reward and ``"transition"`` the step's SMDP
    transition when the settings write it; with ``learn``, the potential is first trained online on the
    transitions the step closes.

    Examples:
        >>> isinstance(TorchShaping, type) and all(hasattr(TorchShaping, m) for m in ("prepare", "step"))
        True
    """

    def prepare(self, batch: BatchSetup, online: bool) -> None: ...

    def step(
        self, batch: BatchSetup, current: dict[str, torch.Tensor], step: StepInputs, learn: bool
    ) -> dict[str, Any]: ...


class TorchShaping:
    """The reference backend: one step in torch, the online update one :meth:`ValueUpdate.step`.

    Examples:
        >>> from torchrl_subgoal import State, SubgoalPotentialTransform, SubgoalSeries, TabularPotential
        >>> series = SubgoalSeries([State(1)])
        >>> t = SubgoalPotentialTransform(series, TabularPotential(2), gamma=0.9).use_backend("torch")
        >>> env = t._batch(torch.Size([2]), torch.zeros(2, 1, dtype=torch.long), 1, torch.zeros(2, 1), online=True)
        >>> type(env.backend).__name__
        'TorchShaping'
    """

    def __init__(self, settings: Settings, potential: TensorDictModuleBase, update: ValueUpdate | None) -> None:
        self.settings, self.potential, self.update = settings, potential, update
        self.cache = ValueCache()  # Φ by value, while the inputs and the potential are unchanged

    def prepare(self, batch: BatchSetup, online: bool) -> None:
        return None

    def step(
        self, batch: BatchSetup, current: dict[str, torch.Tensor], step: StepInputs, learn: bool
    ) -> dict[str, Any]:
        settings = self.settings
        if step.obs is None and settings.reads_observation:
            raise KeyError(f"SubgoalPotentialTransform: the step has no {settings.observation_key!r} entry")
        update = self.update.step if learn and self.update is not None else None
        return torch_step(batch, settings, self.potential, self.cache, current, step, update)


class CompiledShaping(TorchShaping):
    """The numba kernels: the abstraction's regions advanced, the TD update and the shaping in one call
    per step (a batch whose entries are off the CPU steps in torch).

    Examples:
        >>> from torchrl_subgoal import State, SubgoalPotentialTransform, SubgoalSeries, TabularPotential
        >>> t = SubgoalPotentialTransform(SubgoalSeries([State(1)]), TabularPotential(2), gamma=0.9)
        >>> env = t._batch(torch.Size([2]), torch.zeros(2, 1, dtype=torch.long), 1, torch.zeros(2, 1), online=True)
        >>> type(env.backend).__name__, env.compiled
        ('CompiledShaping', True)
    """

    def prepare(self, batch: BatchSetup, online: bool) -> None:
        batch.use_kernels(self.potential, self.settings, self.update, online)

    def step(
        self, batch: BatchSetup, current: dict[str, torch.Tensor], step: StepInputs, learn: bool
    ) -> dict[str, Any]:
        if current[self.settings.keys.index].device.type == "cpu":
            return compiled_step(batch, self.settings, current, step, learn)
        return super().step(batch, current, step, learn)


def backend_for(
    name: Backend, settings: Settings, potential: TensorDictModuleBase, update: ValueUpdate | None
) -> ShapingBackend:
    """The backend ``name`` asks for, given the potential as it is now: ``"auto"`` compiles when it can;
    ``"compiled"`` where it cannot is a ``TypeError`` saying why (:func:`~.setup.compiles`).

    Examples:
        >>> from torchrl_subgoal import NeuralPotential, State, SubgoalPotentialTransform, SubgoalSeries
        >>> from torchrl_subgoal import TabularPotential
        >>> t = SubgoalPotentialTransform(SubgoalSeries([State(1)]), TabularPotential(2), gamma=0.9)
        >>> type(backend_for("auto", t._settings, t.potential, None)).__name__
        'CompiledShaping'
        >>> type(backend_for("torch", t._settings, t.potential, None)).__name__
        'TorchShaping'
    """
    kind = CompiledShaping if setup.compiles(name, potential, update) else TorchShaping
    return kind(settings, potential, update)


def batch_for(
    subgoals: Subgoals,
    potential: TensorDictModuleBase,
    settings: Settings,
    update: ValueUpdate | None,
    backend: Backend,
    learner: torch.Tensor,
    n_learners: int,
    layout: tuple[int, bool],
    obs: torch.Tensor | None,
    online: bool,
) -> BatchSetup:
    """A batch whose rows belong to ``learner`` (``[*B, 1]``; ``online``: the env's batch, in order) set up for
    the backend that shapes it: the subgoals compiled for its rows (observations of ``layout = (entries,
    one-hot)``), a monotone table's ancestors, the potential as the kernels read it when compiled.

    Examples:
        >>> from torchrl_subgoal import State, SubgoalPotentialTransform, SubgoalSeries, TabularPotential
        >>> t = SubgoalPotentialTransform(SubgoalSeries([State(1)]), TabularPotential(2), gamma=0.9)
        >>> learner = torch.zeros(3, 1, dtype=torch.long)
        >>> batch = batch_for(t.subgoals, t.potential, t._settings, None, "torch", learner, 1, (1, False), None, True)
        >>> batch.rows, type(batch.backend).__name__
        (3, 'TorchShaping')
    """
    batch_shape = learner.shape[:-1]
    setup.check_table(potential, n_learners, subgoals.num_states)
    setup.check_device(potential, obs)
    abstraction = subgoals.compile(learner, batch_shape, n_learners, layout, settings.observation_key)
    ancestors = setup.monotone_ancestors(potential, subgoals, learner, n_learners)
    shaper = backend_for(backend, settings, potential, update)
    batch = BatchSetup(batch_shape, abstraction, learner, compiled_search=backend != "torch" and NUMBA,
                       ancestors=ancestors, observation_size=layout[0], backend=shaper)  # fmt: skip
    shaper.prepare(batch, online)
    return batch
