"""Off-screen pictures of registrations (matplotlib's Figure API: no display, no backend
switch; matplotlib is the optional ``[plot]`` extra)."""

from __future__ import annotations

import os
from typing import Any

import numpy as np

from ._utils.validation import as_points
from .transforms import apply_transform

__all__ = ["save_registration_png", "require_matplotlib"]


def require_matplotlib():
    """matplotlib's ``Figure`` class (the object API: no pyplot, so the caller's backend
    and open figures are left alone), or an ImportError saying how to install it."""
    try:
        from matplotlib.figure import Figure
    except ImportError as exc:
        raise ImportError(
            "pictures need matplotlib: pip install '.[plot]' in the project folder"
        ) from exc
    return Figure


def _thin(points: np.ndarray, limit: int, seed: int = 0) -> np.ndarray:
    if len(points) <= limit:
        return points
    return points[np.random.default_rng(seed).choice(len(points), limit, replace=False)]


def save_registration_png(
    source: Any,
    target: Any,
    transformation: np.ndarray,
    path: str | os.PathLike,
    *,
    title: str = "",
    max_points: int = 4000,
) -> None:
    """Draw the source (red) and target (blue) before and after ``transformation``.

    Parameters
    ----------
    source, target : array-like (n, 3) or Open3D point cloud
    transformation : ndarray of shape (4, 4)
        Source-to-target transformation (e.g. ``register(...).transformation``).
    path : str or path-like
        PNG file to write.
    title : str, default=""
    max_points : int, default=4000
        Points drawn per cloud (a random subset of larger clouds).
    """
    figure_class = require_matplotlib()
    src = _thin(as_points(source, "source"), max_points)
    tgt = _thin(as_points(target, "target"), max_points, seed=1)
    aligned = apply_transform(src, transformation)
    # Show everything in the target's principal axes, looking along the thinnest one, so
    # any cloud is seen broadside whatever its coordinate convention.
    centre = tgt.mean(axis=0)
    _, _, axes = np.linalg.svd(tgt - centre, full_matrices=False)
    view = [(p - centre) @ axes.T for p in (src, aligned, tgt)]
    fig = figure_class(figsize=(11, 5.2))
    for k, (label, moved) in enumerate((("before", view[0]), ("after", view[1]))):
        ax = fig.add_subplot(1, 2, k + 1, projection="3d")
        both = np.concatenate([moved, view[2]])
        mid = 0.5 * (both.max(axis=0) + both.min(axis=0))
        radius = 0.5 * (both.max(axis=0) - both.min(axis=0)).max()
        ax.scatter(*view[2].T, s=1.0, c="tab:blue", alpha=0.5, label="target", depthshade=False)
        ax.scatter(*moved.T, s=1.0, c="tab:red", alpha=0.5, label="source", depthshade=False)
        for setter, c in zip((ax.set_xlim, ax.set_ylim, ax.set_zlim), mid, strict=True):
            setter(c - radius, c + radius)
        ax.set_box_aspect((1, 1, 1))
        ax.view_init(elev=70, azim=-90)
        ax.set_axis_off()
        ax.set_title(label)
        if k == 0:
            ax.legend(loc="upper left", markerscale=6, fontsize=8)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
