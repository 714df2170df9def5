"""Build small C kernels once with the system compiler and load them with ``ctypes``.

Libraries are cached under ``$SNN_NEAT_CACHE`` (default ``~/.cache/snn_neat``), keyed by
source, flags, compiler and CPU, and written atomically (build in a temp folder, rename),
so concurrent processes never load half a library. ``SNN_NEAT_FUSED=0`` disables every
kernel; callers then use their torch reference path.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import shutil
import subprocess
import sys
import tempfile
import warnings
from pathlib import Path

__all__ = ["load_c_library", "kernels_enabled"]

# No contraction, no fast-math: the kernels must repeat torch's IEEE operations exactly.
FLAGS = ["-O3", "-march=native", "-ffp-contract=off", "-fno-fast-math", "-fopenmp", "-shared", "-fPIC", "-std=c11"]
_cache: dict[str, ctypes.CDLL | None] = {}


def kernels_enabled() -> bool:
    return os.environ.get("SNN_NEAT_FUSED", "1") != "0"


def _cpu_signature() -> str:
    # -march=native code must not be loaded on a different CPU sharing the same cache folder.
    try:
        with open("/proc/cpuinfo") as f:
            return next((line for line in f if line.startswith(("flags", "Features"))), "")
    except OSError:
        return ""


def _build(name: str, source: str) -> ctypes.CDLL | None:
    cc = os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")
    if cc is None:
        return None
    key = hashlib.sha256((source + " ".join(FLAGS) + cc + sys.platform + _cpu_signature()).encode()).hexdigest()[:16]
    root = Path(os.environ.get("SNN_NEAT_CACHE") or Path.home() / ".cache" / "snn_neat")
    target = root / f"{name}_{key}.so"
    if not target.exists():
        root.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(dir=root) as tmp:
            src, out = Path(tmp) / f"{name}.c", Path(tmp) / f"{name}.so"
            src.write_text(source)
            proc = subprocess.run([cc, *FLAGS, str(src), "-o", str(out), "-lm"], capture_output=True, text=True)
            if proc.returncode != 0:
                warnings.warn(f"snn-neat: C kernel {name!r} did not compile; using the torch path\n{proc.stderr}",
                              RuntimeWarning, stacklevel=3)
                return None
            os.replace(out, target)
    return ctypes.CDLL(str(target))


def load_c_library(name: str, source: str) -> ctypes.CDLL | None:
    """The compiled library, or None (no compiler, build failed, or kernels disabled)."""
    if not kernels_enabled():
        return None
    if name not in _cache:
        try:
            _cache[name] = _build(name, source)
        except OSError as exc:  # unwritable cache, unloadable library: fall back and say why
            warnings.warn(f"snn-neat: C kernel {name!r} unavailable ({exc}); using the torch path",
                          RuntimeWarning, stacklevel=2)
            _cache[name] = None
    return _cache[name]
