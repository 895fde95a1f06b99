"""Synthetic shapes: generic, asymmetric closed surfaces for tests, demos and examples.

The project ships no third-party data; these surfaces stand in for it wherever a real
cloud is not at hand.
"""

from __future__ import annotations

import numpy as np

from .._utils.validation import renamed_seed

__all__ = ["make_blob", "make_object"]


def make_blob(
    n_points: int = 1024,
    *,
    shape_seed: int = 0,
    sample_seed: int | None = None,
    n_bumps: int = 12,
    bump_height: float = 0.35,
) -> np.ndarray:
    """Sample points from a smooth, bumpy, asymmetric closed surface in the unit sphere.

    The surface is a sphere whose radius along direction ``d`` is
    ``1 + sum_j h_j exp((d . c_j - 1) / w_j)`` for random bump centres ``c_j``, widths
    ``w_j`` and signed heights ``h_j``; it is then scaled so its farthest point lies at
    about distance 1 from the origin (the scale depends on the shape only, so different
    samples of one shape share one frame). Such a surface has no symmetry, so every region looks
    different, like a real object's.

    Parameters
    ----------
    n_points : int, default=1024
    shape_seed : int, default=0
        Picks the surface. The same seed gives the same surface.
    sample_seed : int, default=None
        Picks the points on it; ``None`` uses ``shape_seed``. Two different sample seeds
        give two different point samples of the same surface, as two scans would.
    n_bumps : int, default=12
    bump_height : float, default=0.35
        Largest bump height relative to the unit radius.

    Returns
    -------
    points : ndarray of shape (n_points, 3)
    """
    if n_points < 1:
        raise ValueError(f"n_points must be positive, got {n_points}")
    shape_rng = np.random.default_rng(shape_seed)
    centres = shape_rng.normal(size=(n_bumps, 3))
    centres /= np.linalg.norm(centres, axis=1, keepdims=True)
    widths = shape_rng.uniform(0.05, 0.4, n_bumps)
    heights = shape_rng.uniform(-1.0, 1.0, n_bumps) * bump_height

    sample_rng = np.random.default_rng(shape_seed if sample_seed is None else sample_seed)
    directions = sample_rng.normal(size=(n_points, 3))
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    points = directions * _radius(directions, centres, widths, heights)[:, None]
    # Normalise with a per-shape constant (not the sample's own extent), so two samples of
    # one shape stay in one frame.
    probe = np.random.default_rng(shape_seed + 10_007).normal(size=(4096, 3))
    probe /= np.linalg.norm(probe, axis=1, keepdims=True)
    extent = _radius(probe, centres, widths, heights).max()
    return points / extent


def _radius(directions, centres, widths, heights):
    cos = directions @ centres.T
    return 1.0 + (heights * np.exp((cos - 1.0) / widths)).sum(axis=1)


def _box_surface(rng, n, half):
    """Uniform samples on the surface of an axis-aligned box with half-sizes ``half``."""
    areas = 4 * np.array([half[1] * half[2], half[0] * half[2], half[0] * half[1]])
    axis = rng.choice(3, size=n, p=areas / areas.sum())
    pts = rng.uniform(-1, 1, size=(n, 3)) * half
    pts[np.arange(n), axis] = np.where(rng.random(n) < 0.5, -1.0, 1.0) * half[axis]
    return pts


def _cylinder_surface(rng, n, radius, half_height):
    """Uniform samples on a closed cylinder along z."""
    side = 2 * np.pi * radius * 2 * half_height
    caps = 2 * np.pi * radius**2
    on_side = rng.random(n) < side / (side + caps)
    theta = rng.uniform(0, 2 * np.pi, n)
    r = np.where(on_side, radius, radius * np.sqrt(rng.random(n)))
    z = np.where(
        on_side,
        rng.uniform(-half_height, half_height, n),
        np.where(rng.random(n) < 0.5, -half_height, half_height),
    )
    return np.c_[r * np.cos(theta), r * np.sin(theta), z]


def _ellipsoid_surface(rng, n, radii):
    """Samples on an ellipsoid (directions uniform on the sphere, then stretched)."""
    d = rng.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return d * radii


