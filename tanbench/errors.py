"""User-facing errors: one clear line, exit code 2, no traceback (unless --debug)."""

from __future__ import annotations

import os
import traceback


class TanbenchError(Exception):
    """A problem with the user's input or environment, explained in one line.

    The CLI prints ``str(error)`` and exits with ``exit_code``; the message must
    name what is wrong (the file, the key, the value) and, where it helps, what to do.
    """

    exit_code = 2

    def __init__(self, message: str):
        super().__init__(" ".join(str(message).split()))


def describe_exception(exc: BaseException) -> str:
    """An exception as one line: ``Type: message (at file.py:line)`` (a TanbenchError: its message),
    the place being where it was raised."""
    if isinstance(exc, TanbenchError):
        return str(exc)
    text = " ".join(str(exc).split())
    last = traceback.extract_tb(exc.__traceback__)[-1] if exc.__traceback__ else None
    where = f" (at {os.path.basename(last.filename)}:{last.lineno})" if last else ""
    return f"{type(exc).__name__}: {text}{where}" if text else f"{type(exc).__name__}{where}"
