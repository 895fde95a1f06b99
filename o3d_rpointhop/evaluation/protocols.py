"""Registration test pairs: the paper's ModelNet40 protocols and realistic variants.

Every pair is ``(source, target, truth)`` where ``truth`` is the 4x4 transformation that
maps the source into the target frame, and ``source_clean`` keeps the noise-free source
points in the target frame (for symmetry-aware scoring).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.transform import Rotation

from ..transforms import random_rigid_motion

__all__ = ["Pair", "PROTOCOLS", "make_pairs", "crop_by_plane", "crop_nearest"]


@dataclass
class Pair:
    """One registration problem.

    Attributes
    ----------
    source, target : ndarray of shape (n, 3)
    truth : ndarray of shape (4, 4)
        Maps ``source`` into the target frame.
    source_clean : ndarray of shape (n, 3)
        The source points without noise, in the target frame (``truth`` applied).
    name : str
        Which shape it came from.
    shape : ndarray of shape (m, 3) or None
        The whole clean shape both clouds were cut from, in the target frame: the
        protocols that score the modified Chamfer distance (RPM-Net's) keep it.
    """

    source: np.ndarray
    target: np.ndarray
    truth: np.ndarray
    source_clean: np.ndarray
    name: str = ""
    shape: np.ndarray | None = None


PROTOCOLS = {
    "paper": "the paper's: source = the target's own 1024 points, shuffled, Euler angles in "
    "[0, 45] deg, translation in [-0.5, 0.5]",
    "paper-noise": "as 'paper', Gaussian noise (sigma 0.01, clipped at 0.05) on the source",
    "paper-partial": "as 'paper', source and target each cropped to the 3/4 of points nearest "
    "to an independent random point",
    "resampled": "target = points 0-1023, source = points 1024-2047 (a different sample of the "
    "surface), rotations uniform over SO(3)",
    "resampled-noise": "as 'resampled', Gaussian noise (sigma 0.01, clipped at 0.05) on the source",
    "resampled-partial": "as 'resampled', source and target each cropped to the 70 % of points "
    "nearest to an independent random point",
    "rpmnet-partial": "RPM-Net's partial-visibility protocol (Yew and Lee, CVPR 2020): source "
    "and target each cut from the shape's 2048 points by an independent random plane that "
    "keeps 70 % of them, 717 points drawn from each, Euler angles in [0, 45] deg, translation "
    "in [-0.5, 0.5], Gaussian noise (sigma 0.01, clipped at 0.05) on both",
    "rpmnet-partial-so3": "as 'rpmnet-partial', with rotations uniform over SO(3)",
}
#: RPM-Net's crop: the share of each cloud a random plane keeps, and the points drawn
#: from what it keeps (``ceil(0.7 * 1024)``).
RPMNET_KEEP, RPMNET_POINTS = 0.7, 717


def crop_nearest(points: np.ndarray, fraction: float, rng: np.random.Generator) -> np.ndarray:
    """Keep the ``fraction`` of points nearest to a random one of them (a partial view)."""
    centre = points[rng.integers(len(points))]
    keep = int(round(fraction * len(points)))
    _, idx = cKDTree(points).query(centre, k=keep)
    return np.sort(np.atleast_1d(idx))


def crop_by_plane(points: np.ndarray, fraction: float, rng: np.random.Generator) -> np.ndarray:
    """Indices of the ``fraction`` of points on the far side of a random plane: the
    plane is normal to a direction drawn uniformly on the sphere and shifted along it
    until it keeps that share of the points (RPM-Net's crop)."""
    direction = rng.normal(size=3)
    direction /= np.linalg.norm(direction)
    height = (points - points.mean(axis=0)) @ direction
    return np.flatnonzero(height > np.percentile(height, 100.0 * (1.0 - fraction)))


def _moved(points: np.ndarray, rotation: np.ndarray, shift: np.ndarray):
    """``points`` (in the target frame) moved by ``R x + t`` as a pair's source, and the
    pair's truth, the motion that maps them back."""
    truth = np.eye(4)
    truth[:3, :3] = rotation.T
    truth[:3, 3] = -rotation.T @ shift
    return points @ rotation.T + shift, truth


def _rpmnet_pair(shape: np.ndarray, rng: np.random.Generator, so3: bool):
    """``(source, target, truth, source_clean)`` of RPM-Net's partial protocol."""
    views = []
    for _ in range(2):
        kept = crop_by_plane(shape, RPMNET_KEEP, rng)
        views.append(shape[np.sort(rng.choice(kept, RPMNET_POINTS, replace=False))])
    truth_source, target = views
    if so3:
        motion = random_rigid_motion(rng, 0.5)
        rotation, shift = motion[:3, :3], motion[:3, 3]
    else:
        rotation = _euler_rotation(rng, 45.0)
        shift = rng.uniform(-0.5, 0.5, 3)

    def noisy(points):
        return points + np.clip(rng.normal(scale=0.01, size=points.shape), -0.05, 0.05)

    source, truth = _moved(noisy(truth_source), rotation, shift)
    return source, noisy(target), truth, truth_source


def _euler_rotation(rng: np.random.Generator, max_angle_deg: float) -> np.ndarray:
    angles = rng.uniform(0.0, max_angle_deg, 3)
    return Rotation.from_euler("zyx", angles, degrees=True).as_matrix()


def make_pairs(
    shapes: np.ndarray,
    protocol: str,
    seed: int = 0,
    *,
    max_angle_deg: float = 45.0,
    names: list[str] | None = None,
) -> list[Pair]:
    """Build one pair per shape under ``protocol`` (see :data:`PROTOCOLS`).

    Parameters
    ----------
    shapes : ndarray of shape (n_shapes, 2048, 3)
        Normalised ModelNet40 shapes (the first 1024 points are the target).
    protocol : str
    seed : int
        Same seed, same pairs.
    max_angle_deg : float, default=45
        Largest Euler angle of the paper protocols (the angle sweep varies it).
    """
    if protocol not in PROTOCOLS:
        raise ValueError(f"unknown protocol {protocol!r}; choose from {sorted(PROTOCOLS)}")
    if shapes.ndim != 3 or shapes.shape[2] != 3:
        raise ValueError(f"shapes must be an (n_shapes, n_points, 3) array, got {shapes.shape}")
    if protocol.startswith(("resampled", "rpmnet")) and shapes.shape[1] < 2048:
        raise ValueError("resampled and RPM-Net protocols need shapes of (at least) 2048 points")
    rng = np.random.default_rng(seed)
    pairs = []
    for i, shape in enumerate(shapes):
        name = names[i] if names else str(i)
        if protocol.startswith("rpmnet"):
            whole = shape[:2048]
            source, target, truth, clean = _rpmnet_pair(whole, rng, protocol.endswith("so3"))
            pairs.append(Pair(source, target, truth, clean, name, whole))
            continue
        target = shape[:1024]
        if protocol.startswith("paper"):
            rotation = _euler_rotation(rng, max_angle_deg)
            truth_source = target[rng.permutation(len(target))]
            shift = rng.uniform(-0.5, 0.5, 3)
        else:
            motion = random_rigid_motion(rng, 0.5)
            rotation, shift = motion[:3, :3], motion[:3, 3]
            truth_source = shape[1024:2048]
        observed = truth_source
        if protocol.endswith("noise"):
            noise = np.clip(rng.normal(scale=0.01, size=observed.shape), -0.05, 0.05)
            observed = observed + noise
        if protocol.endswith("partial"):
            fraction = 0.75 if protocol.startswith("paper") else 0.70
            keep_src = crop_nearest(truth_source, fraction, rng)
            keep_tgt = crop_nearest(target, fraction, rng)
            observed, truth_source = observed[keep_src], truth_source[keep_src]
            target = target[keep_tgt]
        source, truth = _moved(observed, rotation, shift)
        pairs.append(Pair(source, target, truth, truth_source, name))
    return pairs
