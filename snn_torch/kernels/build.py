"""Build the package's C kernels once per machine with the system compiler; load them with ``ctypes``.

Kernels are ``.c``/``.h`` files shipped as package data (``snn_torch/kernels/csrc``, ``evolution/kernels/csrc``).
Each library's exported functions are declared once, in its header: ``load_library`` reads the
prototypes there and sets every function's ``ctypes`` signature from them, and the ``.c`` file
includes the header, so the compiler checks that the definitions match. A header function
missing from the built library is an error at load. Entry points with many parameters take
them as structs declared in the header (``parse_structs`` reads them), mirrored in Python by
``KernelStruct`` subclasses, so that no parameter can shift into another's place. Headers a
file includes by ``#include "name.h"`` are read from its folder (else from ``snn_torch/kernels/csrc``, the shared
headers) and are part of the build (and its cache key).
``load_libraries`` builds several libraries side by side, one compiler process each.

Libraries are cached under ``$SNN_NEAT_CACHE`` (default ``~/.cache/snn_neat``), keyed by the
sources, flags, compiler and CPU, and written atomically (build in a temp folder, rename), so
concurrent processes never load half a library. A build prints one line to stderr. With no
compiler, a failed build, an unwritable cache or ``SNN_NEAT_C_KERNELS=0``, ``load_library`` returns
None and callers use their torch path, which gives the same results (tested), only slower.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import re
import shutil
import subprocess
import sys
import tempfile
import threading
import time
import warnings
from collections.abc import Sequence
from pathlib import Path

__all__ = ["load_library", "load_libraries", "kernels_enabled", "parse_prototypes", "parse_structs",
           "KernelLibrary", "KernelStruct", "library_loader"]

# No contraction, no fast-math: the kernels must repeat torch's IEEE operations exactly.
FLAGS = ["-O3", "-march=native", "-ffp-contract=off", "-fno-fast-math", "-fopenmp", "-shared", "-fPIC", "-std=c11"]
_cache: dict[str, object] = {}
_lock = threading.Lock()  # one build per library and process, whichever thread asks first

_CTYPES = {
    "void": None, "int": ctypes.c_int, "int64_t": ctypes.c_int64, "uint64_t": ctypes.c_uint64,
    "int32_t": ctypes.c_int32, "uint32_t": ctypes.c_uint32, "uint8_t": ctypes.c_uint8,
    "float": ctypes.c_float, "double": ctypes.c_double,
}
_PROTOTYPE = re.compile(r"^\s*(\w+)\s+(\w+)\s*\(([^)]*)\)\s*;", re.MULTILINE)
_STRUCT = re.compile(r"typedef\s+struct\s*\w*\s*\{([^}]*)\}\s*(\w+)\s*;")
_FIELD = re.compile(r"^(?:const\s+)?(\w+)\s*(\*?)\s*(?:const\s+)?(\w+)\s*(?:\[(\d+)\])?$")
SHARED_CSRC = Path(__file__).resolve().parent / "csrc"  # headers every library may include (counter_rng.h)
_LOCAL_INCLUDE = re.compile(r'^\s*#\s*include\s+"([^"]+)"', re.MULTILINE)


ENV_SWITCH = "SNN_NEAT_C_KERNELS"
_ENV_SWITCH_OLD = "SNN_NEAT_FUSED"  # the old name ("fused" meant "C kernel"), still read
_warned_old_switch = False


def kernels_enabled() -> bool:
    """False when ``SNN_NEAT_C_KERNELS=0``: every C kernel off, the torch paths run.

    ``SNN_NEAT_FUSED``, the variable's old name, is still read when the new one is unset (with a
    ``DeprecationWarning``, once)."""
    global _warned_old_switch
    value = os.environ.get(ENV_SWITCH)
    if value is None:
        value = os.environ.get(_ENV_SWITCH_OLD)
        if value is not None and not _warned_old_switch:
            _warned_old_switch = True
            warnings.warn(f"{_ENV_SWITCH_OLD} is deprecated; set {ENV_SWITCH} instead", DeprecationWarning,
                          stacklevel=2)
    return value != "0"


def parse_prototypes(header: str) -> dict[str, tuple[object, list[object]]]:
    """``{name: (restype, argtypes)}`` for every function prototype in ``header``'s text.

    Pointers of any type map to ``c_void_p``; scalars to their ctypes type. An unknown type
    raises ``ValueError`` naming the function and the parameter.
    """
    text = re.sub(r"/\*.*?\*/", "", header, flags=re.DOTALL)
    out: dict[str, tuple[object, list[object]]] = {}
    for ret, name, params in _PROTOTYPE.findall(text):
        if ret not in _CTYPES:
            raise ValueError(f"prototype {name}: unknown return type {ret!r}")
        argtypes: list[object] = []
        for param in (p.strip() for p in params.split(",")):
            if not param or param == "void":
                continue
            if "*" in param:
                argtypes.append(ctypes.c_void_p)
                continue
            words = [w for w in param.split() if w != "const"]
            if len(words) != 2 or words[0] not in _CTYPES or words[0] == "void":
                raise ValueError(f"prototype {name}: cannot map parameter {param!r} to a ctypes type")
            argtypes.append(_CTYPES[words[0]])
        out[name] = (_CTYPES[ret], argtypes)
    return out


def parse_structs(header: str) -> dict[str, list[tuple[str, object]]]:
    """``{name: [(field, ctypes type), ...]}`` for every ``typedef struct { ... } name;`` in
    ``header``'s text, in declaration order: what a ``ctypes.Structure`` mirroring it must hold.

    Pointers of any type map to ``c_void_p``, ``T name[K]`` to ``ctype * K``. A field is one
    declarator per statement; anything else (several names, function pointers, unknown types)
    raises ``ValueError`` naming the struct and the field.
    """
    text = re.sub(r"/\*.*?\*/", "", header, flags=re.DOTALL)
    out: dict[str, list[tuple[str, object]]] = {}
    for body, name in _STRUCT.findall(text):
        fields: list[tuple[str, object]] = []
        for decl in (d.strip() for d in body.split(";")):
            if not decl:
                continue
            m = _FIELD.match(" ".join(decl.split()))
            if m is None or (not m.group(2) and (m.group(1) not in _CTYPES or m.group(1) == "void")):
                raise ValueError(f"struct {name}: cannot map field {decl!r} to a ctypes type")
            ctype = ctypes.c_void_p if m.group(2) else _CTYPES[m.group(1)]
            fields.append((m.group(3), ctype * int(m.group(4)) if m.group(4) else ctype))
        out[name] = fields
    return out


class KernelStruct(ctypes.Structure):
    """Base of the ``ctypes.Structure`` mirrors of the kernels' parameter structs (declared in
    their headers; ``parse_structs`` reads those, and the tests compare the two). Built with
    every field named: a field left out would silently be 0 or NULL, a misspelt one ignored."""

    def __init__(self, **values: object) -> None:
        names = {name for name, _ in self._fields_}
        missing, unknown = names - values.keys(), values.keys() - names
        if missing or unknown:
            raise TypeError(f"{type(self).__name__}: missing fields {sorted(missing)}, unknown {sorted(unknown)}")
        super().__init__(**values)


class KernelLibrary:
    """A loaded kernel library whose functions carry the signatures of its header."""

    def __init__(self, dll: ctypes.CDLL, prototypes: dict[str, tuple[object, list[object]]], path: Path) -> None:
        self.path = path
        self.functions = {}
        for name, (restype, argtypes) in prototypes.items():
            try:
                fn = getattr(dll, name)
            except AttributeError:
                raise ImportError(f"C kernel library {path.name}: {name} is declared in the header but not "
                                  "defined in the library") from None
            fn.restype, fn.argtypes = restype, argtypes
            self.functions[name] = fn

    def __getattr__(self, name: str):
        try:
            return self.__dict__["functions"][name]
        except KeyError:
            raise AttributeError(f"{name} is not declared in this library's header") from None


def _cpu_signature() -> str:
    # -march=native code must not be loaded on a different CPU sharing the same cache folder.
    try:
        with open("/proc/cpuinfo") as f:
            return next((line for line in f if line.startswith(("flags", "Features"))), "")
    except OSError:
        return ""


def _compiler() -> str | None:
    return os.environ.get("CC") or shutil.which("cc") or shutil.which("gcc")


def _cache_root() -> Path:
    return Path(os.environ.get("SNN_NEAT_CACHE") or Path.home() / ".cache" / "snn_neat")


class _Build:
    """A compiler process building one library into a temporary folder of the cache."""

    def __init__(self, name: str, files: dict[str, str], main: str, cc: str, target: Path) -> None:
        self.name, self.target, self.t0 = name, target, time.perf_counter()
        self.path: Path | None = None  # the cached library, once built
        self.tmp = tempfile.TemporaryDirectory(dir=target.parent)
        folder = Path(self.tmp.name)
        self.out, self.log = folder / f"{name}.so", folder / "cc.log"
        try:
            for file_name, text in files.items():
                (folder / file_name).write_text(text)
            with open(self.log, "w") as log:  # a file, not a pipe: a long log cannot stall the compiler
                self.proc = subprocess.Popen([cc, *FLAGS, str(folder / main), "-o", str(self.out), "-lm"],
                                             stdout=subprocess.DEVNULL, stderr=log)
        except OSError:  # a full disk, a compiler that will not start
            self.tmp.cleanup()
            raise

    def finish(self) -> Path | None:
        """Wait for the compiler; the cached library's path, or None (warned) if it failed."""
        try:
            if self.proc.wait() != 0:
                warnings.warn(f"snn-neat: C kernel {self.name!r} did not compile; using the torch path\n"
                              f"{self.log.read_text()}", RuntimeWarning, stacklevel=4)
                return None
            os.replace(self.out, self.target)
        finally:
            self.tmp.cleanup()
        print(f"snn-neat: built C kernel {self.name!r} once for this machine "
              f"({time.perf_counter() - self.t0:.1f} s, cached in {self.target.parent})", file=sys.stderr)
        self.path = self.target
        return self.path


