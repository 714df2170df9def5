"""Atomic files: checkpoints of a whole NEAT state, written to a temp file then renamed."""

from __future__ import annotations

import hashlib
import io
import os
import re
import tempfile
from pathlib import Path
from typing import Any

import torch

from snn_torch._files import current_umask, file_mode  # noqa: F401 - re-exported (evolution.checkpoint.file_mode)

__all__ = ["CheckpointError", "atomic_write_bytes", "atomic_torch_save", "load_checkpoint_dict", "clean_stale_temps",
           "file_mode",
           "CHECKPOINT_FORMAT", "CHECKPOINT_VERSION"]

CHECKPOINT_FORMAT = "snn-neat-checkpoint"
# 2: counter-based GA streams (``RunRNG`` offsets); version 1 held mt19937 generator states.
CHECKPOINT_VERSION = 2
# File layout: MAGIC, the SHA-256 of the payload (32 bytes), the payload (torch.save bytes).
# torch.load does not notice flipped bytes inside tensor data; the digest does.
MAGIC = b"SNN-NEAT-CKPT\n"


class CheckpointError(ValueError):
    """A checkpoint or genome file is missing, truncated, corrupted or of another format."""


# Temp names: mkstemp's ``.NAME.`` + 8 characters of [a-z0-9_] + ``.tmp`` (this module) or
# ``.png`` (``snn_torch.plots.save_figure``).
_TEMP_NAME = re.compile(r"^\..+\.[a-z0-9_]{8}\.(tmp|png)$")


def clean_stale_temps(*folders: str | os.PathLike) -> list[Path]:
    """Remove the temp files that interrupted atomic writes left in ``folders`` (not below them:
    a folder the user named may hold anything). A killed process cannot remove its own. Only
    safe while no other process writes there: call it holding the folder's lock. Returns the
    paths removed."""
    removed = []
    for folder in folders:
        for path in Path(folder).glob(".*"):
            if _TEMP_NAME.match(path.name) and path.is_file() and not path.is_symlink():
                path.unlink(missing_ok=True)
                removed.append(path)
    return removed


def _atomic(path: str | os.PathLike, write) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as fh:
            os.fchmod(fh.fileno(), file_mode())  # as open() would have made it, not mkstemp's 0o600
            write(fh)
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)  # atomic on POSIX: readers see the old file or the new one
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def atomic_write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    return _atomic(path, lambda fh: fh.write(data))


def atomic_torch_save(obj: Any, path: str | os.PathLike) -> Path:
    """``torch.save(obj)`` with a SHA-256 digest, written atomically."""
    buf = io.BytesIO()
    torch.save(obj, buf)
    payload = buf.getvalue()
    return atomic_write_bytes(path, MAGIC + hashlib.sha256(payload).digest() + payload)


def load_checkpoint_dict(path: str | os.PathLike, *, map_location: str | torch.device | None = None) -> dict:
    """Load and check a checkpoint's envelope; raise ``CheckpointError`` naming the file."""
    name = os.fspath(path)
    try:
        with open(name, "rb") as fh:
            raw = fh.read()
    except FileNotFoundError:
        raise CheckpointError(f"checkpoint {name!r} does not exist") from None
    except OSError as exc:
        raise CheckpointError(f"cannot read checkpoint {name!r}: {exc}") from exc
    if not raw.startswith(MAGIC):
        raise CheckpointError(f"{name!r} is not an snn-neat checkpoint (no snn-neat header)")
    digest, payload = raw[len(MAGIC): len(MAGIC) + 32], raw[len(MAGIC) + 32:]
    if hashlib.sha256(payload).digest() != digest:
        raise CheckpointError(f"checkpoint {name!r} is truncated or corrupted (checksum mismatch)")
    try:
        data = torch.load(io.BytesIO(payload), map_location=map_location, weights_only=True)
    except Exception as exc:  # torch raises many types for a damaged zip/pickle
        raise CheckpointError(f"checkpoint {name!r} is truncated or corrupted ({type(exc).__name__}: {exc})") from exc
    if not isinstance(data, dict) or data.get("format") != CHECKPOINT_FORMAT:
        raise CheckpointError(f"{name!r} is not an snn-neat checkpoint")
    if data.get("version") != CHECKPOINT_VERSION:
        raise CheckpointError(f"checkpoint {name!r} has version {data.get('version')!r}; "
                              f"this snn-neat reads version {CHECKPOINT_VERSION} (version 1 checkpoints hold mt19937 "
                              "streams, which this version no longer draws; resume them with snn-neat at commit "
                              "509348d, the last before the counter-based streams)")
    return data
