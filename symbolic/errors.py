"""User-facing errors: one line naming the file, the key and the reason (exit code 2)."""

from __future__ import annotations


class GearsymError(Exception):
    """Bad user input. The CLI prints ``str(err)`` as one line and exits with code 2."""

    def __init__(self, file: str, key: str, reason: str) -> None:
        self.file = file
        self.key = key
        self.reason = reason
        super().__init__(f"{file}: {key}: {reason}" if key else f"{file}: {reason}")
