"""Reading and writing point clouds, with errors that say what went wrong."""

from __future__ import annotations

import contextlib
import logging
import os
import threading
import warnings
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import open3d as o3d

from ._utils.geometry import vectors
from ._utils.validation import PrecisionWarning, as_points, coarse_float32

log = logging.getLogger(__name__)

__all__ = [
    "read_cloud",
    "read_provenance",
    "write_cloud",
    "OPEN3D_FORMATS",
    "READ_FORMATS",
    "WRITE_FORMATS",
    "MESH_POINTS",
    "PrecisionWarning",
]

# Bytes per value of the PLY property types.
_PLY_SIZES = {
    **dict.fromkeys(("char", "uchar", "int8", "uint8"), 1),
    **dict.fromkeys(("short", "ushort", "int16", "uint16"), 2),
    **dict.fromkeys(("int", "uint", "int32", "uint32", "float", "float32"), 4),
    **dict.fromkeys(("double", "float64"), 8),
}
_PLY_FORMATS = ("ascii", "binary_little_endian", "binary_big_endian")


def _check_ply(path: Path) -> tuple[int, bool]:
    """The number of vertices a PLY file declares, and whether it stores their ``x`` as
    a 32-bit float (which Open3D's reader widens to float64 without a word), after
    checking that its header is well formed and that its body holds them (so that
    Open3D's reader, whose C parser reports errors by printing, never meets a damaged
    file); ValueError otherwise.

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
        x_float32 = False
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
                    if elements[-1][0] == "vertex" and words[2:] == ["x"]:
                        x_float32 = words[1] in ("float", "float32")
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
            return n_vertices, x_float32  # list properties: sizes known only while reading
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
    return n_vertices, x_float32


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
# Triangle meshes, sampled by area into a cloud (open3d.io.read_triangle_mesh).
_MESH_FORMATS = (".obj", ".stl", ".off", ".glb", ".gltf")
# Survey and driving formats, each through its own reader.
_SURVEY_FORMATS = (".las", ".laz", ".e57", ".bin")
#: Every extension :func:`read_cloud` reads.
READ_FORMATS = OPEN3D_FORMATS + _NUMPY_FORMATS + _MESH_FORMATS + _SURVEY_FORMATS
#: Points :func:`read_cloud` samples from a mesh when not told.
MESH_POINTS = 100_000

# The optional extra that brings each survey format's reader.
_EXTRAS = {".las": ("laspy", "las"), ".laz": ("laspy", "las"), ".e57": ("pye57", "e57")}


def _optional(module: str, suffix: str):
    """The reader module for ``suffix``, or an ImportError naming the install line."""
    import importlib

    try:
        return importlib.import_module(module)
    except ImportError:
        extra = _EXTRAS[suffix][1]
        raise ImportError(
            f"reading {suffix} files needs {module}: pip install '.[{extra}]' in the "
            f"project folder (or pip install {module}"
            f"{' lazrs' if extra == 'las' else ''})"
        ) from None


def _cloud(points, colors=None, normals=None) -> o3d.geometry.PointCloud:
    cloud = o3d.geometry.PointCloud(vectors(points))
    if colors is not None:
        cloud.colors = vectors(np.clip(colors, 0.0, 1.0))
    if normals is not None:
        cloud.normals = vectors(normals)
    return cloud


def _unit_colors(channels: list[np.ndarray]) -> np.ndarray | None:
    """Integer colour channels as floats in [0, 1] (8 or 16 bits, judged by the largest
    value); None when every channel is zero (a format's colour fields left empty)."""
    rgb = np.stack([np.asarray(c, dtype=np.float64) for c in channels], axis=1)
    top = rgb.max(initial=0.0)
    if top == 0:
        return None
    return rgb / (255.0 if top <= 255 else 65535.0)


def _first_line(exc: BaseException) -> str:
    """A reader library's error in one line (libE57 appends its call stack)."""
    lines = [ln.strip() for ln in str(exc).splitlines() if ln.strip()]
    return lines[0] if lines else type(exc).__name__


def _read_las(path: Path) -> o3d.geometry.PointCloud:
    laspy = _optional("laspy", path.suffix.lower())
    try:
        las = laspy.read(str(path))
    except Exception as exc:  # laspy raises its own errors, and OSError/ValueError
        raise ValueError(
            f"{path}: damaged or unreadable {path.suffix} file ({_first_line(exc)})"
        ) from None
    # Scaled coordinates in float64: survey offsets keep their millimetres.
    points = np.column_stack([np.asarray(las.x), np.asarray(las.y), np.asarray(las.z)])
    names = set(las.point_format.dimension_names)
    colors = None
    if {"red", "green", "blue"} <= names:
        colors = _unit_colors([las.red, las.green, las.blue])
    return _cloud(as_points(points, name=str(path)), colors)


def _e57_stores_single(header) -> bool:
    """Whether the scan of ``header`` stores its cartesian coordinates in single
    precision."""
    from pye57 import libe57

    try:
        prototype = libe57.StructureNode(header.points.prototype())
        node = prototype.get("cartesianX")
        if node.type() != libe57.NodeType.E57_FLOAT:
            return False
        return libe57.FloatNode(node).precision() == libe57.FloatPrecision.E57_SINGLE
    except Exception:  # a scan without cartesian fields: nothing to judge
        return False


def _read_e57(path: Path) -> o3d.geometry.PointCloud:
    pye57 = _optional("pye57", ".e57")
    try:
        e57 = pye57.E57(str(path))
        scans = [
            e57.read_scan(k, colors=True, ignore_missing_fields=True, transform=True)
            for k in range(e57.scan_count)
        ]
    except Exception as exc:  # libE57's errors come as its own exception type
        raise ValueError(f"{path}: damaged or unreadable .e57 file ({_first_line(exc)})") from None
    if not scans:
        raise ValueError(f"{path}: no scans in this .e57 file")
    for k, scan in enumerate(scans):
        header = e57.get_header(k)
        if _e57_stores_single(header):  # judged in the scan's own frame, before its pose
            xyz = np.column_stack([scan[f"cartesian{a}"] for a in "XYZ"]).astype(np.float64)
            local = (xyz - np.asarray(header.translation)) @ np.asarray(header.rotation_matrix)
            _warn_if_coarse(local.astype(np.float32), path, depth=2)
    parts, colors = [], []
    for scan in scans:
        xyz = np.column_stack([scan["cartesianX"], scan["cartesianY"], scan["cartesianZ"]]).astype(
            np.float64
        )
        parts.append(xyz)
        if all(c in scan for c in ("colorRed", "colorGreen", "colorBlue")):
            colors.append(_unit_colors([scan[c] for c in ("colorRed", "colorGreen", "colorBlue")]))
        else:
            colors.append(None)
    points = as_points(np.concatenate(parts), name=str(path))
    rgb = np.concatenate(colors) if all(c is not None for c in colors) else None
    return _cloud(points, rgb)


def _warn_if_coarse(points32: np.ndarray, path: Path, depth: int = 0) -> None:
    """A :class:`PrecisionWarning` when the float32 coordinates a file stores are too
    coarse for the cloud's own size (said by the reader, where it is still known),
    pointing at the caller of :func:`read_cloud` / :func:`write_cloud` (``depth``:
    the frames between those and this call)."""
    problem = coarse_float32(points32, str(path))
    if problem is not None:
        warnings.warn(problem, PrecisionWarning, stacklevel=3 + depth)


def _pcd_stores_float32(path: Path) -> bool:
    """Whether a PCD file stores its ``x`` as a 32-bit float (Open3D writes them so, and
    its reader widens them to float64 without a word)."""
    try:
        with open(path, "rb") as fh:
            header = []
            for raw in fh:
                line = raw.decode("ascii", "replace").split()
                header.append(line)
                if line[:1] == ["DATA"] or len(header) > 200:
                    break
    except OSError:
        return False
    fields = next((ln[1:] for ln in header if ln[:1] == ["FIELDS"]), [])
    sizes = next((ln[1:] for ln in header if ln[:1] == ["SIZE"]), [])
    types = next((ln[1:] for ln in header if ln[:1] == ["TYPE"]), [])
    if "x" in fields and len(sizes) == len(types) == len(fields):
        k = fields.index("x")
        return sizes[k] == "4" and types[k] == "F"
    return False


def _read_kitti(path: Path) -> o3d.geometry.PointCloud:
    """A KITTI Velodyne sweep: float32 records of x, y, z, reflectance."""
    size = path.stat().st_size
    if size % 16:
        raise ValueError(
            f"{path}: not a KITTI .bin sweep ({size} bytes is not a whole number of "
            "16-byte x, y, z, reflectance records)"
        )
    records = np.fromfile(path, dtype="<f4").reshape(-1, 4)
    points = as_points(records[:, :3].astype(np.float64), name=str(path))
    # The format's float32 is all the precision there is: say so here, where it is
    # still known, when it is too coarse for the sweep's own size.
    _warn_if_coarse(records[:, :3], path, depth=2)
    return _cloud(points)


def _sample_mesh(path: Path, n_points: int) -> o3d.geometry.PointCloud:
    """``n_points`` drawn uniformly by area from the mesh's triangles, with the
    triangles' normals; a fixed seed (Open3D's own sampler draws from a process-wide
    generator), so the same file gives the same cloud."""
    with _quiet_open3d():
        mesh = o3d.io.read_triangle_mesh(str(path))
    vertices = np.asarray(mesh.vertices)
    triangles = np.asarray(mesh.triangles)
    if len(vertices) == 0:
        raise ValueError(f"{path}: no vertices in this {path.suffix} file (empty, or damaged)")
    as_points(vertices, name=str(path))
    if len(triangles) == 0:  # a mesh file holding only points
        return _cloud(vertices)
    a, b, c = (vertices[triangles[:, k]] for k in range(3))
    cross = np.cross(b - a, c - a)
    area = np.linalg.norm(cross, axis=1)
    if not area.sum() > 0:
        raise ValueError(f"{path}: every triangle of this mesh has zero area")
    rng = np.random.default_rng(0)
    pick = rng.choice(len(triangles), size=n_points, p=area / area.sum())
    u, v = rng.random((2, n_points))
    flip = u + v > 1  # reflect into the triangle: uniform barycentric coordinates
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    points = a[pick] + u[:, None] * (b - a)[pick] + v[:, None] * (c - a)[pick]
    normals = cross[pick] / np.maximum(area[pick], 1e-300)[:, None]
    colors = None
    if mesh.has_vertex_colors():
        rgb = np.asarray(mesh.vertex_colors)
        w = 1 - u - v
        colors = (
            w[:, None] * rgb[triangles[pick, 0]]
            + u[:, None] * rgb[triangles[pick, 1]]
            + v[:, None] * rgb[triangles[pick, 2]]
        )
    return _cloud(points, colors, normals)


def read_cloud(
    path: str | os.PathLike, *, mesh_points: int = MESH_POINTS
) -> o3d.geometry.PointCloud:
    """Read a point cloud from a scan, survey, mesh, numpy or text file.

    Parameters
    ----------
    path : str or path-like
        By extension: ``.ply``, ``.pcd``, ``.xyz``, ``.xyzn``, ``.xyzrgb``, ``.pts``
        (through Open3D); ``.las`` / ``.laz`` (laspy with its LAZ backend, the ``las``
        extra; coordinates scaled and offset in float64, colours when the point format
        has them); ``.e57`` (pye57, the ``e57`` extra; every scan, placed by its pose,
        with colours when every scan has them); ``.bin`` (a KITTI Velodyne sweep);
        ``.obj``, ``.stl``, ``.off``, ``.glb``, ``.gltf`` (a triangle mesh, sampled
        uniformly by area, with the triangles' normals); ``.npy`` (an ``(n, 3+)``
        array), ``.npz`` (its ``points`` array, or its only array), ``.txt`` or
        ``.csv`` (whitespace- or comma-separated, first three columns).
    mesh_points : int, default=MESH_POINTS
        Points sampled from a mesh (seeded: the same file gives the same cloud).

    Returns
    -------
    open3d.geometry.PointCloud
        With the file's normals and colours when it has any. Intensities and
        reflectances are not kept (Open3D's point cloud has no field for them).

    Raises
    ------
    FileNotFoundError
        If ``path`` does not exist.
    ImportError
        If the format's optional reader is not installed (the message gives the
        install line).
    ValueError
        If ``path`` is a directory or an empty file, the format is unknown, the file is
        damaged or truncated (a PLY file's header and size are checked before Open3D
        reads it, so nothing is printed; other formats are refused when their reader
        fails or reads no points), or it holds no points or non-finite coordinates.

    Notes
    -----
    Safe to call from several threads at once: nothing process-wide is redirected (only
    Open3D's own warnings are silenced while a read runs).
    """
    cloud = _read_cloud(path, mesh_points)
    extras = [
        n for n, has in (("normals", cloud.has_normals()), ("colours", cloud.has_colors())) if has
    ]
    log.info(
        "read %s: %d points%s",
        path,
        len(cloud.points),
        f" with {' and '.join(extras)}" if extras else "",
    )
    return cloud


def _read_cloud(path: str | os.PathLike, mesh_points: int) -> o3d.geometry.PointCloud:
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
        declared, stores_float32 = None, suffix == ".pcd" and _pcd_stores_float32(path)
        if suffix == ".ply":
            try:
                declared, stores_float32 = _check_ply(path)
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
        if stores_float32:
            _warn_if_coarse(np.asarray(cloud.points).astype(np.float32), path, depth=1)
        return cloud
    if suffix in (".las", ".laz"):
        return _read_las(path)
    if suffix == ".e57":
        return _read_e57(path)
    if suffix == ".bin":
        return _read_kitti(path)
    if suffix in _MESH_FORMATS:
        if isinstance(mesh_points, bool) or not isinstance(mesh_points, int) or mesh_points < 1:
            raise ValueError(f"mesh_points must be a positive int, got {mesh_points!r}")
        return _sample_mesh(path, mesh_points)
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
        if arr.dtype == np.float32:
            _warn_if_coarse(arr, path, depth=1)
        return o3d.geometry.PointCloud(vectors(points))
    raise ValueError(
        f"{path}: unknown point cloud format {suffix!r}; use one of {', '.join(READ_FORMATS)}"
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


#: Extensions :func:`write_cloud` writes.
WRITE_FORMATS = OPEN3D_FORMATS + (".npy", ".las", ".laz", ".e57")
#: The VLR a LAS file written here records its run in (user id, record id).
LAS_RECORD = ("o3d-rpointhop", 1)


def _as_open3d(cloud) -> o3d.geometry.PointCloud:
    if isinstance(cloud, o3d.geometry.PointCloud):
        return cloud
    return o3d.geometry.PointCloud(vectors(as_points(cloud)))


def _las_grid(points: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Offsets and scales for points with no template: offsets at the whole units
    below the points, a power-of-ten scale that keeps about 1e-7 of the cloud's extent
    (well inside LAS's 32-bit integers)."""
    low = np.floor(points.min(axis=0))
    extent = max(float(np.ptp(points, axis=0).max()), 1e-6)
    scale = 10.0 ** np.floor(np.log10(extent * 1e-7))
    return low, np.full(3, scale)


def _las_records(laspy, path: Path, files: Sequence, n_points: int):
    """The point records of the LAS / LAZ ``files``, joined in order, in the first
    file's point format (extra bytes included): ``(point_format, version, array)``.
    Files of another point format are converted to it first (laspy's ``convert``, which
    keeps the dimensions the formats share; the others are 0, said in one warning)."""
    sources = []
    for name in files:
        try:
            sources.append(laspy.read(str(name)))
        except Exception as exc:
            raise ValueError(
                f"{name}: damaged or unreadable LAS file ({_first_line(exc)})"
            ) from None
    total = sum(len(s.points) for s in sources)
    if total != n_points:
        raise ValueError(
            f"{path}: the cloud has {n_points} points, the LAS files it comes from {total}"
        )
    first = sources[0]
    point_format = first.header.point_format
    names = first.points.array.dtype.names
    array = np.zeros(total, dtype=first.points.array.dtype)
    start, lost = 0, set()
    for name, source in zip(files, sources, strict=True):
        if source.header.point_format.id != point_format.id:
            source = laspy.convert(source, point_format_id=point_format.id)
        have = source.points.array
        missing = [n for n in names if n not in have.dtype.names]
        if missing:
            lost.add(Path(name).name)
        for field in names:
            if field in have.dtype.names:
                array[field][start : start + len(have)] = have[field]
        start += len(have)
    if lost:
        warnings.warn(
            f"{path}: {', '.join(sorted(lost))} lack some of {Path(files[0]).name}'s point "
            "dimensions; they are written as 0 for their points",
            UserWarning,
            stacklevel=4,
        )
    return point_format, str(first.header.version), array


def _write_las(path: Path, cloud, like, provenance, las_points_of, keep_colours) -> None:
    laspy = _optional("laspy", path.suffix.lower())
    points = np.asarray(cloud.points)
    colours = np.asarray(cloud.colors) if cloud.has_colors() else None
    records = None
    if las_points_of:
        point_format, version, records = _las_records(laspy, path, las_points_of, len(points))
    template = None
    if like is not None and Path(like).suffix.lower() in (".las", ".laz"):
        template = laspy.open(str(like)).header
    if template is not None:
        offsets, scales = np.asarray(template.offsets), np.asarray(template.scales)
        if records is None:
            point_format, version = template.point_format.id, str(template.version)
    else:
        offsets, scales = _las_grid(points)
        if records is None:
            point_format, version = 0, "1.2"
    format_id = point_format if isinstance(point_format, int) else point_format.id
    names = set(laspy.PointFormat(format_id).dimension_names)
    has_rgb = {"red", "green", "blue"} <= names
    if colours is not None and not has_rgb and records is None:
        point_format = 7 if version == "1.4" else 3  # the same format with colours
        has_rgb = True
    header = laspy.LasHeader(point_format=point_format, version=version)
    header.offsets, header.scales = offsets, scales
    span = (points - offsets) / scales
    if np.abs(span).max(initial=0.0) >= 2**31 - 1:
        raise ValueError(
            f"{path}: the points do not fit the LAS grid (offsets {offsets.tolist()}, "
            f"scales {scales.tolist()}) of {like}"
        )
    if provenance is not None:
        import json

        header.vlrs.append(
            laspy.VLR(*LAS_RECORD, "o3d-rpointhop run", json.dumps(provenance).encode())
        )
    las = laspy.LasData(header)
    if records is not None:
        las.points = laspy.ScaleAwarePointRecord(records, header.point_format, scales, offsets)
    las.x, las.y, las.z = points[:, 0], points[:, 1], points[:, 2]
    if colours is not None and has_rgb and not (records is not None and keep_colours):
        rgb = np.round(np.clip(colours, 0, 1) * 65535).astype(np.uint16)
        las.red, las.green, las.blue = rgb[:, 0], rgb[:, 1], rgb[:, 2]
    las.write(str(path))


def _write_e57(path: Path, cloud) -> None:
    pye57 = _optional("pye57", ".e57")
    points = np.asarray(cloud.points)
    # pye57 stores coordinates in single precision: they are written about the
    # cloud's centre (in whole units), which the scan's pose puts back, so that float32
    # holds them to about 1e-7 of the cloud's extent at survey coordinates too.
    centre = np.floor(points.mean(axis=0))
    data = {f"cartesian{a}": points[:, k] - centre[k] for k, a in enumerate("XYZ")}
    if cloud.has_colors():
        rgb = np.round(np.clip(np.asarray(cloud.colors), 0, 1) * 255).astype(np.uint8)
        for k, channel in enumerate(("Red", "Green", "Blue")):
            data[f"color{channel}"] = rgb[:, k].copy()
    e57 = pye57.E57(str(path), mode="w")
    try:
        e57.write_scan_raw(
            data, name=path.stem, rotation=np.array([1.0, 0.0, 0.0, 0.0]), translation=centre
        )
    finally:
        e57.close()


#: How the lines of a run's record start in a PLY header.
_PLY_RECORD = b"comment o3d-rpointhop "
#: Characters of the record per PLY comment line (Open3D's PLY reader, RPly, aborts on
#: header lines over 1024 characters).
_PLY_CHUNK = 200


def _ply_with_comment(path: Path, provenance: dict) -> None:
    """Record ``provenance`` as JSON in ``comment`` lines of a PLY header (Open3D writes
    none; readers skip comments): the file is copied once with the lines added."""
    import json
    import shutil
    import tempfile

    text = json.dumps(provenance).encode()
    lines = b"".join(
        _PLY_RECORD + text[k : k + _PLY_CHUNK] + b"\n" for k in range(0, len(text), _PLY_CHUNK)
    )
    with open(path, "rb") as src:
        opening = src.readline() + src.readline()  # "ply", then the format line
        with tempfile.NamedTemporaryFile(dir=path.parent, delete=False) as dst:
            dst.write(opening)
            dst.write(lines)
            shutil.copyfileobj(src, dst)
    os.replace(dst.name, path)


def read_provenance(path: str | os.PathLike) -> dict | None:
    """The record of the run that wrote a cloud file (:func:`write_cloud`'s
    ``provenance``): from a LAS/LAZ file's VLR or a PLY header's comments; ``None``
    when the file holds none."""
    import json

    path = Path(path)
    suffix = path.suffix.lower()
    if suffix in (".las", ".laz"):
        laspy = _optional("laspy", suffix)
        with laspy.open(str(path)) as reader:
            for vlr in reader.header.vlrs:
                if (vlr.user_id, vlr.record_id) == LAS_RECORD:
                    return json.loads(vlr.record_data)
        return None
    if suffix == ".ply":
        parts = []
        with open(path, "rb") as fh:
            for line in fh:
                if line.startswith(_PLY_RECORD):
                    parts.append(line[len(_PLY_RECORD) :].rstrip(b"\n"))
                elif line.strip() == b"end_header":
                    break
        return json.loads(b"".join(parts)) if parts else None
    return None


def write_cloud(
    path: str | os.PathLike,
    cloud,
    *,
    like: str | os.PathLike | None = None,
    provenance: dict | None = None,
    las_points_of: Sequence[str | os.PathLike] | None = None,
    keep_colours: bool = True,
) -> None:
    """Write a cloud in the format its extension names.

    Parameters
    ----------
    path : str or path-like
        ``.ply``, ``.pcd``, ``.xyz``, ``.xyzn``, ``.xyzrgb``, ``.pts`` (Open3D), ``.npy``
        (the points), ``.las`` / ``.laz`` (laspy, the ``las`` extra: coordinates on the
        LAS grid of ``like``, colours as 16-bit channels), ``.e57`` (pye57, the ``e57``
        extra: one scan named after the file, its points in single precision about
        their centre, which the scan's pose puts back; colours as 8-bit).
    cloud : array-like (n, 3) or open3d.geometry.PointCloud
    like : str or path-like, optional
        A LAS/LAZ file whose point format, version, offsets and scales a LAS/LAZ output
        keeps (the scan the cloud came from): survey coordinates go back on their own
        grid. Without one, offsets at the whole units below the points and a
        power-of-ten scale of about 1e-7 of the cloud's extent.
    provenance : dict, optional
        What made the cloud, JSON-ready: recorded in a LAS/LAZ file as a VLR (user id
        ``"o3d-rpointhop"``, record 1) and in a PLY header as ``comment`` lines;
        :func:`read_provenance` reads it back. The other formats have no place for it.
    las_points_of : sequence of str or path-like, optional
        LAS / LAZ files whose points, joined in order, are the cloud's points (moved: a
        registered scan, merged scans): a LAS / LAZ output then keeps every dimension
        of each point (intensity, return numbers, classification, GPS time, colours,
        extra bytes, ...) in the first file's point format, with the cloud's
        coordinates. ValueError when the counts differ.
    keep_colours : bool, default=True
        With ``las_points_of``: keep the files' own colour values (the cloud's colours
        come from them); False writes the cloud's colours instead (scans painted by
        scan).
    """
    path = check_output_path(path)
    cloud = _as_open3d(cloud)
    suffix = path.suffix.lower()
    if suffix == ".npy":
        save_npy(path, np.asarray(cloud.points))
    elif suffix in (".las", ".laz"):
        _write_las(path, cloud, like, provenance, las_points_of, keep_colours)
    elif suffix == ".e57":
        _write_e57(path, cloud)
    elif suffix in OPEN3D_FORMATS:
        if suffix == ".pcd":  # Open3D writes PCD coordinates as float32
            _warn_if_coarse(np.asarray(cloud.points).astype(np.float32), path)
        if not o3d.io.write_point_cloud(str(path), cloud):
            raise OSError(f"Open3D could not write {path}")
        if suffix == ".ply" and provenance is not None:
            _ply_with_comment(path, provenance)
    else:
        raise ValueError(
            f"{path}: cannot write format {suffix!r}; use one of {', '.join(WRITE_FORMATS)}"
        )
