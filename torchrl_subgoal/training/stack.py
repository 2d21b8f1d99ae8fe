"""``K`` learners' networks and replay as one: stacked parameters, per-learner losses, clipping and samples.

What any learner written for a leading learner dim needs, whatever its algorithm:

* :class:`LearnerStack`: ``K`` copies of a network, each with its own
  parameters (stacked ``[K, …]``, applied with ``torch.vmap``), over inputs whose
  first dim is the env batch (learner-major: rows ``k·M … (k+1)·M − 1`` are learner
  ``k``'s) or the learners; :func:`per_learner`: one learner's module out of a batch's;
* :func:`learner_means`: per-sample losses as each learner's mean, whose sum
  gives every learner the gradient it gets alone;
* :func:`clip_grad_norm_per_learner`: gradient clipping learner by learner;
* :class:`LearnerReplay`: one replay buffer with a learner dim, every learner
  sampling its own transitions.

Adam's state is per element, so one Adam over stacked parameters is each learner's own.
"""

from __future__ import annotations

import copy
from collections.abc import Iterable, Sequence
from typing import Any

import torch
from tensordict import TensorDict, TensorDictBase
from torch import nn
from torchrl.data import LazyTensorStorage, ReplayBuffer
from torchrl.data.replay_buffers.samplers import Sampler

__all__ = ["LearnerReplay", "LearnerStack", "clip_grad_norm_per_learner", "learner_means", "per_learner"]


class LearnerStack(nn.Module):
    """``K`` networks of one architecture as one module: each learner's rows go through its own parameters.

    Args:
        networks: one network per learner (same architecture; their parameters and buffers are
            copied, stacked along a new first dim).

    The inputs' first dim is the env batch, learner-major (``K·M`` rows, the first
    ``M`` learner 0's), or the learners themselves (``K`` rows of samples); any further
    dims (time, minibatch, a ``vmap`` of TorchRL's value estimators) follow.

    Examples:
        >>> _ = torch.manual_seed(0)
        >>> nets = [nn.Linear(3, 2) for _ in range(2)]
        >>> stack = LearnerStack(nets)
        >>> x = torch.randn(4, 5, 3)  # 2 learners x 2 envs, 5 steps
        >>> out = stack(x)
        >>> out.shape, torch.allclose(out[2:], nets[1](x[2:]), atol=1e-6)
        (torch.Size([4, 5, 2]), True)
        >>> torch.equal(stack.learner(1).weight, nets[1].weight)  # learner 1's own network
        True
    """

    def __init__(self, networks: Sequence[nn.Module]) -> None:
        super().__init__()
        if not networks:
            raise ValueError("LearnerStack needs at least one network")
        self.learners = len(networks)
        self.params = TensorDict.from_modules(*networks, as_module=True)
        base = copy.deepcopy(networks[0])
        self.params[0].data.to("meta").to_module(base)  # the architecture, without its own weights
        self.__dict__["_base"] = base  # not a submodule: its (meta) parameters are not this module's
        # where each stacked entry goes in the architecture: the forward pass puts a learner's tensors
        # there directly (a TensorDict's ``to_module`` costs tenths of a millisecond a call)
        self._keys = list(self.params.keys(include_nested=True, leaves_only=True))
        self._slots = []
        for key in self._keys:
            path = (key,) if isinstance(key, str) else key
            owner = base.get_submodule(".".join(path[:-1])) if len(path) > 1 else base
            self._slots.append((owner, path[-1], path[-1] in owner._parameters))
        self._meta = [getattr(owner, name) for owner, name, _ in self._slots]

    def forward(self, *inputs: torch.Tensor) -> torch.Tensor | tuple[torch.Tensor, ...]:
        return self.call(self.params, *inputs)

    def call(self, params: TensorDictBase, *inputs: torch.Tensor) -> torch.Tensor | tuple[torch.Tensor, ...]:
        """The forward pass with ``params`` (stacked as :attr:`params`, e.g. ``params.detach()``) in place of
        the learners' own."""
        k = self.learners
        for x in inputs:
            if x.shape[0] % k:
                raise ValueError(f"LearnerStack of {k} learners got {x.shape[0]} rows: not a multiple of {k}")
        tensors = [params.get(key) for key in self._keys]
        if k == 1:  # one learner: its network on its own parameters, no vmap
            return self._apply_base([t[0] for t in tensors], inputs)
        n = len(tensors)

        def one(*args: torch.Tensor) -> Any:
            return self._apply_base(args[:n], args[n:])

        grouped = [x.unflatten(0, (k, -1)) for x in inputs]
        out = torch.vmap(one, (0,) * (n + len(inputs)))(*tensors, *grouped)
        if isinstance(out, tuple):  # several outputs (a location and a scale)
            return tuple(o.flatten(0, 1) for o in out)
        return out.flatten(0, 1)

    def _apply_base(self, tensors: Sequence[torch.Tensor], inputs: Sequence[torch.Tensor]) -> Any:
        """The architecture called on ``inputs`` with ``tensors`` (one learner's) as its parameters and buffers."""
        for (owner, name, is_parameter), tensor in zip(self._slots, tensors, strict=True):
            (owner._parameters if is_parameter else owner._buffers)[name] = tensor  # type: ignore[assignment]
        try:
            return self.__dict__["_base"](*inputs)
        finally:  # the architecture keeps no learner's tensors (it stays picklable and copyable)
            for (owner, name, is_parameter), meta in zip(self._slots, self._meta, strict=True):
                (owner._parameters if is_parameter else owner._buffers)[name] = meta

    def learner(self, k: int) -> nn.Module:
        """Learner ``k``'s network on its own: a copy of the architecture with learner ``k``'s parameters and
        buffers (detached from the stack)."""
        device = next(iter(self.params.values(True, True))).device
        network = copy.deepcopy(self.__dict__["_base"]).to_empty(device=device)
        self.params[k].detach().to_module(network, inplace=True)
        return network


