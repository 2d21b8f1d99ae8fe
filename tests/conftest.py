"""Suite-wide set-up: Ctrl-C must raise KeyboardInterrupt in the tests and in the processes they start.

A shell starts a background job (``make test &``, a CI runner without a terminal) with
SIGINT ignored, and an ignored signal stays ignored in every child process: the tests
that interrupt a sweep or a server with SIGINT would then hang. Restore Python's handler
here (handled signals are reset to the default in children, so they get theirs too).
"""

from __future__ import annotations

import contextlib
import signal

if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
    with contextlib.suppress(ValueError):  # only the main thread may set handlers
        signal.signal(signal.SIGINT, signal.default_int_handler)
