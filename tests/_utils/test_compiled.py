"""Compiled kernels: compiled lazily, numba never imported by the package import, and a
working fallback when no cache folder is writable."""

from __future__ import annotations

import subprocess
import sys

import numpy as np

from o3d_rpointhop._utils import compiled


def test_import_does_not_import_numba():
    code = "import sys, o3d_rpointhop; print('numba' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def _sum_of_squares(values):  # pragma: no cover - compiled
    total = 0.0
    for i in range(values.shape[0]):
        total += values[i] * values[i]
    return total


def test_a_kernel_compiles_without_a_writable_cache(monkeypatch):
    import numba

    real = numba.njit
    asked = []

    def no_cache_folder(*args, **options):
        asked.append(options.get("cache", False))
        if options.get("cache"):
            raise RuntimeError("cannot cache function '_sum_of_squares': no locator available")
        return real(*args, **options)

    monkeypatch.setattr(numba, "njit", no_cache_folder)
    kernel = compiled.kernel()(_sum_of_squares)
    assert kernel(np.arange(4.0)) == 14.0
    assert asked[:2] == [True, False]  # tried the cache first, then compiled for the process


def test_other_compile_errors_are_not_swallowed(monkeypatch):
    import numba

    def broken(*args, **options):
        raise RuntimeError("something else")

    monkeypatch.setattr(numba, "njit", broken)
    kernel = compiled.kernel()(_sum_of_squares)
    try:
        kernel(np.arange(3.0))
    except RuntimeError as exc:
        assert "something else" in str(exc)
    else:  # pragma: no cover - the test fails here
        raise AssertionError("the compile error was swallowed")


def test_threads_restores_the_callers_setting():
    import numba

    before = numba.get_num_threads()
    with compiled.threads(1):
        assert numba.get_num_threads() == 1
    assert numba.get_num_threads() == before


def _popcounts(words):  # pragma: no cover - compiled
    out = np.empty(words.shape[0], dtype=np.int64)
    for i in range(words.shape[0]):
        out[i] = popcount(words[i])
    return out


popcount = compiled.popcount  # bound to the processor's instruction when compiled


def test_popcount_counts_the_set_bits_of_a_word():
    rng = np.random.default_rng(0)
    words = np.concatenate(
        [
            np.array([0, 1, 2**63, 2**64 - 1], dtype=np.uint64),
            rng.integers(0, 2**63, 200, dtype=np.uint64) * np.uint64(2) + np.uint64(1),
        ]
    )
    expected = np.array([int(w).bit_count() for w in words])
    assert [compiled.popcount(int(w)) for w in words[:4]] == [0, 1, 1, 64]
    kernel = compiled.kernel()(_popcounts)
    np.testing.assert_array_equal(kernel(words), expected)


def _outer(values):  # pragma: no cover - compiled
    return _inner(values) + 1.0


def _inner_function(values):  # pragma: no cover - compiled
    return values.sum()


_inner = compiled.kernel(inline="always")(_inner_function)


def test_a_kernel_calls_other_kernels():
    outer = compiled.kernel()(_outer)
    assert outer(np.arange(4.0)) == 7.0
    assert _inner(np.ones(3)) == 3.0  # still callable from Python once bound


def test_the_cache_folder_is_named_after_every_kernel_module_s_source(tmp_path, monkeypatch):
    """A kernel calls helpers from other files, and numba checks a cached kernel
    against its own file only: so the folder changes with any kernel module."""
    import numba

    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    before = numba.config.CACHE_DIR
    with compiled._cache_folder(numba):
        folder = numba.config.CACHE_DIR
    assert numba.config.CACHE_DIR == before  # the user's setting is back
    assert folder == str(tmp_path / "o3d-rpointhop" / f"kernels-{compiled._sources_key()}")
    monkeypatch.setattr(compiled, "_SOURCES_KEY", [])
    key = compiled._sources_key()
    assert len(key) == 16 and key == compiled._sources_key()
