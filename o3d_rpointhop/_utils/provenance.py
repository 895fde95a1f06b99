"""What made an output: the library's version, the checkout's commit and the versions of
the libraries it ran on, and values made JSON-ready to be recorded beside them."""

from __future__ import annotations

import platform
import subprocess
from pathlib import Path
from typing import Any

import numpy as np

__all__ = ["commit", "json_safe", "library_facts", "library_versions"]


def json_safe(value: Any) -> Any:
    """``value`` with tuples as lists, numpy scalars as Python ones and any other object
    as its ``repr`` (a record must not fail on a parameter it cannot store)."""
    if isinstance(value, dict):
        return {str(k): json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    if isinstance(value, np.generic):
        return value.item()
    if value is None or isinstance(value, (bool, int, float, str)):
        return value
    return repr(value)


def commit() -> dict:
    """The checkout's commit and whether the package's files differ from it (``None``
    for both outside a git checkout, e.g. an installed wheel)."""
    root = Path(__file__).resolve().parents[2]
    if not (root / ".git").exists():
        return {"id": None, "modified": None}
    try:
        head = subprocess.run(
            ["git", "-C", str(root), "rev-parse", "HEAD"],
            capture_output=True,
            text=True,
            check=True,
            timeout=30,
        ).stdout.strip()
        changed = subprocess.run(
            ["git", "-C", str(root), "status", "--porcelain", "--", "o3d_rpointhop"],
            capture_output=True,
            text=True,
            check=True,
            timeout=30,
        ).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return {"id": None, "modified": None}
    return {"id": head, "modified": bool(changed)}


def library_versions() -> dict:
    """The library's, Open3D's, numpy's and Python's versions."""
    import open3d

    from .._version import __version__

    return {
        "o3d_rpointhop": __version__,
        "open3d": open3d.__version__,
        "numpy": np.__version__,
        "python": platform.python_version(),
    }


def library_facts() -> dict:
    """The library's version and commit, and Open3D's, numpy's and Python's versions."""
    versions = library_versions()
    return {
        "o3d_rpointhop": versions["o3d_rpointhop"],
        "commit": commit(),
        **{k: versions[k] for k in ("open3d", "numpy", "python")},
    }
