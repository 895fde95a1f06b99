"""Pose files: KITTI, TUM and 3DMatch ``.log`` trajectories, Open3D pose graphs, and one
4x4 matrix per text file.

Every pose is a 4x4 rigid transformation that maps a scan (or a source) into a common
frame (or the target), as everywhere in this library and in Open3D.

=================  ==============================================================
format             one record
=================  ==============================================================
``"kitti"``        12 numbers: the top three rows of the matrix, row by row; line k
                   is scan k, and a scan without a pose is a line of 12 ``nan``
``"tum"``          ``timestamp tx ty tz qx qy qz qw`` (a unit quaternion, scalar last)
``"3dmatch"``      a line ``i j n`` and the matrix's four rows (Choi et al.'s ``.log``)
``"matrix"``       one 4x4 matrix per file (``np.loadtxt``), what ``--init`` reads
=================  ==============================================================

The trajectory functions take ``format="auto"`` by default: ``"3dmatch"`` for a path
ending in ``.log`` (the suffix of Choi et al.'s files and of Open3D's trajectories),
else ``"kitti"``. TUM files end in ``.txt`` as KITTI's do, so TUM is always named.
"""

from __future__ import annotations

import json
import os
from collections.abc import Sequence
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

__all__ = [
    "POSE_FORMATS",
    "SUFFIX_FORMATS",
    "log_records",
    "pose_format",
    "read_matrix",
    "read_poses",
    "read_pose_graph",
    "read_trajectory",
    "write_matrix",
    "write_pose_graph",
    "write_poses",
    "write_trajectory",
]

#: What :func:`read_poses` and :func:`write_poses` read and write.
POSE_FORMATS = ("kitti", "tum", "3dmatch")
#: The format ``"auto"`` gives a path by its suffix (any other suffix: KITTI).
SUFFIX_FORMATS = {".log": "3dmatch"}
# Largest deviation from a rigid motion a pose file may hold (rounding of printed files).
_RIGID_TOLERANCE = 1e-4


def pose_format(path: str | os.PathLike, format: str = "auto") -> str:
    """``format``, or for ``"auto"`` the one :data:`SUFFIX_FORMATS` gives ``path``'s
    suffix (``.log``: ``"3dmatch"``; else ``"kitti"``).

    Raises
    ------
    ValueError
        For a format that is neither ``"auto"`` nor one of :data:`POSE_FORMATS`.
    """
    if format == "auto":
        return SUFFIX_FORMATS.get(Path(path).suffix.lower(), "kitti")
    if format not in POSE_FORMATS:
        raise ValueError(f"format must be one of {('auto', *POSE_FORMATS)}, got {format!r}")
    return format


def _check_pose(matrix: np.ndarray, where: str) -> np.ndarray:
    """``matrix`` if it is a finite rigid 4x4 transformation; ValueError naming ``where``."""
    if matrix.shape != (4, 4) or not np.isfinite(matrix).all():
        raise ValueError(f"{where}: not a finite 4x4 matrix")
    rot = matrix[:3, :3]
    if (
        np.abs(matrix[3] - [0, 0, 0, 1]).max() > _RIGID_TOLERANCE
        or np.abs(rot @ rot.T - np.eye(3)).max() > _RIGID_TOLERANCE
        or np.linalg.det(rot) < 0
    ):
        raise ValueError(f"{where}: not a rigid transformation (rotation and translation)")
    return matrix


def _as_poses(poses: Sequence, allow_missing: bool = False) -> list[np.ndarray | None]:
    out: list[np.ndarray | None] = []
    for k, pose in enumerate(poses):
        if pose is None and allow_missing:
            out.append(None)
            continue
        if pose is None:
            raise ValueError(
                f"poses[{k}] is None: only KITTI files mark a scan without a pose (a line "
                "of nan); TUM timestamps and 3DMatch pair ids name their scans, so leave "
                "it out there"
            )
        out.append(_check_pose(np.asarray(pose, dtype=np.float64), f"poses[{k}]"))
    if not any(p is not None for p in out):
        raise ValueError("no poses to write")
    return out


def _line(values) -> str:
    """Numbers as text that reads back to the same doubles (the shortest such
    decimal of each: survey coordinates keep every digit)."""
    return " ".join(_number(float(v)) for v in values)


