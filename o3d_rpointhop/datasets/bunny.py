"""Stanford Bunny range scans with their ``bun.conf`` ground-truth poses."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from ._paths import data_home

__all__ = [
    "BunnyScan",
    "dragon_files",
    "load_bunny",
    "load_dragon",
    "read_bun_conf",
    "BUNNY_SCANS",
]

BUNNY_SCANS = (
    "bun000",
    "bun045",
    "bun090",
    "bun180",
    "bun270",
    "bun315",
    "chin",
    "ear_back",
    "top2",
    "top3",
)


@dataclass
class BunnyScan:
    """One range scan.

    Attributes
    ----------
    name : str
    points : ndarray of shape (n, 3)
        In the scanner's frame, metres.
    pose : ndarray of shape (4, 4)
        Maps the scan into the common frame (bun000's): ``p_global = pose @ p_scan``.
    """

    name: str
    points: np.ndarray
    pose: np.ndarray

    def relative_pose(self, target: BunnyScan) -> np.ndarray:
        """The transformation taking this scan into ``target``'s frame."""
        return np.linalg.inv(target.pose) @ self.pose


def read_bun_conf(path: str | os.PathLike) -> dict[str, np.ndarray]:
    """Poses from a Stanford ``.conf`` file.

    Each ``bmesh <file> tx ty tz qx qy qz qw`` line gives a scan's pose; the quaternion is
    scalar-last, and the pose maps scan coordinates into the common frame as
    ``p = R(q)^T p_scan + t`` (verified against the reconstruction; see the data README).

    Returns
    -------
    dict
        Scan name (file name without extension) to 4x4 pose.
    """
    poses = {}
    for line in Path(path).read_text().splitlines():
        parts = line.split()
        if len(parts) != 9 or parts[0] != "bmesh":
            continue
        name = Path(parts[1]).stem
        t = np.array([float(v) for v in parts[2:5]])
        q = np.array([float(v) for v in parts[5:9]])
        pose = np.eye(4)
        pose[:3, :3] = Rotation.from_quat(q).as_matrix().T
        pose[:3, 3] = t
        poses[name] = pose
    if not poses:
        raise ValueError(f"{path}: no 'bmesh' pose lines found")
    return poses


def load_bunny(
    names: tuple[str, ...] | list[str] = ("bun000", "bun045", "bun315"),
    data_dir: str | os.PathLike | None = None,
) -> dict[str, BunnyScan]:
    """Load Stanford Bunny range scans and their poses.

    Parameters
    ----------
    names : sequence of str
        Scans to load (see :data:`BUNNY_SCANS`).
    data_dir : path, default=None
        A folder holding ``bun.conf`` and the ``.ply`` scans, or one holding
        ``stanford/bunny/data/`` (the shared data layout). ``None`` looks in
        :func:`~o3d_rpointhop.datasets.data_home`.
    """
    from ..io import read_cloud

    root = Path(data_dir).expanduser() if data_dir is not None else data_home()
    folder = root if (root / "bun.conf").is_file() else root / "stanford" / "bunny" / "data"
    conf = folder / "bun.conf"
    if not conf.is_file():
        raise FileNotFoundError(f"no bun.conf in {root} or {folder}")
    poses = read_bun_conf(conf)
    out = {}
    for name in names:
        if name not in poses:
            raise ValueError(f"unknown scan {name!r}; bun.conf has {sorted(poses)}")
        cloud = read_cloud(folder / f"{name}.ply")
        out[name] = BunnyScan(name, np.asarray(cloud.points).copy(), poses[name])
    return out


def dragon_files(
    data_dir: str | os.PathLike | None = None,
) -> tuple[Path, dict[str, tuple[Path, np.ndarray]]]:
    """The folder of the Stanford dragon "stand" scans, and the scans present in it, in
    turntable order: each name's file and ``dragonStandRight.conf`` pose (the same
    convention as ``bun.conf``). Nothing is read but the ``.conf``.

    Parameters
    ----------
    data_dir : path, default=None
        A folder holding ``dragonStandRight.conf`` and the scans, or one holding
        ``stanford/dragon_stand/`` (the shared data layout).

    Raises
    ------
    FileNotFoundError
        Without the ``.conf``.
    """
    root = Path(data_dir).expanduser() if data_dir is not None else data_home()
    folder = (
        root if (root / "dragonStandRight.conf").is_file() else root / "stanford" / "dragon_stand"
    )
    conf = folder / "dragonStandRight.conf"
    if not conf.is_file():
        raise FileNotFoundError(f"no dragonStandRight.conf in {folder}")
    poses = read_bun_conf(conf)
    found = {}
    for name in sorted(poses, key=lambda n: int(n.rsplit("_", 1)[1]) if "_" in n else -1):
        path = folder / f"{name}.ply"
        if path.is_file():
            found[name] = (path, poses[name])
    return folder, found


def load_dragon(data_dir: str | os.PathLike | None = None) -> dict[str, BunnyScan]:
    """The Stanford dragon "stand" range scans present in the data folder, with their
    ``dragonStandRight.conf`` poses (:func:`dragon_files`).

    Parameters
    ----------
    data_dir : path, default=None
        A folder holding ``dragonStandRight.conf`` and the scans, or one holding
        ``stanford/dragon_stand/`` (the shared data layout).
    """
    from ..io import read_cloud

    folder, found = dragon_files(data_dir)
    if len(found) < 2:
        raise FileNotFoundError(f"fewer than two dragon scans in {folder}")
    return {
        name: BunnyScan(name, np.asarray(read_cloud(path).points).copy(), pose)
        for name, (path, pose) in found.items()
    }
