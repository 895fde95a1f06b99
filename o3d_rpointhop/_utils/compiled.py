"""Compiled kernels with numba, compiled on first use.

``import o3d_rpointhop`` does not import numba: :func:`kernel` returns a stand-in that
imports numba, compiles the function (``cache=True``: the machine code is kept on disk,
so later processes load it instead of compiling) and replaces itself on its first call.
Kernels call each other (helpers), across modules, and numba checks a cached kernel
against its own source file only; so the cache lives in a folder named after the
sources of every module that holds kernels (``<cache>/o3d-rpointhop/kernels-<hash>``,
``<cache>`` being ``NUMBA_CACHE_DIR`` if set, else the user's cache folder): editing or
upgrading any of them starts a fresh folder, and a kernel is never loaded with a stale
helper inside. With no writable folder the kernel is compiled for the process alone,
so a read-only install works too.

Threads: the library's kernels are serial and release the GIL (``nogil=True``); their
callers share the work out in pieces among the process's thread pool
(:func:`~o3d_rpointhop._utils.threads.run_blocks`), which a forked child starts anew.
numba's own parallel layer (GNU OpenMP) does not survive a fork; the kernels declared
``parallel=True`` (the SC2-PCR benchmark peer's) run on :func:`threads` threads, which
the caller sets from its ``n_jobs``.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from typing import Any

__all__ = ["kernel", "popcount", "prange", "threads"]

_LOCK = threading.RLock()

#: ``numba.prange`` inside a kernel: a kernel module imports this name, and compiling
#: binds it to numba's parallel range (``range`` until then: numba is not imported).
prange = range


def popcount(word: int) -> int:
    """The number of set bits of an unsigned 64-bit word. Inside a kernel, compiling
    binds this name to the processor's population count (LLVM's ``ctpop``)."""
    return int(word).bit_count()


_POPCOUNT: Any = None


def _popcount_intrinsic(numba) -> Any:
    """``popcount`` as a numba intrinsic: one ``llvm.ctpop.i64`` on a uint64, typed as
    int64 (so that sums of counts stay integers)."""
    global _POPCOUNT
    if _POPCOUNT is None:
        from numba.core import types
        from numba.extending import intrinsic

        @intrinsic
        def _ctpop(typingctx, word):
            if word != types.uint64:
                return None

            def codegen(context, builder, signature, args):
                function = builder.module.declare_intrinsic("llvm.ctpop", [args[0].type])
                return builder.call(function, args)

            return types.int64(types.uint64), codegen

        _POPCOUNT = _ctpop
    return _POPCOUNT


class _Kernel:
    """A function compiled by ``numba.njit(**options)`` at its first call.

    A kernel may call other kernels of this module's kind (helpers, typically
    ``inline="always"``): compiling it first compiles every kernel its code names and
    binds the name to the compiled function, which numba can call.
    """

    def __init__(self, function: Callable, options: dict) -> None:
        self.function = function
        self.options = options
        self.compiled: Callable | None = None
        self.__name__ = function.__name__
        self.__doc__ = function.__doc__

    def __call__(self, *args: Any) -> Any:
        return self.dispatcher()(*args)

    def dispatcher(self) -> Callable:
        """The compiled function (compiled now if it was not yet)."""
        if self.compiled is None:
            with _LOCK:
                self._compile()
        return self.compiled

    def _compile(self) -> None:
        """Compile under ``_LOCK`` (re-entrant: helpers compile inside their caller)."""
        if self.compiled is not None:
            return
        numba = _numba()
        names = self.function.__globals__
        if "prange" in names:
            names["prange"] = numba.prange
        if "popcount" in names:
            names["popcount"] = _popcount_intrinsic(numba)
        for name in self.function.__code__.co_names:
            helper = names.get(name)
            if isinstance(helper, _Kernel):
                helper._compile()
                names[name] = helper.compiled
        try:
            with _cache_folder(numba):
                compiled = numba.njit(cache=True, **self.options)(self.function)
        except RuntimeError as exc:
            # No writable cache folder (a read-only install and no writable home):
            # compile for this process only.
            if "cannot cache" not in str(exc):
                raise
            compiled = numba.njit(**self.options)(self.function)
        self.compiled = compiled


_SOURCES_KEY: list[str] = []


def _sources_key() -> str:
    """A hash of the source of every module of the package that holds kernels."""
    if not _SOURCES_KEY:
        import hashlib
        from pathlib import Path

        digest = hashlib.sha1()
        root = Path(__file__).resolve().parents[1]
        for path in sorted(root.rglob("*.py")):
            text = path.read_bytes()
            if b"@kernel(" in text:
                digest.update(path.relative_to(root).as_posix().encode() + b"\0" + text)
        _SOURCES_KEY.append(digest.hexdigest()[:16])
    return _SOURCES_KEY[0]


@contextmanager
def _cache_folder(numba) -> Iterator[None]:
    """numba's cache folder set to this version of the kernels' own while a kernel is
    declared (numba reads it then); the user's setting is restored after."""
    import os
    from pathlib import Path

    base = os.environ.get("NUMBA_CACHE_DIR") or os.environ.get("XDG_CACHE_HOME")
    base = Path(base) if base else Path.home() / ".cache"
    previous = numba.config.CACHE_DIR
    numba.config.CACHE_DIR = str(base / "o3d-rpointhop" / f"kernels-{_sources_key()}")
    try:
        yield
    finally:
        numba.config.CACHE_DIR = previous


def _numba():
    """numba, with OpenMP preferred as its threading layer (the same runtime as Open3D's;
    numba's TBB layer refuses the TBB versions found on common systems) unless the user
    chose one (``NUMBA_THREADING_LAYER``)."""
    import os

    import numba

    if "NUMBA_THREADING_LAYER" not in os.environ:
        numba.config.THREADING_LAYER_PRIORITY = ["omp", "tbb", "workqueue"]
    return numba


def kernel(**options: Any) -> Callable[[Callable], _Kernel]:
    """Decorator: compile with ``numba.njit(cache=True, **options)`` on first call."""

    def wrap(function: Callable) -> _Kernel:
        return _Kernel(function, options)

    return wrap


@contextmanager
def threads(n_threads: int) -> Iterator[None]:
    """Parallel kernels called inside run on ``n_threads`` threads (at most numba's
    pool size), the calling thread's earlier setting restored on exit."""
    numba = _numba()
    previous = numba.get_num_threads()
    numba.set_num_threads(max(1, min(int(n_threads), numba.config.NUMBA_NUM_THREADS)))
    try:
        yield
    finally:
        numba.set_num_threads(previous)
