"""Ctrl-C, SIGTERM and SIGHUP while tasks run: noted, then acted on between waits.

Outside the task loop a stop signal raises ``KeyboardInterrupt`` (Python's Ctrl-C, and the
CLI's handler for SIGTERM and SIGHUP). Inside it, an exception raised at an arbitrary
bytecode could land while the parent holds a lock of the executor's: in the middle of
``concurrent.futures.wait`` acquiring its futures' conditions, say, whose locks would then
stay held, so the pool's manager thread blocks on them and stopping the pool (which joins
that thread) hangs. The loop therefore installs :class:`StopRequest` for the signals whose
handler raises, waits with a short timeout (``engine._collect``), and stops the pool itself when
a request is seen. (That hang is our reading of one CI failure, not reproduced.)
"""

from __future__ import annotations

import signal
import threading
from contextlib import contextmanager

POLL_S = 0.1  # how long a stop request can wait to be seen
SIGNAL_NAMES = ("SIGINT", "SIGTERM", "SIGHUP")


class StopRequest:
    """Set by a stop signal; ``signum`` is the first one received (None: no request)."""

    def __init__(self) -> None:
        self.signum: int | None = None

    @property
    def requested(self) -> bool:
        return self.signum is not None

    def __call__(self, signum, frame) -> None:
        if self.signum is None:
            self.signum = signum


@contextmanager
def noted_stop_requests():
    """Yield a :class:`StopRequest` that the stop signals set instead of raising.

    Only signals whose handler is a Python function (``KeyboardInterrupt`` for Ctrl-C, the CLI's
    for SIGTERM and SIGHUP) are taken over: one left at its default or ignored keeps it. Off the
    main thread (a sweep run from a thread) nothing is installed and the request is never set.
    """
    request = StopRequest()
    if threading.current_thread() is not threading.main_thread():
        yield request
        return
    before = {}
    try:
        for name in SIGNAL_NAMES:
            sig = getattr(signal, name, None)
            if sig is not None and callable(signal.getsignal(sig)):
                before[sig] = signal.signal(sig, request)
        yield request
    finally:
        for sig, handler in before.items():
            signal.signal(sig, handler)
