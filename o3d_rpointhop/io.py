"""Reading and writing point clouds, with errors that say what went wrong."""

from __future__ import annotations

import contextlib
import io
import os
import re
import sys
import tempfile
from pathlib import Path

import numpy as np
import open3d as o3d

from ._utils.validation import as_points

__all__ = ["read_cloud", "write_cloud", "OPEN3D_FORMATS"]

_ANSI = re.compile(r"\x1b\[[0-9;]*[A-Za-z]")


def _flush_c_stdio() -> None:
    try:
        import ctypes

        ctypes.CDLL(None).fflush(None)
    except (OSError, AttributeError):  # no C library to call: nothing buffered there
        pass


@contextlib.contextmanager
def _captured_output():
    """Capture what a reader prints: RPly writes to file descriptor 2 from C, Open3D's log
    goes through Python's ``sys.stdout``; yields a list that receives the text."""
    captured: list[str] = []
    sys.stdout.flush()
    sys.stderr.flush()
    saved = [os.dup(1), os.dup(2)]
    python_level = io.StringIO()
    with tempfile.TemporaryFile(mode="w+b") as sink:
        try:
            os.dup2(sink.fileno(), 1)
            os.dup2(sink.fileno(), 2)
            with (
                contextlib.redirect_stdout(python_level),
                contextlib.redirect_stderr(python_level),
                o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Warning),
            ):
                yield captured
        finally:
            _flush_c_stdio()  # Open3D's log sits in C's stdout buffer until flushed
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            for fd in saved:
                os.close(fd)
            sink.seek(0)
            text = sink.read().decode("utf-8", "replace") + python_level.getvalue()
            # RPly's own line names the problem best: put it first.
            lines = sorted(_ANSI.sub("", text).splitlines(), key=lambda ln: "RPly" not in ln)
            captured.append("\n".join(lines))


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
        damaged or truncated (whatever Open3D's reader reports becomes the message, and
        nothing is printed), or it holds no points or non-finite coordinates.
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
        with _captured_output() as log:
            cloud = o3d.io.read_point_cloud(str(path))
        problems = [line.strip() for line in log[0].splitlines() if line.strip()]
        if problems:
            raise ValueError(f"{path}: damaged or unreadable {suffix} file ({problems[0]})")
        if not cloud.has_points():
            raise ValueError(f"{path}: no points in this {suffix} file")
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