def per_learner(module: nn.Module, k: int) -> nn.Module:
    """A copy of ``module`` (a block's policy or one of its networks, over ``K`` learners) in which every
    per-learner part (a module with a ``learner(k)`` method: a :class:`LearnerStack`, a normaliser's
    statistics…) is learner ``k``'s own: learner ``k``'s module, for one learner's envs.

    Examples:
        >>> stack = LearnerStack([nn.Linear(2, 1), nn.Linear(2, 1)])
        >>> one = per_learner(nn.Sequential(stack, nn.Tanh()), 1)
        >>> type(one[0]).__name__, torch.equal(one[0].weight, stack.params["weight"][1])
        ('Linear', True)
    """
    if callable(getattr(type(module), "learner", None)):  # (not TensorDictModule's, which reads its module's)
        return module.learner(k)  # type: ignore[operator]
    out = copy.copy(module)
    out._modules = {
        name: per_learner(child, k) if child is not None else None for name, child in module._modules.items()
    }
    return out


def learner_means(values: torch.Tensor, learners: int) -> torch.Tensor:
    """Each learner's mean of per-sample ``values`` (first dim the learner-major env batch, or the learners), ``[K]``.

    A learner's mean is its loss alone; the sum over learners is the batch's loss, whose
    gradient for each learner's parameters is its gradient alone.

    Examples:
        >>> learner_means(torch.tensor([[1.0, 3.0], [2.0, 2.0], [5.0, 7.0], [6.0, 6.0]]), 2).tolist()
        [2.0, 6.0]
    """
    return values.reshape(learners, -1).mean(1)


