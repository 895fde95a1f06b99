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

__all__ = ["Pair", "PROTOCOLS", "make_pairs", "crop_nearest"]


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
    """

    source: np.ndarray
    target: np.ndarray
    truth: np.ndarray
    source_clean: np.ndarray
    name: str = ""


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
}


def crop_nearest(points: np.ndarray, fraction: float, rng: np.random.Generator) -> np.ndarray:
    """Keep the ``fraction`` of points nearest to a random one of them (a partial view)."""
    centre = points[rng.integers(len(points))]
    keep = int(round(fraction * len(points)))
    _, idx = cKDTree(points).query(centre, k=keep)
    return np.sort(np.atleast_1d(idx))


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
    if protocol.startswith("resampled") and shapes.shape[1] < 2048:
        raise ValueError("resampled protocols need shapes of (at least) 2048 points")
    rng = np.random.default_rng(seed)
    pairs = []
    for i, shape in enumerate(shapes):
        target = shape[:1024]
        if protocol.startswith("paper"):
            rotation = _euler_rotation(rng, max_angle_deg)
            truth_source = target[rng.permutation(len(target))]
        else:
            rotation = Rotation.random(random_state=int(rng.integers(2**31))).as_matrix()
            truth_source = shape[1024:2048]
        shift = rng.uniform(-0.5, 0.5, 3)
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
        # source = R x + t (x in the target frame); truth maps it back.
        source = observed @ rotation.T + shift
        truth = np.eye(4)
        truth[:3, :3] = rotation.T
        truth[:3, 3] = -rotation.T @ shift
        name = names[i] if names else str(i)
        pairs.append(Pair(source, target, truth, truth_source, name))
    return pairs