def _start(name: str, files: dict[str, str], main: str, cc: str) -> Path | _Build:
    """The cached library built from ``files`` (name -> text; ``main`` the translation unit), or
    its build, started."""
    key_text = "\0".join(f"{k}\0{v}" for k, v in sorted(files.items()))
    key = hashlib.sha256((key_text + " ".join(FLAGS) + cc + sys.platform + _cpu_signature()).encode()).hexdigest()[:16]
    root = _cache_root()
    target = root / f"{name}_{key}.so"
    if target.exists():
        return target
    root.mkdir(parents=True, exist_ok=True)
    return _Build(name, files, main, cc, target)


def _compile(name: str, files: dict[str, str], main: str, cc: str) -> Path | None:
    """Build ``files`` into the cache (or find them there); the .so path."""
    build = _start(name, files, main, cc)
    return build if isinstance(build, Path) else build.finish()


def _library_files(source: Path, header: Path | None, include_dirs: Sequence[Path] = ()) -> dict[str, str]:
    """``source``, ``header`` and the local headers they include, transitively (name -> text)."""
    files: dict[str, str] = {}
    pending = [source] if header is None else [source, header]
    while pending:
        path = pending.pop()
        if path.name in files:
            continue
        files[path.name] = text = path.read_text()
        for inc in _LOCAL_INCLUDE.findall(text):  # the file's own folder, then include_dirs, then the shared headers
            found = [d / inc for d in (path.parent, *include_dirs) if (d / inc).exists()]
            pending.append(found[0] if found else SHARED_CSRC / inc)
    return files