def clip_grad_norm_per_learner(parameters: Iterable[torch.Tensor], max_norm: float, learners: int) -> torch.Tensor:
    """``torch.nn.utils.clip_grad_norm_`` for each learner of stacked parameters (first dim ``K``): each
    learner's gradients scaled by ``min(1, max_norm / (‖g_k‖ + 1e-6))``; the learners' norms.

    Examples:
        >>> p = nn.Parameter(torch.zeros(2, 2))
        >>> p.grad = torch.tensor([[3.0, 4.0], [0.3, 0.4]])
        >>> clip_grad_norm_per_learner([p], 1.0, 2).tolist()
        [5.0, 0.5]
        >>> [round(g, 4) for g in p.grad.reshape(-1).tolist()]  # learner 0 clipped to norm 1, learner 1 kept
        [0.6, 0.8, 0.3, 0.4]
    """
    grads = [p.grad for p in parameters if p.grad is not None]
    for g in grads:
        if g.shape[0] != learners:
            raise ValueError(f"a parameter of shape {tuple(g.shape)} is not stacked over {learners} learners")
    if not grads:
        return torch.zeros(learners)
    norms = torch.stack([g.reshape(learners, -1).pow(2).sum(1) for g in grads]).sum(0).sqrt()
    scale = (max_norm / (norms + 1e-6)).clamp(max=1.0)
    for g in grads:
        g.mul_(scale.view(learners, *([1] * (g.dim() - 1))))
    return norms


class _LearnerSampler(Sampler):
    """Uniform sampling with replacement, independently for each learner of a ``[capacity, K]`` storage: a
    sample ``[K, B]``, row ``k`` learner ``k``'s own transitions (for one learner, the draws of TorchRL's
    ``RandomSampler``)."""

    def __init__(self, learners: int) -> None:
        super().__init__()
        self.learners = learners
        self.columns: torch.Tensor | None = None

    def sample(self, storage: Any, batch_size: int) -> tuple[tuple[torch.Tensor, torch.Tensor], dict[str, Any]]:
        if len(storage) == 0:
            raise RuntimeError("cannot sample from an empty replay buffer")
        rows = torch.randint(len(storage), (self.learners, batch_size))
        if self.columns is None or self.columns.shape != rows.shape:
            self.columns = torch.arange(self.learners).unsqueeze(1).expand_as(rows)
        return (rows, self.columns), {}

    def _empty(self) -> None:
        pass

    def dumps(self, path: Any) -> None:
        pass

    def loads(self, path: Any) -> None:
        pass

    def state_dict(self) -> dict[str, Any]:
        return {}

    def load_state_dict(self, state_dict: dict[str, Any]) -> None:
        pass


class LearnerReplay:
    """Every learner's replay buffer as one TorchRL :class:`~torchrl.data.ReplayBuffer` with a learner dim.

    The storage holds ``capacity`` rows of ``K`` transitions (a row: one transition of every learner); a
    sample is ``[K, batch_size]``, learner ``k``'s row drawn uniformly from its own transitions.

    Args:
        learners: ``K``.
        capacity: transitions per learner.
        batch_size: transitions per learner per sample.
        keys: the entries kept.
        device: where the storage lives.

    Examples:
        >>> replay = LearnerReplay(2, capacity=100, batch_size=5, keys=["x"])
        >>> replay.extend(TensorDict({"x": torch.tensor([[0.0], [0.0], [1.0], [1.0]])}, [4]))  # 2 learners x 2
        >>> sample = replay.sample()
        >>> sample.batch_size, sample["x"][1].unique().tolist()
        (torch.Size([2, 5]), [1.0])
    """

    def __init__(
        self,
        learners: int,
        capacity: int,
        batch_size: int,
        keys: Sequence[Any],
        device: torch.device | str = "cpu",
    ) -> None:
        self.learners, self.keys, self.device = learners, list(dict.fromkeys(keys)), torch.device(device)
        self.buffer = ReplayBuffer(
            storage=LazyTensorStorage(capacity, device=self.device),
            sampler=_LearnerSampler(learners),
            batch_size=batch_size,
        )

    def extend(self, data: TensorDictBase) -> None:
        """Store a collected batch (first dim the learner-major env batch, any further dims)."""
        own = data.select(*self.keys).reshape(self.learners, -1)  # [K, frames per learner]
        self.buffer.extend(own.transpose(0, 1).contiguous().to(self.device))

    def sample(self) -> TensorDictBase:
        """``[K, batch_size]`` transitions, learner ``k``'s from its own."""
        return self.buffer.sample()

    def __len__(self) -> int:
        return len(self.buffer)
