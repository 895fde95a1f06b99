"""Reading and writing point clouds, with errors that say what went wrong."""

from __future__ import annotations

import contextlib
import os
import threading
from pathlib import Path

import numpy as np
import open3d as o3d

from ._utils.validation import as_points

__all__ = ["read_cloud", "write_cloud", "OPEN3D_FORMATS"]

# Bytes per value of the PLY property types.
_PLY_SIZES = {
    **dict.fromkeys(("char", "uchar", "int8", "uint8"), 1),
    **dict.fromkeys(("short", "ushort", "int16", "uint16"), 2),
    **dict.fromkeys(("int", "uint", "int32", "uint32", "float", "float32"), 4),
    **dict.fromkeys(("double", "float64"), 8),
}
_PLY_FORMATS = ("ascii", "binary_little_endian", "binary_big_endian")


def _check_ply(path: Path) -> int:
    """The number of vertices a PLY file declares, after checking that its header is
    well formed and that its body holds them (so that Open3D's reader, whose C parser
    reports errors by printing, never meets a damaged file); ValueError otherwise.

    The body is checked up to the end of the vertex element: by size for binary files,
    by its number of values for ASCII ones. Elements after the vertices (faces, range
    grids) are Open3D's to read.
    """
    size = path.stat().st_size
    with open(path, "rb") as fh:
        first = fh.readline()
        if first.strip() != b"ply":
            raise ValueError("not a PLY file: its first line is not 'ply'")
        header = len(first)
        fmt, elements = None, []  # elements: [name, count, [property type or None]]
        for raw in fh:
            header += len(raw)
            words = raw.decode("ascii", "replace").split()
            if not words or words[0] in ("comment", "obj_info"):
                continue
            if words[0] == "end_header":
                break
            try:
                if words[0] == "format":
                    fmt = words[1]
                elif words[0] == "element":
                    elements.append([words[1], int(words[2]), []])
                elif words[0] == "property":
                    elements[-1][2].append(None if words[1] == "list" else _PLY_SIZES[words[1]])
                else:
                    raise ValueError
            except (ValueError, IndexError, KeyError):
                raise ValueError(f"bad header line {raw.strip()[:60]!r}") from None
        else:
            raise ValueError("its header has no end_header line")
        if fmt not in _PLY_FORMATS:
            raise ValueError(f"unknown PLY format {fmt!r}")
        names = [e[0] for e in elements]
        if "vertex" not in names:
            raise ValueError("it has no vertex element")
        upto = elements[: names.index("vertex") + 1]
        n_vertices = upto[-1][1]
        if any(None in properties for _, _, properties in upto):
            return n_vertices  # list properties: sizes known only while reading
        if fmt == "ascii":
            needed = sum(count * len(properties) for _, count, properties in upto)
            found = len(fh.read().split())
            what = "values"
        else:
            needed = sum(count * sum(properties) for _, count, properties in upto)
            found = size - header
            what = "bytes"
    if found < needed:
        raise ValueError(f"it ends early: {found} {what} where its vertices need {needed}")
    return n_vertices


_QUIET = {"lock": threading.Lock(), "users": 0, "level": None}


@contextlib.contextmanager
def _quiet_open3d():
    """Open3D's own warnings off while any thread is reading (a reference count, so
    threads reading at once restore the caller's level only when the last one is done)."""
    with _QUIET["lock"]:
        if _QUIET["users"] == 0:
            _QUIET["level"] = o3d.utility.get_verbosity_level()
            o3d.utility.set_verbosity_level(o3d.utility.VerbosityLevel.Error)
        _QUIET["users"] += 1
    try:
        yield
    finally:
        with _QUIET["lock"]:
            _QUIET["users"] -= 1
            if _QUIET["users"] == 0:
                o3d.utility.set_verbosity_level(_QUIET["level"])


# Extensions open3d.io.read_point_cloud understands.
OPEN3D_FORMATS = (".ply", ".pcd", ".xyz", ".xyzn", ".xyzrgb", ".pts")
_NUMPY_FORMATS = (".npy", ".npz", ".txt", ".csv")


