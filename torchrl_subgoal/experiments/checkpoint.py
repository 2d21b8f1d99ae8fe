"""Per-epoch checkpoints of one long learning, so that a re-run resumes mid-learning.

A learning's directory holds::

    state.pt                   everything but the replay data: networks, optimisers,
                               normaliser, potential, RNG states, per-epoch records,
                               and the number of finished epochs
    transitions/00001.pt ...   the transitions collected in each epoch, in order

Each file is written atomically (temporary file, fsync, rename). The transitions
of an epoch are written before the state that counts it, so a kill at any
moment leaves a consistent checkpoint: :meth:`LearningCheckpoint.load` reads
the state and the transition files of the epochs it counts, and ignores a
newer file left by a kill between the two writes. Replaying the stored
transitions in order into an empty replay buffer rebuilds its storage exactly,
also when it has wrapped around, so nothing of the buffer is written twice.

Random states of torch, numpy and Python are part of the state: a resumed
learning draws the same exploration noise and replay samples as an
uninterrupted one.
"""

from __future__ import annotations

import io
import os
import random
import shutil
from pathlib import Path
from typing import Any

import numpy as np
import torch
from tensordict import TensorDictBase

from torchrl_subgoal.experiments.store import _atomic_file

__all__ = ["LearningCheckpoint", "restore_rng_states", "rng_states"]

STATE_FILE = "state.pt"
TRANSITIONS_DIR = "transitions"


def rng_states() -> dict[str, Any]:
    """The global random states of torch, numpy and Python.

    Examples:
        >>> states = rng_states()
        >>> first = torch.rand(2)
        >>> restore_rng_states(states)
        >>> torch.equal(torch.rand(2), first)
        True
    """
    return {"torch": torch.get_rng_state(), "numpy": np.random.get_state(), "python": random.getstate()}


def restore_rng_states(states: dict[str, Any]) -> None:
    """Inverse of :func:`rng_states`.

    Examples:
        >>> states = rng_states()
        >>> first = np.random.rand(), random.random()
        >>> restore_rng_states(states)
        >>> (np.random.rand(), random.random()) == first
        True
    """
    torch.set_rng_state(states["torch"])
    np.random.set_state(states["numpy"])
    random.setstate(states["python"])


class LearningCheckpoint:
    """The checkpoint directory of one learning.

    Args:
        directory: created on the first :meth:`save`.

    Examples:
        >>> import tempfile
        >>> from tensordict import TensorDict
        >>> ckpt = LearningCheckpoint(tempfile.mkdtemp())
        >>> ckpt.load() is None
        True
        >>> ckpt.save(1, {"records": [0.5]}, TensorDict({"x": torch.ones(3)}, [3]))
        >>> state, transitions = ckpt.load()
        >>> state["epoch"], state["records"], [t["x"].sum().item() for t in transitions]
        (1, [0.5], [3.0])
    """

    def __init__(self, directory: str | os.PathLike[str]) -> None:
        self.directory = Path(directory)

    def _transitions_path(self, epoch: int) -> Path:
        return self.directory / TRANSITIONS_DIR / f"{epoch:05d}.pt"

    def save(self, epoch: int, state: dict[str, Any], transitions: TensorDictBase) -> None:
        """Record finished epoch ``epoch`` (1-based): its transitions, then the state."""
        _write(self._transitions_path(epoch), transitions)
        _write(self.directory / STATE_FILE, {**state, "epoch": int(epoch)})

    def load(self) -> tuple[dict[str, Any], list[TensorDictBase]] | None:
        """The saved state and the transitions of every epoch it counts, or ``None``."""
        path = self.directory / STATE_FILE
        if not path.exists():
            return None
        state = torch.load(path, weights_only=False)
        epochs = range(1, int(state["epoch"]) + 1)
        missing = [e for e in epochs if not self._transitions_path(e).exists()]
        if missing:
            raise FileNotFoundError(
                f"{self.directory}: checkpoint of epoch {state['epoch']} lacks the transitions of "
                f"epoch(s) {missing}; delete the directory to restart this learning"
            )
        transitions = [torch.load(self._transitions_path(e), weights_only=False) for e in epochs]
        return state, transitions

    def clear(self) -> None:
        """Delete the directory (e.g. once the learning's results are stored)."""
        shutil.rmtree(self.directory, ignore_errors=True)


def _write(path: Path, obj: Any) -> None:
    buffer = io.BytesIO()
    torch.save(obj, buffer)
    with _atomic_file(path) as handle:
        handle.write(buffer.getbuffer())