def make_object(
    n_points: int = 1024,
    *,
    shape_seed: int = 0,
    sample_seed: int | None = None,
    n_parts: int = 5,
) -> np.ndarray:
    """Sample points from a random CAD-like object: boxes, cylinders and ellipsoids.

    The parts are randomly sized, placed and turned, so the object has flat faces,
    sharp edges, corners and curved patches, like a ModelNet40 shape. Points are spread
    over the parts in proportion to their (approximate) areas. The object is centred and
    scaled into (about) the unit sphere by constants of the shape, not of the sample, so
    different samples of one object share one frame.

    Parameters
    ----------
    n_points : int, default=1024
    shape_seed : int, default=0
        Picks the object.
    sample_seed : int, default=None
        Picks the points on it; ``None`` uses ``shape_seed``. Two sample seeds give two
        different scans of the same object.
    n_parts : int, default=5

    Returns
    -------
    points : ndarray of shape (n_points, 3)
    """
    if n_points < 1:
        raise ValueError(f"n_points must be positive, got {n_points}")
    shape_rng = np.random.default_rng(shape_seed)
    parts = []
    for _ in range(n_parts):
        kind = shape_rng.choice(3)
        if kind == 0:
            dims = shape_rng.uniform(0.08, 0.6, 3)
            area = 8 * (dims[0] * dims[1] + dims[1] * dims[2] + dims[0] * dims[2])
        elif kind == 1:
            dims = np.array([shape_rng.uniform(0.05, 0.3), shape_rng.uniform(0.1, 0.6), 0.0])
            area = 2 * np.pi * dims[0] * (2 * dims[1] + dims[0])
        else:
            dims = shape_rng.uniform(0.1, 0.45, 3)
            p = 1.6
            a, b, c = dims
            area = 4 * np.pi * (((a * b) ** p + (a * c) ** p + (b * c) ** p) / 3) ** (1 / p)
        rotation = np.linalg.qr(shape_rng.normal(size=(3, 3)))[0]
        offset = shape_rng.uniform(-0.5, 0.5, 3)
        parts.append((kind, dims, rotation, offset, area))
    areas = np.array([p[4] for p in parts])

    def sample(rng: np.random.Generator, n: int) -> np.ndarray:
        counts = rng.multinomial(n, areas / areas.sum())
        points = []
        for (kind, dims, rotation, offset, _), count in zip(parts, counts, strict=True):
            if kind == 0:
                local = _box_surface(rng, count, dims)
            elif kind == 1:
                local = _cylinder_surface(rng, count, dims[0], dims[1])
            else:
                local = _ellipsoid_surface(rng, count, dims)
            points.append(local @ rotation.T + offset)
        return np.concatenate(points)[rng.permutation(n)]  # rows not grouped by part

    # Centre and radius from a dense probe of the surface: the same for every sample.
    probe = sample(np.random.default_rng([shape_seed, 7]), 8192)
    centre = probe.mean(axis=0)
    radius = np.linalg.norm(probe - centre, axis=1).max()
    sample_rng = np.random.default_rng(shape_seed if sample_seed is None else sample_seed)
    return (sample(sample_rng, n_points) - centre) / radius


def make_room(
    n_points: int = 3000, *, random_state: int = 0, seed: int | None = None
) -> np.ndarray:
    """Sample points from the corner of a room, in metres: a floor, two walls, a table
    top and a box, every piece exactly planar (the worst case for normals and
    eigenvalue features, and what indoor scans are mostly made of).

    Parameters
    ----------
    n_points : int, default=3000
    random_state : int, default=0
        Picks the points; the room is always the same, so two seeds give two samplings
        of one room.
    seed : int, default=None
        The former name of ``random_state``; given, it wins with a ``FutureWarning``.

    Returns
    -------
    points : ndarray of shape (n_points, 3)
    """
    if n_points < 5:
        raise ValueError(f"n_points must be at least 5, got {n_points}")
    rng = np.random.default_rng(renamed_seed(random_state, seed, "make_room"))
    m = n_points // 5
    floor_n = n_points - 4 * m
    floor = np.c_[rng.uniform(0, 4, floor_n), rng.uniform(0, 3, floor_n), np.zeros(floor_n)]
    wall_a = np.c_[np.zeros(m), rng.uniform(0, 3, m), rng.uniform(0, 2.5, m)]
    wall_b = np.c_[rng.uniform(0, 4, m), np.zeros(m), rng.uniform(0, 2.5, m)]
    table = np.c_[rng.uniform(1, 2.2, m), rng.uniform(1, 1.8, m), np.full(m, 0.75)]
    box = np.c_[rng.uniform(3, 3.5, m), np.full(m, 0.6), rng.uniform(0, 0.5, m)]
    return np.vstack([floor, wall_a, wall_b, table, box])