def load_library(name: str, source: Path, header: Path | str, *,
                 include_dirs: Sequence[Path] = ()) -> KernelLibrary | None:
    """The kernel library built from ``source`` (which includes ``header``), or None. Headers it
    includes are read from its folder, then ``include_dirs``, then ``snn_torch/kernels/csrc``.

    None: no compiler, the build failed, the cache is unwritable, or kernels are disabled
    (``SNN_NEAT_C_KERNELS=0``); each but the last warns once with the reason.
    """
    return load_libraries([(name, source, header)], include_dirs=include_dirs)[0]


def load_libraries(specs: Sequence[tuple[str, Path, Path | str]], *,
                   include_dirs: Sequence[Path] = ()) -> list[KernelLibrary | None]:
    """``load_library`` for each ``(name, source, header)``; those not yet built compile side by
    side (one compiler each, so a cold start waits for the slowest, not the sum). ``header`` may
    be the prototypes' text instead of a file (the native plants' generated declarations)."""
    if not kernels_enabled():
        return [None] * len(specs)
    if all(name in _cache for name, _, _ in specs):  # the kernels' every call: no lock
        return [_cache[name] for name, _, _ in specs]  # type: ignore[misc]
    with _lock:
        cc = _compiler()
        libs: dict[str, KernelLibrary | None] = {}
        started: dict[str, tuple[Path | _Build, str]] = {}
        for name, source, header in specs:
            if name in _cache or name in libs:
                continue
            libs[name] = None
            if cc is None:
                continue
            try:
                files = _library_files(source, header if isinstance(header, Path) else None, include_dirs)
                prototypes = files[header.name] if isinstance(header, Path) else header
                started[name] = (_start(name, files, source.name, cc), prototypes)
            except OSError as exc:  # unreadable sources, unwritable cache: fall back and say why
                _unavailable(name, exc)
        running = [build for build, _ in started.values() if isinstance(build, _Build)]
        while running:  # each finished as it ends, so that it reports its own build time
            for build in [b for b in running if b.proc.poll() is not None]:
                running.remove(build)
                try:
                    build.finish()
                except OSError as exc:
                    _unavailable(build.name, exc)
            if running:
                time.sleep(0.01)
        for name, (build, header_text) in started.items():
            path = build if isinstance(build, Path) else build.path
            if path is not None:
                try:
                    libs[name] = KernelLibrary(ctypes.CDLL(str(path)), parse_prototypes(header_text), path)
                except OSError as exc:  # unloadable library
                    _unavailable(name, exc)
        _cache.update(libs)  # only now: the lock-free check above must not see a library being built
        return [_cache[name] for name, _, _ in specs]  # type: ignore[misc]


def _unavailable(name: str, exc: OSError) -> None:
    warnings.warn(f"snn-neat: C kernel {name!r} unavailable ({exc}); using the torch path", RuntimeWarning,
                  stacklevel=4)


def library_loader(name: str, source: Path, header: Path, missing_note: str | None = None):
    """A function returning the library (``load_library``), looked up once per value of
    ``kernels_enabled()`` (``SNN_NEAT_C_KERNELS`` may change at any time: tests set it). Where the
    library cannot be built, ``missing_note`` (what the fallback costs) is warned once."""
    loaded: dict[bool, KernelLibrary | None] = {}

    def library() -> KernelLibrary | None:
        enabled = kernels_enabled()
        if enabled not in loaded:
            lib = loaded[enabled] = load_library(name, source, header)
            if lib is None and enabled and missing_note:
                warnings.warn(missing_note, RuntimeWarning, stacklevel=3)
        return loaded[enabled]

    return library
