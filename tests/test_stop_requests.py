"""Stop signals during the task loop are noted, not raised (runner/stop_requests.py).

An exception raised inside ``concurrent.futures.wait`` while it holds its futures' locks can
leave them held, and stopping the pool then hangs: the CLI did not stop within 30 s of a
SIGTERM once in CI. The end-to-end behaviour is tested in test_resume.py."""

from __future__ import annotations

import os
import signal
import threading

import pytest

from tanbench.runner.stop_requests import noted_stop_requests


def _raise(signum, frame):
    raise KeyboardInterrupt


@pytest.fixture
def cli_like_handlers():
    """SIGTERM raising KeyboardInterrupt (as the CLI installs it), SIGHUP left at its default."""
    before = {signal.SIGTERM: signal.signal(signal.SIGTERM, _raise),
              signal.SIGHUP: signal.signal(signal.SIGHUP, signal.SIG_DFL)}
    yield
    for sig, handler in before.items():
        signal.signal(sig, handler)


def test_a_raising_handler_is_taken_over_and_restored(cli_like_handlers):
    with noted_stop_requests() as stop:
        assert not stop.requested
        os.kill(os.getpid(), signal.SIGTERM)  # delivered at once to this (the main) thread: no exception
        assert stop.signum == signal.SIGTERM
        os.kill(os.getpid(), signal.SIGINT)  # the first request is the one kept
        assert stop.signum == signal.SIGTERM
        assert signal.getsignal(signal.SIGHUP) is signal.SIG_DFL  # a default handler is left alone
    assert signal.getsignal(signal.SIGTERM) is _raise
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    with pytest.raises(KeyboardInterrupt):
        os.kill(os.getpid(), signal.SIGTERM)


def test_off_the_main_thread_nothing_is_installed(cli_like_handlers):
    seen = {}

    def body():
        with noted_stop_requests() as stop:
            seen["requested"] = stop.requested
            seen["handler"] = signal.getsignal(signal.SIGTERM)

    thread = threading.Thread(target=body)
    thread.start()
    thread.join()
    assert seen == {"requested": False, "handler": _raise}
