"""File modes for atomic writes: ``mkstemp`` makes 0o600, an ordinary new file 0o666 less the umask."""

from __future__ import annotations

import os

__all__ = ["current_umask", "file_mode"]


def current_umask() -> int:
    """The process's umask, read without changing it where Linux shows it (``os.umask`` sets
    it, and a thread creating a file meanwhile would get the wrong mode)."""
    try:
        with open("/proc/self/status", encoding="ascii") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def file_mode() -> int:
    """The mode an ordinary new file gets (0o666 less the umask); ``mkstemp`` makes 0o600."""
    return 0o666 & ~current_umask()
