"""Suite-wide set-up: Ctrl-C must raise KeyboardInterrupt in the tests and in the processes they start.

A shell starts a background job (``make test &``, a CI runner without a terminal) with
SIGINT ignored, and an ignored signal stays ignored in every child process: the tests
that interrupt a sweep or a server with SIGINT would then hang. Restore Python's handler
here (handled signals are reset to the default in children, so they get theirs too).

Every test also starts from the same global random state, so a test that draws from it
(a random rollout, an initialisation) sees the same draws whichever tests ran before it
in the same worker process.
"""

from __future__ import annotations

import contextlib
import random
import signal
from collections.abc import Iterator

import numpy as np
import pytest
import torch

if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    with contextlib.suppress(ValueError):  # only the main thread may set handlers
        signal.signal(signal.SIGINT, signal.default_int_handler)


@pytest.fixture(autouse=True)
def _same_random_state_for_every_test() -> Iterator[None]:
    random.seed(0)
    np.random.seed(0)
    torch.manual_seed(0)
    yield