def _number(value: float) -> str:
    """The shortest decimal that reads back as ``value`` (``1`` for 1.0)."""
    text = repr(value)
    return text[:-2] if text.endswith(".0") else text


def _rows(path: Path, width: int) -> np.ndarray:
    """The numeric rows of a text file, each of ``width`` numbers (``#`` comments and
    blank lines skipped); ValueError naming the first bad line."""
    rows = []
    for number, line in enumerate(path.read_text().splitlines(), start=1):
        text = line.split("#", 1)[0].strip()
        if not text:
            continue
        words = text.split()
        try:
            values = [float(w) for w in words]
        except ValueError:
            raise ValueError(f"{path}, line {number}: not numbers: {text[:60]!r}") from None
        if len(values) != width:
            raise ValueError(f"{path}, line {number}: {len(values)} numbers, expected {width}")
        rows.append(values)
    if not rows:
        raise ValueError(f"{path}: no poses in this file")
    return np.asarray(rows)


def log_records(path: str | os.PathLike, size: int) -> dict[tuple[int, int], np.ndarray]:
    """The records of a 3DMatch ``.log`` / ``.info`` file (Choi et al.'s layout): a
    header line ``i j n`` followed by a ``size`` x ``size`` matrix, by ``(i, j)``;
    ValueError naming the first record that is not one."""
    lines = [ln.split() for ln in Path(path).read_text().splitlines() if ln.strip()]
    if len(lines) % (size + 1):
        raise ValueError(f"{path}: expected records of {size + 1} lines, got {len(lines)} lines")
    out = {}
    for k in range(0, len(lines), size + 1):
        rows = lines[k + 1 : k + 1 + size]
        try:
            if len(lines[k]) < 2 or any(len(row) != size for row in rows):
                raise ValueError
            i, j = int(lines[k][0]), int(lines[k][1])
            out[(i, j)] = np.array([[float(v) for v in row] for row in rows])
        except ValueError:
            raise ValueError(
                f"{path}, record {k // (size + 1)}: not a header and a {size} x {size} matrix"
            ) from None
    return out


def write_poses(
    path: str | os.PathLike,
    poses: Sequence,
    format: str = "auto",
    *,
    timestamps: Sequence[float] | None = None,
    pairs: Sequence[tuple[int, int]] | None = None,
    n_fragments: int | None = None,
    comment: str | None = None,
) -> None:
    """Write poses as a trajectory file.

    Parameters
    ----------
    path : path-like
    poses : sequence of array-like (4, 4)
        Rigid transformations (ValueError otherwise). KITTI only: ``None`` for a scan
        without a pose, written as a line of 12 ``nan`` so that line k stays scan k.
    format : {"auto", "kitti", "tum", "3dmatch"}, default="auto"
        ``"auto"``: ``"3dmatch"`` for a ``.log`` path, else ``"kitti"``
        (:func:`pose_format`).
    timestamps : sequence of float, default=None
        TUM only: one per pose (default: 0, 1, 2, ...).
    pairs : sequence of (int, int), default=None
        3DMatch only: the ``(i, j)`` of each record, the pose mapping fragment ``j``
        into fragment ``i`` (default: ``(0, k)``, scan ``k`` into scan 0, the frame of
        :func:`~o3d_rpointhop.register_multiway`'s poses).
    n_fragments : int, default=None
        3DMatch only: the third number of every header line (default: the number of
        poses).
    comment : str, default=None
        TUM only (the one format with comments): a first line ``# comment``, e.g. the
        record of the run that made the poses; readers skip it. ValueError for the
        other formats.
    """
    format = pose_format(path, format)
    if comment is not None and format != "tum":
        raise ValueError(f"a {format} trajectory has no comments; only TUM's has")
    poses = _as_poses(poses, allow_missing=format == "kitti")
    path = Path(path)
    lines = []
    if format == "kitti":
        lines = [
            " ".join(["nan"] * 12) if pose is None else _line(pose[:3].ravel()) for pose in poses
        ]
    elif format == "tum":
        stamps = np.arange(len(poses), dtype=float) if timestamps is None else timestamps
        if len(stamps) != len(poses):
            raise ValueError(f"{len(stamps)} timestamps for {len(poses)} poses")
        for stamp, pose in zip(stamps, poses, strict=True):
            quat = Rotation.from_matrix(pose[:3, :3]).as_quat()  # x, y, z, w
            values = [float(stamp), *pose[:3, 3], *quat]
            lines.append(_line(values))
    else:  # "3dmatch"
        ids = [(0, k) for k in range(len(poses))] if pairs is None else list(pairs)
        if len(ids) != len(poses):
            raise ValueError(f"{len(ids)} pairs for {len(poses)} poses")
        total = len(poses) if n_fragments is None else int(n_fragments)
        for (i, j), pose in zip(ids, poses, strict=True):
            lines.append(f"{int(i)} {int(j)} {total}")
            lines += [_line(row) for row in pose]
    if comment is not None:
        lines.insert(0, "# " + " ".join(comment.splitlines()))
    path.write_text("\n".join(lines) + "\n")


