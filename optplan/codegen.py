"""Compile a ``casadi.Function`` to C and call it through ctypes with preallocated buffers.

CasADi's Python call path costs ~20 µs per call whatever the function; a compiled function called
through ctypes costs ~1-3 µs plus the work itself, which is what hot loops (IK, collision checks,
planners) need. The shared library is cached under ``$OPTPLAN_CACHE`` (default
``~/.cache/optplan``), keyed by a hash of the generated C code; a C compiler (``cc``) is needed the
first time. Each library is checked against the size and SHA-256 recorded when it was written
before it is loaded; a damaged one is quarantined and rebuilt (:mod:`optplan.cache`). :func:`compile_function` falls back to the plain CasADi function, with a logged
warning, when no compiler is available.
"""
from __future__ import annotations

import contextlib
import ctypes
import hashlib
import logging
import os
import shutil
import signal
import subprocess
import tempfile
from pathlib import Path

import casadi as ca
import numpy as np

from .cache import quarantine, usable

__all__ = ["CompiledFunction", "FastFunction", "build_library", "c_compiler", "compile_function", "cache_dir"]
log = logging.getLogger(__name__)


def cache_dir() -> Path:
    """The kernel cache folder (:func:`optplan.cache.cache_dir`: ``$OPTPLAN_CACHE``, default
    ``~/.cache/optplan``; :class:`optplan.errors.CacheError` when it is not a usable folder)."""
    from .cache import cache_dir as _cache_dir

    return _cache_dir()


class CompiledFunction:
    """A compiled CasADi function: ``f(*inputs) -> tuple of dense numpy arrays``.

    Inputs are dense vectors/matrices (column-major as CasADi); outputs are returned as fresh
    dense arrays (vectors as 1-D, matrices as 2-D). Not thread-safe (shared work buffers).
    """

    def __init__(self, f: ca.Function, lib_path: Path):
        self.f = f  # the interpreted function (same values)
        self.name = f.name()
        self.lib = ctypes.CDLL(str(lib_path))
        self._fn = getattr(self.lib, self.name)
        sz_arg, sz_res, sz_iw, sz_w = (ctypes.c_longlong() for _ in range(4))
        getattr(self.lib, f"{self.name}_work")(ctypes.byref(sz_arg), ctypes.byref(sz_res),
                                                ctypes.byref(sz_iw), ctypes.byref(sz_w))
        self._iw = np.zeros(max(sz_iw.value, 1), dtype=np.int64)
        self._w = np.zeros(max(sz_w.value, 1), dtype=np.float64)
        self.n_in, self.n_out = f.n_in(), f.n_out()
        self._in_shapes = [f.size_in(i) for i in range(self.n_in)]
        self._in_bufs = [np.zeros(f.nnz_in(i)) for i in range(self.n_in)]
        for i in range(self.n_in):
            if not f.sparsity_in(i).is_dense():
                raise ValueError(f"{self.name}: input {i} must be dense")
        self._out_bufs = [np.zeros(max(f.nnz_out(i), 1)) for i in range(self.n_out)]
        self._out_map = []
        for i in range(self.n_out):
            sp = f.sparsity_out(i)
            rows, cols = sp.get_triplet()
            self._out_map.append((sp.shape, np.array(rows, dtype=np.intp), np.array(cols, dtype=np.intp)))
        self._arg = (ctypes.c_void_p * max(sz_arg.value, self.n_in))()
        self._res = (ctypes.c_void_p * max(sz_res.value, self.n_out))()
        for i, b in enumerate(self._in_bufs):
            self._arg[i] = b.ctypes.data
        for i, b in enumerate(self._out_bufs):
            self._res[i] = b.ctypes.data
        self._iw_p = self._iw.ctypes.data_as(ctypes.c_void_p)
        self._w_p = self._w.ctypes.data_as(ctypes.c_void_p)
        self._fn.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p, ctypes.c_int]
        self._fn.restype = ctypes.c_int

    def __call__(self, *inputs):
        if len(inputs) != self.n_in:
            raise TypeError(f"{self.name}: expected {self.n_in} inputs, got {len(inputs)}")
        for buf, x, shp in zip(self._in_bufs, inputs, self._in_shapes):
            a = np.asarray(x, dtype=np.float64)
            if a.size != buf.size:
                raise ValueError(f"{self.name}: input of shape {a.shape}, expected {shp}")
            buf[:] = a.reshape(-1, order="F")
        if self._fn(self._arg, self._res, self._iw_p, self._w_p, 0) != 0:
            raise RuntimeError(f"{self.name}: evaluation failed")
        outs = []
        for buf, (shape, rows, cols) in zip(self._out_bufs, self._out_map):
            out = np.zeros(shape)
            out[rows, cols] = buf[:rows.size]
            outs.append(out[:, 0] if shape[1] == 1 else out)
        return tuple(outs)


