"""C code generated from the model's CasADi graphs, compiled into shared libraries cached on disk.

Shared by the compiled Powell of SUMT (:mod:`tolsynth.solvers.cpowell`) and the compiled
Levenberg-Marquardt of the map's inverse kinematics (:mod:`tolsynth.kinematics.ik_compiled`): each writes
one C file (CasADi's generated code for its graph and a hand-written driver) and loads it here.

The library is cached on disk, keyed by a hash of the C source, the compiler, its flags and the
CasADi version (and the processor, for a library built for its vector units): ``$TOLSYNTH_CACHE_DIR``, else ``$XDG_CACHE_HOME/tolsynth``, else
``~/.cache/tolsynth`` (a temporary directory if none is writable).  ``TOLSYNTH_NO_COMPILE=1``
turns compilation off (the callers then use their Python paths); ``TOLSYNTH_CC`` (or ``CC``)
names the compiler, by default ``cc``, ``gcc`` or ``clang`` on the PATH.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import shutil
import subprocess
import tempfile
import threading
from pathlib import Path
from typing import Any, Callable

import casadi as ca

__all__ = ["CFLAGS", "NATIVE_FLAGS", "cache_dir", "find_compiler", "disabled", "load_library", "GraphLibraries"]

#: -ffp-contract=off: no fused multiply-adds, so the compiled arithmetic is the IEEE arithmetic of
#: the Python/CasADi paths operation for operation
CFLAGS = ["-O2", "-fPIC", "-shared", "-ffp-contract=off"]

#: added for the libraries built for this machine's vector units (the certified search's kernels):
#: wider vectors, the same IEEE operations (no contraction, no reassociation), so the same bits
NATIVE_FLAGS = ["-march=native"]

#: the C library headers every driver may use (written before it)
C_INCLUDES = "#include <float.h>\n#include <math.h>\n#include <stdlib.h>\n#include <string.h>\n"

_lock = threading.Lock()
_loaded: dict[str, tuple[ctypes.CDLL, Path]] = {}  # by key


def cache_dir() -> Path:
    """Where compiled libraries are kept (created on demand; see the module docstring)."""
    env = os.environ.get("TOLSYNTH_CACHE_DIR")
    if env:
        return Path(env)
    xdg = os.environ.get("XDG_CACHE_HOME")
    base = Path(xdg) if xdg else Path.home() / ".cache"
    return base / "tolsynth"


_found: dict[tuple, str | None] = {}


def find_compiler() -> str | None:
    """The C compiler to use (full path), or None if there is none (looked up once per value of
    the environment variables it depends on)."""
    key = tuple(os.environ.get(k) for k in ("TOLSYNTH_CC", "CC", "PATH"))
    if key not in _found:
        name = key[0] or key[1]
        _found[key] = shutil.which(name) if name else shutil.which("cc") or shutil.which("gcc") or shutil.which("clang")
    return _found[key]


def disabled() -> bool:
    """True when ``TOLSYNTH_NO_COMPILE`` is set (to anything but "" or "0")."""
    return os.environ.get("TOLSYNTH_NO_COMPILE", "") not in ("", "0")


def _writable_dir() -> Path:
    for d in (cache_dir(), Path(tempfile.gettempdir()) / f"tolsynth-{os.getuid() if hasattr(os, 'getuid') else 0}"):
        try:
            d.mkdir(parents=True, exist_ok=True)
            if os.access(d, os.W_OK):
                return d
        except OSError:
            continue
    raise OSError("no writable cache directory")


def _cpu() -> str:
    """What a library built with NATIVE_FLAGS depends on: the machine and its processor's feature
    flags (so that a cache shared between machines never hands one a library for another)."""
    import platform

    flags = ""
    try:
        with open("/proc/cpuinfo") as fh:
            flags = next((line for line in fh if line.startswith(("flags", "Features"))), "")
    except OSError:
        pass
    return f"{platform.machine()} {platform.processor()} {flags}"


def _build(source: str, name: str, cc: str, flags: list[str]) -> Path:
    """Compile ``source`` into ``<cache>/<name>.so`` unless it is there (atomic: a temporary name,
    then a rename, so concurrent processes never load a half-written library)."""
    d = _writable_dir()
    target = d / f"{name}.so"
    if target.exists():
        return target
    fd, c_path = tempfile.mkstemp(suffix=".c", dir=d)
    with os.fdopen(fd, "w") as fh:
        fh.write(source)
    tmp_so = c_path[:-2] + ".so"
    try:
        proc = subprocess.run([cc, *flags, "-o", tmp_so, c_path, "-lm"], capture_output=True, text=True, timeout=300)
        if proc.returncode != 0:
            raise RuntimeError(proc.stderr.strip()[-2000:] or f"{cc} exited {proc.returncode}")
        os.replace(tmp_so, target)
    except subprocess.SubprocessError as err:  # a timeout
        raise RuntimeError(str(err)) from None
    finally:
        for p in (c_path, tmp_so):
            try:
                os.unlink(p)
            except OSError:
                pass
    return target


def load_library(
    source: str, prefix: str, cc: str, symbols: tuple[str, ...], native: bool = False
) -> tuple[ctypes.CDLL, Path]:
    """The shared library compiled from ``source`` by ``cc`` (built on first use, then loaded from
    the cache; once per process), with each of ``symbols`` present; with ``native``, built for
    this machine's processor (NATIVE_FLAGS; without them where the compiler refuses them).  Raises
    OSError, AttributeError or RuntimeError (the compiler's message) when it cannot be built or
    loaded."""
    if native:
        try:
            return _load(source, prefix, cc, symbols, CFLAGS + NATIVE_FLAGS, _cpu())
        except RuntimeError:
            pass
    return _load(source, prefix, cc, symbols, CFLAGS, "")


def _load(source, prefix, cc, symbols, flags, cpu):
    key = hashlib.sha256("\0".join([source, cc, " ".join(flags), cpu, ca.__version__]).encode()).hexdigest()[:24]
    name = f"{prefix}_{key}"
    with _lock:
        if name in _loaded:
            return _loaded[name]
        try:
            path = _build(source, name, cc, flags)
            lib = ctypes.CDLL(str(path))
            for sym in symbols:
                getattr(lib, sym)
        except (OSError, AttributeError):  # a damaged file in the cache: build it again, once
            (_writable_dir() / f"{name}.so").unlink(missing_ok=True)
            path = _build(source, name, cc, flags)
            lib = ctypes.CDLL(str(path))
            for sym in symbols:
                getattr(lib, sym)
        _loaded[name] = (lib, path)
        return lib, path


class GraphLibraries:
    """Compiled libraries of CasADi graphs, each with the same hand-written C driver.

    :meth:`get` writes ``F`` out as C with CasADi's code generator, appends ``#define TS_F
    <name>``, ``TS_F_WORK <name>_work``, the ``defines`` of ``F``, :data:`C_INCLUDES` and the
    ``driver``, builds it through :func:`load_library` and returns ``wrap(lib, path)``; or None,
    when compilation is turned off, no compiler is found, the graph has more than
    ``max_instructions`` instructions or the build fails (:attr:`status` says which; the caller
    then runs its Python path).  The outcome is remembered per graph object and compiler, a failed
    build included (not retried in this process).
    """

    def __init__(
        self,
        prefix: str,
        driver: str,
        symbols: tuple[str, ...],
        fallback: str,
        max_instructions: int,
        defines: Callable[[ca.Function], dict] | None = None,
    ):
        self.prefix = prefix
        self.driver = driver
        self.symbols = symbols
        self.fallback = fallback
        self.max_instructions = max_instructions
        self.defines = defines
        self.status = {"backend": "not tried", "reason": ""}
        self._by_function: dict[int, tuple] = {}  # id(F) -> (F, compiler, result or None, reason)

    def _set(self, out, reason: str):
        self.status.update(backend="compiled" if out is not None else self.fallback, reason=reason)
        return out

    def get(self, F: ca.Function, wrap: Callable[[ctypes.CDLL, Path], Any]):
        if disabled():
            return self._set(None, "TOLSYNTH_NO_COMPILE is set")
        cc = find_compiler()
        hit = self._by_function.get(id(F))
        if hit is not None and hit[0] is F and hit[1] == cc:
            return self._set(hit[2], hit[3])
        if F.n_instructions() > self.max_instructions:
            return self._set(None, f"graph of {F.n_instructions()} instructions > {self.max_instructions}")
        if cc is None:
            return self._set(None, "no C compiler found (cc, gcc, clang; or set TOLSYNTH_CC)")
        cg = ca.CodeGenerator(f"tolsynth_{self.prefix}.c", {"with_header": False})
        cg.add(F)
        name = F.name()
        defines = {"TS_F": name, "TS_F_WORK": f"{name}_work", **(self.defines(F) if self.defines else {})}
        source = cg.dump() + "".join(f"\n#define {k} {v}" for k, v in defines.items()) + "\n" + C_INCLUDES + self.driver
        try:
            lib, path = load_library(source, self.prefix, cc, self.symbols)
            out, reason = wrap(lib, path), ""
        except (OSError, AttributeError, RuntimeError) as err:
            out, reason = None, f"compilation failed: {err}"
        self._by_function[id(F)] = (F, cc, out, reason)
        return self._set(out, reason)