def write_trajectory(
    path: str | os.PathLike,
    poses: Sequence,
    format: str = "auto",
    *,
    comment: str | None = None,
) -> None:
    """Write scan ``k``'s pose (``None``: the scan has none) so that every format says
    which scan each pose is.

    KITTI: line ``k`` is scan ``k``, a line of 12 ``nan`` for a scan without a pose.
    TUM: timestamp ``k`` names scan ``k``; scans without a pose are left out (TUM has
    no way to mark one). 3DMatch ``.log``: record ``0 k n`` is scan ``k`` into scan 0,
    ``n`` the number of scans; scans without a pose are left out. :func:`read_trajectory`
    reads each back as the same list. ``format="auto"``: 3DMatch for a ``.log`` path,
    else KITTI (:func:`pose_format`). ``comment``: see :func:`write_poses` (TUM only).
    """
    format = pose_format(path, format)
    poses = list(poses)
    placed = [k for k, pose in enumerate(poses) if format == "kitti" or pose is not None]
    write_poses(
        path,
        [poses[k] for k in placed],
        format,
        timestamps=[float(k) for k in placed],
        pairs=[(0, k) for k in placed],
        n_fragments=len(poses),
        comment=comment,
    )


def read_trajectory(
    path: str | os.PathLike, format: str = "auto", n_scans: int | None = None
) -> list[np.ndarray | None]:
    """Scan ``k``'s pose at index ``k`` (``None`` for a scan without one), as
    :func:`write_trajectory` writes them.

    KITTI: line ``k``. TUM: a whole-number timestamp ``k`` is scan ``k`` (other
    timestamps: the poses in file order). 3DMatch ``.log``: record ``i k n`` is scan
    ``k``, every record into the same scan ``i``; the list is ``n`` long. ``n_scans``
    lengthens the list to that many scans (ValueError if a pose names a later one).
    ``format="auto"``: 3DMatch for a ``.log`` path, else KITTI (:func:`pose_format`).
    """
    format = pose_format(path, format)
    if format == "kitti":
        out: list = list(read_poses(path, "kitti"))
    elif format == "tum":
        poses = read_poses(path, "tum")
        stamps = _rows(Path(path), 8)[:, 0]
        whole = np.all(stamps == np.round(stamps)) and np.all(stamps >= 0)
        if whole and len(set(stamps.tolist())) == len(stamps):
            out = [None] * (int(stamps.max()) + 1)
            for stamp, pose in zip(stamps, poses, strict=True):
                out[int(stamp)] = pose
        else:
            out = list(poses)
    else:  # "3dmatch"
        records = read_poses(path, "3dmatch")
        references = {i for i, _ in records}
        if len(references) != 1:
            raise ValueError(
                f"{path}: records into several scans ({sorted(references)}), not one trajectory"
            )
        total = max(int(ln.split()[2]) for ln in _headers(Path(path)))
        out = [None] * max(total, max(j for _, j in records) + 1)
        for (_, j), pose in records.items():
            out[j] = pose
    if n_scans is not None:
        if len(out) > n_scans and any(p is not None for p in out[n_scans:]):
            raise ValueError(f"{path}: poses of more than {n_scans} scans")
        out = (out + [None] * n_scans)[:n_scans]
    return out


def _headers(path: Path) -> list[str]:
    """The header lines ``i j n`` of a ``.log`` file (every fifth non-blank line)."""
    lines = [ln for ln in path.read_text().splitlines() if ln.strip()]
    return [ln for ln in lines[::5] if len(ln.split()) >= 3] or ["0 0 0"]


