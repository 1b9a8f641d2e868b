"""A worker function for tests/test_resume.py: it leaves half a result message in the
process pool's result pipe and never finishes it, as a worker stopped mid-send does."""

from __future__ import annotations

import gc
import struct
import time
from pathlib import Path


def send_half_a_result(sent: str) -> None:
    """Send half a message, then touch the file ``sent`` and wait."""
    from multiprocessing.queues import SimpleQueue

    queue = next(q for q in gc.get_objects() if isinstance(q, SimpleQueue))
    with queue._wlock:
        # a message header announcing 1 MB, then 10 bytes of it
        queue._writer._send(struct.pack("!i", 1 << 20) + b"0123456789")
        Path(sent).touch()
        time.sleep(3600)
