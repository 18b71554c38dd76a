"""vltm's exceptions: one-line messages, the same as the command line prints; and its
warnings (``RuntimeWarning``), the lines the command line writes to stderr."""

from __future__ import annotations

from typing import Optional


class VltmError(Exception):
    """Any error of vltm (the message is the library's one-line message)."""


class ArgumentError(VltmError, ValueError):
    """A bad argument: malformed or out of range (the command line's exit code 2)."""


class DataError(VltmError, OSError):
    """Unreadable or malformed input data (the command line's exit code 1)."""


def _warn(msg: Optional[str]) -> None:
    if msg:
        import warnings

        warnings.warn(f"vltm: {msg}", RuntimeWarning, stacklevel=3)
