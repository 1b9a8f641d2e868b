"""User-facing errors: one clear line, exit code 2, no traceback (unless --debug)."""


class TanbenchError(Exception):
    """A problem with the user's input or environment, explained in one line.

    The CLI prints ``str(error)`` and exits with ``exit_code``; the message must
    name what is wrong (the file, the key, the value) and, where it helps, what to do.
    """

    exit_code = 2

    def __init__(self, message: str):
        super().__init__(" ".join(str(message).split()))