class FastFunction:
    """A CasADi function with dense inputs and ONE dense vector output for hot loops: compiled
    (:func:`compile_function`) and called with the inputs copied into preallocated buffers and no
    shape checks (inputs already flat, column-major); falls back to the interpreted function."""

    def __init__(self, f: ca.Function, opt: str = "-O2"):
        if not f.sparsity_out(0).is_dense():
            raise ValueError(f"{f.name()}: the output must be dense")
        self.f = f
        self.n_out = int(f.nnz_out(0))
        cf = compile_function(f, opt)
        self.compiled = isinstance(cf, CompiledFunction)
        self._cf = cf if self.compiled else None

    def __call__(self, *inputs) -> np.ndarray:
        cf = self._cf
        if cf is None:
            return np.asarray(self.f(*inputs), dtype=float).ravel(order="F")
        for b, x in zip(cf._in_bufs, inputs):
            b[:] = x
        if cf._fn(cf._arg, cf._res, cf._iw_p, cf._w_p, 0) != 0:
            raise RuntimeError(f"{self.f.name()}: evaluation failed")
        return cf._out_bufs[0][:self.n_out].copy()


def c_compiler() -> str | None:
    """The C compiler (``$CC``, else ``cc``, else ``gcc``), or None."""
    return shutil.which(os.environ.get("CC", "cc")) or shutil.which("gcc")


def build_library(c_file: Path, lib: Path, opt: str) -> str | None:
    """Compile the C file into the shared library ``lib``, written atomically (a concurrent
    process never loads half a library). None on success, else why not (no compiler, or the
    compiler's last error lines)."""
    cc = c_compiler()
    if cc is None:
        return "no C compiler"
    tmp_lib = lib.with_name(f"{lib.name}.{os.getpid()}.tmp")
    # its own process group: an interruption stops the compiler's own children (cc1, as, ld) with it
    proc = subprocess.Popen([cc, opt, "-fPIC", "-shared", str(c_file), "-o", str(tmp_lib), "-lm"],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        _, stderr = proc.communicate()
    except BaseException:
        with contextlib.suppress(OSError):
            os.killpg(proc.pid, signal.SIGKILL)
        proc.wait()
        with contextlib.suppress(OSError):
            tmp_lib.unlink()
        raise
    if proc.returncode != 0:
        with contextlib.suppress(OSError):
            tmp_lib.unlink()
        return stderr[-500:]
    from .cache import record

    record(tmp_lib, sidecar_for=lib)   # size + SHA-256, checked before every later load
    os.replace(tmp_lib, lib)
    return None


def compile_function(f: ca.Function, opt: str = "-O2"):
    """Compile ``f`` (cached) and return a :class:`CompiledFunction`, or ``f`` itself when no C
    compiler is available (a warning is logged once)."""
    if c_compiler() is None:
        log.warning("no C compiler found: %s stays an interpreted casadi.Function", f.name())
        return f
    with tempfile.TemporaryDirectory() as tmp:
        cname = f"{f.name()}.c"
        cg = ca.CodeGenerator(cname, {"with_header": False, "casadi_int": "long long int"})
        cg.add(f)
        cg.generate(tmp + os.sep)
        code = Path(tmp, cname).read_bytes()
        digest = hashlib.sha1(code + opt.encode()).hexdigest()[:16]
        lib = cache_dir() / f"{f.name()}_{digest}.so"
        for _attempt in range(2):   # a damaged entry is quarantined and built once more
            if not usable(lib):
                err = build_library(Path(tmp, cname), lib, opt)
                if err is not None:
                    log.warning("compiling %s failed (%s); using the interpreted function", f.name(), err)
                    return f
            try:
                return CompiledFunction(f, lib)
            except (OSError, AttributeError) as exc:   # dlopen refused it, or a symbol is missing
                quarantine(lib, f"does not load: {exc}")
    log.warning("%s: the compiled library does not load; using the interpreted function", f.name())
    return f
