"""3DMatch test fragments with the official ``gt.log`` / ``gt.info`` ground truth."""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..poses import log_records
from ._paths import data_home

__all__ = ["FragmentPair", "load_3dmatch_pairs", "read_gt_log", "read_gt_info", "threedmatch_root"]


@dataclass
class FragmentPair:
    """Two overlapping fragments of one scene.

    Attributes
    ----------
    scene : str
    i, j : int
        Fragment ids; ``truth`` maps fragment ``j`` into fragment ``i``'s frame.
    source, target : ndarray of shape (n, 3)
        Fragment ``j`` (to be moved) and fragment ``i``, in metres.
    truth : ndarray of shape (4, 4)
    information : ndarray of shape (6, 6) or None
        The ``gt.info`` matrix of the pair (for the official registration recall).
    benchmark : str
        ``"3DMatch"`` or ``"3DLoMatch"`` (overlap below 30 %).
    overlap : float or None
    """

    scene: str
    i: int
    j: int
    source: np.ndarray
    target: np.ndarray
    truth: np.ndarray
    information: np.ndarray | None
    benchmark: str
    overlap: float | None = None


def read_gt_log(path: str | os.PathLike) -> dict[tuple[int, int], np.ndarray]:
    """``gt.log``: per pair ``(i, j)``, the 4x4 matrix mapping fragment j into i."""
    return log_records(path, 4)


def read_gt_info(path: str | os.PathLike) -> dict[tuple[int, int], np.ndarray]:
    """``gt.info``: per pair ``(i, j)``, the 6x6 information matrix."""
    return log_records(path, 6)


def threedmatch_root(data_dir: str | os.PathLike | None = None) -> Path:
    """The folder holding ``fragments/`` and ``benchmarks/``: ``data_dir`` itself or its
    ``3dmatch/`` subfolder (``None``: ``data_home()``'s).

    Raises
    ------
    FileNotFoundError
        If neither holds a ``fragments/`` folder.
    """
    root = Path(data_dir).expanduser() if data_dir is not None else data_home()
    if not (root / "fragments").is_dir():
        root = root / "3dmatch"
    if not (root / "fragments").is_dir():
        raise FileNotFoundError(f"no 3DMatch fragments/ folder under {root}")
    return root


def load_3dmatch_pairs(
    data_dir: str | os.PathLike | None = None, benchmark: str | None = None
) -> list[FragmentPair]:
    """Every fragment pair whose two fragments are present and that a ``gt.log`` lists.

    Parameters
    ----------
    data_dir : path, default=None
        A folder with ``fragments/<scene>/cloud_bin_<k>.ply`` and
        ``benchmarks/{3DMatch,3DLoMatch}/<scene>/gt.log`` (the shared data's
        ``3dmatch/`` layout), or its parent. ``None`` looks in ``data_home()``.
    benchmark : {"3DMatch", "3DLoMatch"}, default=None
        Restrict to one benchmark; ``None`` takes both.
    """
    from ..io import read_cloud

    root = threedmatch_root(data_dir)
    clouds: dict[tuple[str, int], np.ndarray] = {}
    pairs = []
    for bench in ("3DMatch", "3DLoMatch"):
        if benchmark is not None and bench != benchmark:
            continue
        for scene_dir in sorted((root / "fragments").iterdir()):
            gt_dir = root / "benchmarks" / bench / scene_dir.name
            if not (gt_dir / "gt.log").is_file():
                continue
            log = read_gt_log(gt_dir / "gt.log")
            info = read_gt_info(gt_dir / "gt.info") if (gt_dir / "gt.info").is_file() else {}
            overlaps = {}
            if (gt_dir / "gt_overlap.log").is_file():
                for line in (gt_dir / "gt_overlap.log").read_text().split():
                    a, b, o = line.split(",")
                    overlaps[(int(a), int(b))] = float(o)
            for (i, j), truth in sorted(log.items()):
                paths = [scene_dir / f"cloud_bin_{k}.ply" for k in (i, j)]
                if not all(p.is_file() for p in paths):
                    continue
                for k, path in zip((i, j), paths, strict=True):
                    if (scene_dir.name, k) not in clouds:
                        clouds[(scene_dir.name, k)] = np.asarray(read_cloud(path).points).copy()
                pairs.append(
                    FragmentPair(
                        scene=scene_dir.name,
                        i=i,
                        j=j,
                        source=clouds[(scene_dir.name, j)],
                        target=clouds[(scene_dir.name, i)],
                        truth=truth,
                        information=info.get((i, j)),
                        benchmark=bench,
                        overlap=overlaps.get((i, j)),
                    )
                )
    return pairs