def read_poses(
    path: str | os.PathLike, format: str = "auto"
) -> list[np.ndarray] | dict[tuple[int, int], np.ndarray]:
    """Read a trajectory file :func:`write_poses` (or KITTI, TUM, 3DMatch) wrote, in
    ``format`` (``"auto"``: 3DMatch for a ``.log`` path, else KITTI; :func:`pose_format`).

    Returns
    -------
    list of ndarray (4, 4), or dict
        KITTI and TUM: the poses in file order (TUM's timestamps are dropped; read
        the first column with ``np.loadtxt`` for them); a KITTI line of 12 ``nan`` (a
        scan without a pose) reads as None. 3DMatch: ``{(i, j): pose}``.
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    format = pose_format(path, format)
    if format == "kitti":
        rows = _rows(path, 12)
        missing = np.isnan(rows).all(axis=1)
        if not (~missing).any():
            raise ValueError(f"{path}: no poses in this file, only scans without one")
        return [
            None
            if gone
            else _check_pose(np.vstack([r.reshape(3, 4), [0, 0, 0, 1]]), f"{path}, pose {k}")
            for k, (r, gone) in enumerate(zip(rows, missing, strict=True))
        ]
    elif format == "tum":
        rows = _rows(path, 8)
        norms = np.linalg.norm(rows[:, 4:], axis=1)
        if (np.abs(norms - 1) > 1e-3).any():
            raise ValueError(f"{path}: a quaternion is not of unit length")
        poses = []
        for r in rows:
            pose = np.eye(4)
            pose[:3, :3] = Rotation.from_quat(r[4:]).as_matrix()
            pose[:3, 3] = r[1:4]
            poses.append(pose)
    else:  # "3dmatch"
        records = log_records(path, 4)
        if not records:
            raise ValueError(f"{path}: no poses in this file")
        return {
            ij: _check_pose(pose, f"{path}, record {k}")
            for k, (ij, pose) in enumerate(records.items())
        }
    return [_check_pose(p, f"{path}, pose {k}") for k, p in enumerate(poses)]


def read_matrix(path: str | os.PathLike) -> np.ndarray:
    """One rigid 4x4 matrix: a text file of four rows of four numbers, or a JSON file
    with a ``"transformation"`` (what ``register --transform T.json``, ``--json`` and
    a saved result hold)."""
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    if path.suffix.lower() == ".json":
        try:
            body = json.loads(path.read_text())
        except (ValueError, UnicodeDecodeError) as exc:
            raise ValueError(f"{path}: not a JSON file: {exc}") from None
        if not isinstance(body, dict) or "transformation" not in body:
            raise ValueError(f'{path}: no "transformation" in this JSON file')
        try:
            rows = np.asarray(body["transformation"], dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError(f"{path}: the transformation is not a 4x4 matrix of numbers") from None
    else:
        rows = _rows(path, 4)
    return _check_pose(rows, str(path))


def write_matrix(path: str | os.PathLike, matrix) -> None:
    """One 4x4 matrix as four rows of text (what :func:`read_matrix` and ``--init``
    read)."""
    matrix = _check_pose(np.asarray(matrix, dtype=np.float64), "matrix")
    Path(path).write_text("".join(_line(row) + "\n" for row in matrix))


def write_pose_graph(path: str | os.PathLike, pose_graph) -> None:
    """An Open3D ``PoseGraph`` in Open3D's JSON format (``open3d.io.read_pose_graph``
    reads it)."""
    import open3d as o3d

    if Path(path).suffix.lower() != ".json":
        raise ValueError(f"{path}: Open3D writes pose graphs as .json files")
    o3d.io.write_pose_graph(str(path), pose_graph)  # returns nothing in Open3D 0.19+
    if not Path(path).is_file():
        raise OSError(f"Open3D could not write {path}")


def read_pose_graph(path: str | os.PathLike):
    """An Open3D ``PoseGraph`` from Open3D's JSON format."""
    import open3d as o3d

    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"{path}: no such file")
    graph = o3d.io.read_pose_graph(str(path))
    if len(graph.nodes) == 0:
        raise ValueError(f"{path}: no pose graph nodes (not an Open3D pose graph file)")
    return graph
