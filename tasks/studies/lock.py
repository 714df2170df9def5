"""One command at a time per output folder: ``OUT/.snn-neat.lock``.

Two commands writing one folder would mix their checkpoints, tables and champions without a
word. The lock file is held with ``flock`` for the command's life, so the kernel releases it
when the process ends, however it ends (SIGKILL included): a lock file left behind is stale
and is taken over. Where the filesystem has no ``flock`` (some network mounts), the PID written
in the file decides instead: the lock is stale when no process with that PID runs on this host.
"""

from __future__ import annotations

import errno
import fcntl
import json
import os
import socket
import time
from pathlib import Path

__all__ = ["LOCK_NAME", "LockError", "OutputLock"]

LOCK_NAME = ".snn-neat.lock"


class LockError(RuntimeError):
    """The output folder is in use by another running command."""


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # someone else's process: it exists
        return True
    return True


class OutputLock:
    """``with OutputLock(out, command):`` holds ``out``'s lock (``LockError`` if another
    running command holds it), and removes the lock file on leaving."""

    def __init__(self, folder: str | os.PathLike, command: str) -> None:
        self.folder = Path(folder)
        self.path = self.folder / LOCK_NAME
        self.command = command
        self._fd: int | None = None

    def _holder(self) -> dict:
        try:
            return json.loads(self.path.read_text())
        except (OSError, ValueError):
            return {}

    def _busy(self, holder: dict) -> LockError:
        since = holder.get("started")
        when = time.strftime(" since %Y-%m-%d %H:%M:%S", time.localtime(since)) if isinstance(since, (int, float)) else ""
        who = f"PID {holder.get('pid', '?')} on {holder.get('host', '?')}{when}"
        what = f", `{holder['command']}`" if holder.get("command") else ""
        return LockError(f"--out {str(self.folder)!r} is in use by another snn-neat command ({who}{what}): wait for it "
                         f"to finish or choose another --out (if no such process runs, delete {self.path})")

    def acquire(self) -> OutputLock:
        self.folder.mkdir(parents=True, exist_ok=True)
        while True:
            fd = os.open(self.path, os.O_RDWR | os.O_CREAT, 0o666)  # less the umask, as open() does
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                os.close(fd)
                raise self._busy(self._holder()) from None
            except OSError as exc:
                if exc.errno not in (errno.ENOLCK, errno.EOPNOTSUPP, errno.ENOSYS):
                    os.close(fd)
                    raise
                holder = self._holder()  # no flock here: judge by the PID
                if (holder.get("host") == socket.gethostname() and isinstance(holder.get("pid"), int)
                        and holder["pid"] != os.getpid() and _pid_alive(holder["pid"])):
                    os.close(fd)
                    raise self._busy(holder) from None
            # A holder may have removed the file between our open and our flock; then ours
            # is a lock on a deleted file, and the path needs a new one.
            try:
                same = os.fstat(fd).st_ino == os.stat(self.path).st_ino
            except FileNotFoundError:
                same = False
            if same:
                break
            os.close(fd)
        record = {"pid": os.getpid(), "host": socket.gethostname(), "started": time.time(), "command": self.command}
        os.ftruncate(fd, 0)
        os.pwrite(fd, json.dumps(record).encode(), 0)
        self._fd = fd
        return self

    def release(self) -> None:
        if self._fd is None:
            return
        try:
            self.path.unlink(missing_ok=True)  # while still held: no one can take a file about to vanish
        finally:
            os.close(self._fd)
            self._fd = None

    def __enter__(self) -> OutputLock:
        return self.acquire()

    def __exit__(self, *exc) -> None:
        self.release()