def read_cloud(path: str | os.PathLike) -> o3d.geometry.PointCloud:
    """Read a point cloud from any format Open3D reads, or from numpy/text files.

    Parameters
    ----------
    path : str or path-like
        ``.ply``, ``.pcd``, ``.xyz``, ``.xyzn``, ``.xyzrgb``, ``.pts`` (through Open3D),
        ``.npy`` (an ``(n, 3+)`` array), ``.npz`` (its ``points`` array, or its only
        array), ``.txt`` or ``.csv`` (whitespace- or comma-separated, first three columns).

    Returns
    -------
    open3d.geometry.PointCloud
        With the file's normals and colours when Open3D read any.

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ValueError
        If ``path`` is a directory or an empty file, the format is unknown, the file is
        damaged or truncated (a PLY file's header and size are checked before Open3D
        reads it, so nothing is printed; other formats are refused when Open3D reads no
        points), or it holds no points or non-finite coordinates.

    Notes
    -----
    Safe to call from several threads at once: nothing process-wide is redirected (only
    Open3D's own warnings are silenced while a read runs).
    """
    path = Path(path)
    if path.is_dir():
        raise ValueError(f"{path}: is a directory, not a point cloud file")
    if not path.exists():
        raise FileNotFoundError(f"{path}: no such file")
    if not path.is_file():
        raise ValueError(f"{path}: not a regular file")
    if path.stat().st_size == 0:
        raise ValueError(f"{path}: the file is empty")
    suffix = path.suffix.lower()
    if suffix in OPEN3D_FORMATS:
        declared = None
        if suffix == ".ply":
            try:
                declared = _check_ply(path)
            except (ValueError, OSError) as exc:
                raise ValueError(f"{path}: damaged or unreadable .ply file ({exc})") from None
        with _quiet_open3d():
            cloud = o3d.io.read_point_cloud(str(path))
        if not cloud.has_points():
            raise ValueError(
                f"{path}: no points in this {suffix} file (empty, or damaged: Open3D read none)"
            )
        if declared is not None and len(cloud.points) != declared:
            raise ValueError(
                f"{path}: damaged or unreadable .ply file ({len(cloud.points)} of "
                f"{declared} vertices read)"
            )
        as_points(cloud, name=str(path))  # finiteness check, naming the file
        return cloud
    if suffix in _NUMPY_FORMATS:
        try:
            if suffix == ".npy":
                arr = np.load(path, allow_pickle=False)
            elif suffix == ".npz":
                with np.load(path, allow_pickle=False) as archive:
                    if "points" in archive.files:
                        arr = archive["points"]
                    elif len(archive.files) == 1:
                        arr = archive[archive.files[0]]
                    else:
                        raise ValueError(f"has arrays {archive.files} but none named 'points'")
            else:
                arr = np.loadtxt(path, delimiter="," if suffix == ".csv" else None, ndmin=2)
        except ValueError as exc:
            raise ValueError(f"{path}: cannot read points ({exc})") from exc
        arr = np.asarray(arr)
        if arr.ndim == 2 and arr.shape[1] > 3:
            arr = arr[:, :3]
        points = as_points(arr, name=str(path))
        return o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    raise ValueError(
        f"{path}: unknown point cloud format {suffix!r}; use one of "
        f"{', '.join(OPEN3D_FORMATS + _NUMPY_FORMATS)}"
    )


def check_output_path(path: str | os.PathLike) -> Path:
    """``path`` as a file to write: refuse a directory or a missing parent folder."""
    path = Path(path)
    if path.is_dir():
        raise ValueError(f"{path}: is a directory; give a file name to write")
    if not path.parent.is_dir():
        raise ValueError(f"{path}: folder {path.parent} does not exist")
    return path


def save_npy(path: str | os.PathLike, array: np.ndarray) -> None:
    """``np.save`` to exactly ``path`` (``np.save`` given a name appends ``.npy``)."""
    with open(check_output_path(path), "wb") as fh:
        np.save(fh, array)


def write_cloud(path: str | os.PathLike, cloud) -> None:
    """Write a cloud (array or Open3D point cloud) in the format its extension names."""
    path = check_output_path(path)
    if not isinstance(cloud, o3d.geometry.PointCloud):
        cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(as_points(cloud)))
    suffix = path.suffix.lower()
    if suffix == ".npy":
        save_npy(path, np.asarray(cloud.points))
        return
    if suffix not in OPEN3D_FORMATS:
        raise ValueError(f"{path}: cannot write format {suffix!r}; use .npy or {OPEN3D_FORMATS}")
    if not o3d.io.write_point_cloud(str(path), cloud):
        raise OSError(f"Open3D could not write {path}")
