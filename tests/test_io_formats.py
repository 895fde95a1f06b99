"""Survey, driving and mesh files: LAS/LAZ, E57, KITTI .bin and triangle meshes."""

from __future__ import annotations

import sys

import numpy as np
import open3d as o3d
import pytest

from o3d_rpointhop.datasets import make_object
from o3d_rpointhop.io import READ_FORMATS, read_cloud
from o3d_rpointhop.transforms import rotation_error_deg

laspy = pytest.importorskip("laspy")

# Survey coordinates: offsets of hundreds of kilometres, millimetre resolution.
OFFSET = np.array([512_345.0, 5_412_678.0, 312.0])


def _las(path, points, rgb=None, point_format=3):
    header = laspy.LasHeader(point_format=point_format, version="1.2")
    header.offsets = OFFSET
    header.scales = np.array([0.001, 0.001, 0.001])
    las = laspy.LasData(header)
    las.x, las.y, las.z = points[:, 0], points[:, 1], points[:, 2]
    if rgb is not None:
        las.red, las.green, las.blue = rgb.T
    las.write(str(path))


@pytest.mark.parametrize("suffix", [".las", ".laz"])
def test_las_keeps_survey_coordinates_to_the_millimetre_and_the_colours(tmp_path, suffix):
    rng = np.random.default_rng(0)
    points = OFFSET + np.round(rng.uniform(0, 50, (500, 3)), 3)
    rgb = rng.integers(0, 65536, (500, 3), dtype=np.uint16)
    _las(tmp_path / f"a{suffix}", points, rgb)
    cloud = read_cloud(tmp_path / f"a{suffix}")
    np.testing.assert_allclose(np.asarray(cloud.points), points, atol=5e-4, rtol=0)
    np.testing.assert_allclose(np.asarray(cloud.colors), rgb / 65535.0, atol=1e-12)
    _las(tmp_path / "plain.las", points, point_format=0)  # a format without colours
    assert not read_cloud(tmp_path / "plain.las").has_colors()


def test_a_truncated_las_file_gets_one_clear_line(tmp_path):
    points = OFFSET + np.random.default_rng(1).uniform(0, 5, (300, 3))
    _las(tmp_path / "a.las", points)
    data = (tmp_path / "a.las").read_bytes()
    (tmp_path / "cut.las").write_bytes(data[: len(data) // 2])
    with pytest.raises(ValueError, match=r"cut.las: damaged or unreadable \.las file"):
        read_cloud(tmp_path / "cut.las")


def test_a_missing_reader_names_the_install_line(tmp_path, monkeypatch):
    (tmp_path / "a.las").write_bytes(b"LASF" + b"\0" * 400)
    monkeypatch.setitem(sys.modules, "laspy", None)  # as if not installed
    with pytest.raises(ImportError, match=r"pip install '\.\[las\]'"):
        read_cloud(tmp_path / "a.las")


def test_e57_reads_every_scan_placed_by_its_pose(tmp_path):
    pye57 = pytest.importorskip("pye57")
    rng = np.random.default_rng(2)
    first, second = rng.uniform(-1, 1, (200, 3)), rng.uniform(-1, 1, (150, 3))
    shift = np.array([10.0, -4.0, 2.5])
    with pye57.E57(str(tmp_path / "a.e57"), mode="w") as e57:
        for part, move in ((first, np.zeros(3)), (second, shift)):
            fields = {
                "cartesianX": part[:, 0],
                "cartesianY": part[:, 1],
                "cartesianZ": part[:, 2],
                "colorRed": np.full(len(part), 255, np.uint8),
                "colorGreen": np.zeros(len(part), np.uint8),
                "colorBlue": np.full(len(part), 51, np.uint8),
            }
            e57.write_scan_raw(fields, translation=move)
    cloud = read_cloud(tmp_path / "a.e57")
    np.testing.assert_allclose(
        np.asarray(cloud.points), np.concatenate([first, second + shift]), atol=1e-9
    )
    np.testing.assert_allclose(np.asarray(cloud.colors)[0], [1.0, 0.0, 0.2])
    (tmp_path / "bad.e57").write_bytes(b"ASTM-E57" + b"\1" * 2000)
    with pytest.raises(ValueError, match=r"bad.e57: damaged or unreadable \.e57 file"):
        read_cloud(tmp_path / "bad.e57")


def test_kitti_sweeps_are_read_and_partial_records_refused(tmp_path):
    rng = np.random.default_rng(3)
    records = rng.uniform(-40, 40, (1000, 4)).astype("<f4")
    records.tofile(tmp_path / "000000.bin")
    cloud = read_cloud(tmp_path / "000000.bin")
    np.testing.assert_array_equal(np.asarray(cloud.points), records[:, :3].astype(np.float64))
    (tmp_path / "cut.bin").write_bytes(records.tobytes()[:-6])
    with pytest.raises(ValueError, match="not a whole number of 16-byte"):
        read_cloud(tmp_path / "cut.bin")


def test_a_damaged_e57_is_one_line(tmp_path):
    pye57 = pytest.importorskip("pye57")
    with pye57.E57(str(tmp_path / "a.e57"), mode="w") as e57:
        points = make_object(500, shape_seed=1)
        e57.write_scan_raw(
            {"cartesianX": points[:, 0], "cartesianY": points[:, 1], "cartesianZ": points[:, 2]}
        )
    whole = (tmp_path / "a.e57").read_bytes()
    (tmp_path / "cut.e57").write_bytes(whole[:5000] + b"\0" * (len(whole) - 5000))
    with pytest.raises(ValueError) as caught:
        read_cloud(tmp_path / "cut.e57")
    message = str(caught.value)
    assert "damaged or unreadable .e57 file" in message and "\n" not in message


def test_a_kitti_sweep_too_coarse_for_its_size_says_so_when_read(tmp_path):
    """float32 is the format's precision: a 20 m sweep stored at UTM coordinates is
    rounded to a quarter metre, and the reader says so while the float32 values are still
    at hand; the same sweep near the origin reads silently."""
    import warnings

    from o3d_rpointhop.io import PrecisionWarning

    rng = np.random.default_rng(5)
    local = rng.uniform(-10, 10, (500, 4))
    far = local + [512_345.0, 4_123_456.0, 87.0, 0.0]
    far.astype("<f4").tofile(tmp_path / "far.bin")
    local.astype("<f4").tofile(tmp_path / "near.bin")
    with pytest.warns(PrecisionWarning, match="float32 resolves only 0.25"):
        read_cloud(tmp_path / "far.bin")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        read_cloud(tmp_path / "near.bin")


def test_float32_precision_is_judged_on_the_cloud_s_own_extent():
    from o3d_rpointhop._utils.validation import coarse_float32

    rng = np.random.default_rng(6)
    small_far = (rng.uniform(0, 10, (200, 3)) + [4e6, 0.0, 0.0]).astype(np.float32)
    wide_far = (rng.uniform(0, 1e6, (200, 3)) + [4e6, 0.0, 0.0]).astype(np.float32)
    assert "float32 resolves only 0.25" in coarse_float32(small_far, "scan")
    assert coarse_float32(wide_far, "scan") is None  # 0.25 m steps over 1000 km: fine
    assert coarse_float32(small_far.astype(np.float64), "scan") is None  # not float32


@pytest.mark.parametrize("suffix", [".obj", ".stl", ".off", ".gltf"])
def test_meshes_are_sampled_by_area_with_their_normals(tmp_path, suffix):
    # A 4 x 1 x 1 box: its long faces hold 16 / 18 of the area.
    mesh = o3d.geometry.TriangleMesh.create_box(4.0, 1.0, 1.0)
    mesh.compute_triangle_normals()
    assert o3d.io.write_triangle_mesh(str(tmp_path / f"box{suffix}"), mesh)
    cloud = read_cloud(tmp_path / f"box{suffix}", mesh_points=9000)
    points, normals = np.asarray(cloud.points), np.asarray(cloud.normals)
    assert points.shape == (9000, 3)
    assert points.min(axis=0) == pytest.approx([0, 0, 0], abs=1e-9)
    assert points.max(axis=0) == pytest.approx([4, 1, 1], abs=1e-9)
    on_end = (np.abs(normals[:, 0]) > 0.99).mean()  # the two 1 x 1 end faces
    assert on_end == pytest.approx(2 / 18, abs=0.02)
    on_face = np.isclose(points, 0).any(axis=1) | np.isclose(points, [4, 1, 1]).any(axis=1)
    assert on_face.all()  # every sample lies on the surface
    again = read_cloud(tmp_path / f"box{suffix}", mesh_points=9000)
    np.testing.assert_array_equal(np.asarray(again.points), points)  # seeded


def test_meshes_and_unknown_formats_are_checked(tmp_path):
    (tmp_path / "empty.obj").write_text("# nothing here\n")
    with pytest.raises(ValueError, match="no vertices"):
        read_cloud(tmp_path / "empty.obj")
    mesh = o3d.geometry.TriangleMesh.create_box()
    o3d.io.write_triangle_mesh(str(tmp_path / "box.obj"), mesh)
    with pytest.raises(ValueError, match="mesh_points"):
        read_cloud(tmp_path / "box.obj", mesh_points=0)
    (tmp_path / "a.dxf").write_text("0\nSECTION\n")
    with pytest.raises(ValueError, match=r"unknown point cloud format '\.dxf'.*\.las.*\.e57"):
        read_cloud(tmp_path / "a.dxf")
    assert {".laz", ".e57", ".bin", ".obj", ".stl", ".ply", ".npy"} <= set(READ_FORMATS)


def test_read_points_register(tmp_path):
    """Two LAS files at survey coordinates, the source a moved copy of the target: each
    reads back as its own points (to the file's millimetre) and the pair registers to
    the motion between them."""
    from scipy.spatial.transform import Rotation

    from o3d_rpointhop import register

    target = make_object(1200, shape_seed=4) * 10
    motion = np.eye(4)
    motion[:3, :3] = Rotation.from_euler("xyz", [4, -3, 6], degrees=True).as_matrix()
    motion[:3, 3] = [0.3, -0.2, 0.1]
    source = (target - motion[:3, 3]) @ motion[:3, :3]  # motion maps source onto target
    _las(tmp_path / "s.las", source + OFFSET)
    _las(tmp_path / "t.las", target + OFFSET)
    read_source = np.asarray(read_cloud(tmp_path / "s.las").points)
    read_target = np.asarray(read_cloud(tmp_path / "t.las").points)
    np.testing.assert_allclose(read_source, source + OFFSET, atol=6e-4)
    np.testing.assert_allclose(read_target, target + OFFSET, atol=6e-4)
    result = register(read_source, read_target, global_method=None)
    shift = np.eye(4)
    shift[:3, 3] = OFFSET  # the motion in survey coordinates
    truth = shift @ motion @ np.linalg.inv(shift)
    assert rotation_error_deg(result.transformation, truth) < 0.1
    moved = read_source @ result.transformation[:3, :3].T + result.transformation[:3, 3]
    assert np.abs(moved - (target + OFFSET)).max() < 0.01


def test_survey_scans_keep_their_colours_through_the_command_line(tmp_path, capsys):
    """Three LAS scans with colours, rebuilt by ``o3d-rpointhop reconstruct``: the merged
    cloud holds every point in its scan's own colour; ``describe`` reads LAZ, E57 and
    KITTI files as ``read_cloud`` does."""
    from helpers import partial_views

    from o3d_rpointhop import RPointHopTransformer
    from o3d_rpointhop.cli import main

    scans, _ = partial_views(3, seed=1)
    names = []
    for k, scan in enumerate(scans):
        rgb = np.tile(np.array([[60000, 20000 * k, 0]], dtype=np.uint16), (len(scan), 1))
        _las(tmp_path / f"s{k}.las", OFFSET + scan, rgb)
        names.append(str(tmp_path / f"s{k}.las"))
    out = tmp_path / "merged.ply"
    assert main(["reconstruct", *names, "-o", str(out)]) == 0
    merged = o3d.io.read_point_cloud(str(out))
    assert len(merged.points) == sum(len(s) for s in scans)
    colours = {tuple(c) for c in np.asarray(merged.colors).round(1)}  # PLY keeps 8 bits
    assert colours == {(0.9, 0.0, 0.0), (0.9, 0.3, 0.0), (0.9, 0.6, 0.0)}
    assert np.abs(np.asarray(merged.points).mean(axis=0) - OFFSET).max() < 10  # in place

    records = np.c_[scans[0], np.zeros(len(scans[0]))].astype("<f4")
    records.tofile(tmp_path / "sweep.bin")
    _las(tmp_path / "scan.laz", OFFSET + scans[0])
    pye57 = pytest.importorskip("pye57")
    with pye57.E57(str(tmp_path / "scan.e57"), mode="w") as e57:
        e57.write_scan_raw({f"cartesian{a}": scans[0][:, k] for k, a in enumerate("XYZ")})
    model = RPointHopTransformer.pretrained(n_components=8)
    for name in ("sweep.bin", "scan.laz", "scan.e57"):
        path = tmp_path / name
        assert (
            main(["describe", str(path), "--n-components", "8", "-o", str(tmp_path / "d.npy")]) == 0
        )
        np.testing.assert_array_equal(
            np.load(tmp_path / "d.npy"), model.transform(read_cloud(path))
        )


@pytest.mark.parametrize("suffix", [".las", ".laz"])
def test_las_goes_back_out_on_the_input_s_grid_with_its_colours_and_run(tmp_path, suffix):
    """A cloud written as LAS/LAZ ``like`` a survey file keeps that file's offsets,
    scales and point format, its colours to 16 bits, and records the run in a VLR;
    without a template the grid still holds survey coordinates to well under a
    millimetre."""
    import json

    from o3d_rpointhop.io import LAS_RECORD, write_cloud

    rng = np.random.default_rng(1)
    points = OFFSET + np.round(rng.uniform(0, 50, (400, 3)), 3)
    rgb = rng.integers(0, 65536, (400, 3), dtype=np.uint16)
    _las(tmp_path / "in.las", points, rgb)
    cloud = read_cloud(tmp_path / "in.las")
    out = tmp_path / f"out{suffix}"
    write_cloud(out, cloud, like=tmp_path / "in.las", provenance={"command": "test"})
    written = laspy.read(str(out))
    np.testing.assert_array_equal(written.header.offsets, OFFSET)
    np.testing.assert_array_equal(written.header.scales, [0.001] * 3)
    assert written.header.point_format.id == 3
    np.testing.assert_array_equal(
        np.c_[written.X, written.Y, written.Z], np.round((points - OFFSET) / 0.001)
    )
    np.testing.assert_array_equal(np.c_[written.red, written.green, written.blue], rgb)
    (vlr,) = [v for v in written.header.vlrs if (v.user_id, v.record_id) == LAS_RECORD]
    assert json.loads(vlr.record_data) == {"command": "test"}
    plain = tmp_path / f"plain{suffix}"
    write_cloud(plain, np.asarray(cloud.points))  # no template, no colours
    back = read_cloud(plain)
    assert np.abs(np.asarray(back.points) - points).max() < 1e-5 and not back.has_colors()


def test_e57_and_ply_go_back_out(tmp_path):
    """E57: one scan, survey coordinates kept to about 1e-7 of the cloud's extent
    (pye57 writes single precision about the centre the pose restores), 8-bit colours;
    PLY: the run recorded as a header comment that readers skip."""
    import json

    pytest.importorskip("pye57")
    from o3d_rpointhop.io import read_provenance, write_cloud

    rng = np.random.default_rng(2)
    points = OFFSET + rng.uniform(0, 20, (300, 3))
    colours = rng.random((300, 3))
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(points))
    cloud.colors = o3d.utility.Vector3dVector(colours)
    write_cloud(tmp_path / "c.e57", cloud)
    back = read_cloud(tmp_path / "c.e57")
    assert np.abs(np.asarray(back.points) - points).max() < 2e-5
    np.testing.assert_allclose(np.asarray(back.colors), np.round(colours * 255) / 255, atol=1e-9)
    write_cloud(tmp_path / "c.ply", cloud, provenance={"seed": 3})
    header = (tmp_path / "c.ply").read_bytes()[:300].decode("ascii", "replace").splitlines()
    assert header[:2] == ["ply", "format binary_little_endian 1.0"]
    assert json.loads(header[2].removeprefix("comment o3d-rpointhop ")) == {"seed": 3}
    np.testing.assert_array_equal(np.asarray(read_cloud(tmp_path / "c.ply").points), points)
    # A long record is split over comment lines Open3D's reader accepts (it aborts on a
    # header line over 1024 characters), and read back whole.
    long = {"config": {f"key{k}": "v" * 50 for k in range(100)}}
    write_cloud(tmp_path / "long.ply", cloud, provenance=long)
    lines = (tmp_path / "long.ply").read_bytes().split(b"end_header")[0].splitlines()
    assert max(len(line) for line in lines) < 300
    assert len(o3d.io.read_point_cloud(str(tmp_path / "long.ply")).points) == 300
    assert read_provenance(tmp_path / "long.ply") == long
    with pytest.raises(ValueError, match="cannot write format '.xyzq'"):
        write_cloud(tmp_path / "c.xyzq", cloud)


def test_reconstruct_writes_las_on_scan_0_s_grid(tmp_path):
    """A folder of LAS scans rebuilt into a LAS file: scan 0's offsets and scales, the
    scans' colours, the run in its VLR."""
    import json

    from helpers import partial_views

    from o3d_rpointhop.cli import main
    from o3d_rpointhop.io import LAS_RECORD, read_provenance

    scans, _ = partial_views(3, seed=1)
    for k, scan in enumerate(scans):
        rgb = np.tile(np.array([[60000, 20000 * k, 0]], dtype=np.uint16), (len(scan), 1))
        _las(tmp_path / f"s{k}.las", OFFSET + scan, rgb)
    out = tmp_path / "merged.laz"
    folder = tmp_path
    assert main(["reconstruct", str(folder / "s*.las"), "-o", str(out)]) == 0
    merged = laspy.read(str(out))
    np.testing.assert_array_equal(merged.header.offsets, OFFSET)
    assert len(merged.points) == sum(len(s) for s in scans)
    assert set(np.unique(merged.green).tolist()) == {0, 20000, 40000}
    (vlr,) = [v for v in merged.header.vlrs if (v.user_id, v.record_id) == LAS_RECORD]
    assert json.loads(vlr.record_data)["command"] == "reconstruct"
    assert read_provenance(out)["config"]["register"]["random_state"] == 0


def _las_with_attributes(path, points, seed, point_format=3):
    """A survey LAS file whose every point has its own intensity, return numbers,
    classification, GPS time, colour and an extra-bytes dimension."""
    rng = np.random.default_rng(seed)
    header = laspy.LasHeader(point_format=point_format, version="1.2")
    header.offsets, header.scales = OFFSET, np.array([0.001, 0.001, 0.001])
    header.add_extra_dim(laspy.ExtraBytesParams(name="reflectance", type=np.float32))
    las = laspy.LasData(header)
    las.x, las.y, las.z = points[:, 0], points[:, 1], points[:, 2]
    n = len(points)
    las.intensity = rng.integers(0, 65535, n, dtype=np.uint16)
    las.intensity[0] = 65534
    las.return_number = rng.integers(1, 4, n)
    las.number_of_returns = np.full(n, 3)
    las.classification = rng.choice([2, 5, 6], n)
    las.gps_time = 3e5 + np.cumsum(rng.random(n))
    las.red, las.green, las.blue = rng.integers(0, 65536, (3, n), dtype=np.uint16)
    las.reflectance = rng.random(n).astype(np.float32)
    las.write(str(path))
    return laspy.read(str(path))


_KEPT = ("intensity", "return_number", "number_of_returns", "classification", "gps_time")


def test_register_and_reconstruct_keep_every_las_dimension_of_every_point(tmp_path):
    """A LAS / LAZ output of scans read from LAS files keeps each point's intensity,
    returns, classification, GPS time, colour and extra bytes, with its new
    coordinates (before, they were written as 0)."""
    from helpers import partial_views

    from o3d_rpointhop.cli import main

    scans, _ = partial_views(3, seed=1)
    inputs = [
        _las_with_attributes(tmp_path / f"s{k}.las", OFFSET + scan, k)
        for k, scan in enumerate(scans)
    ]
    out = tmp_path / "aligned.laz"
    status = main(["register", str(tmp_path / "s1.las"), str(tmp_path / "s0.las"), "-o", str(out)])
    assert status in (0, 3)
    aligned = laspy.read(str(out))
    source = inputs[1]
    assert len(aligned.points) == len(source.points)
    for name in (*_KEPT, "red", "green", "blue", "reflectance"):
        np.testing.assert_array_equal(np.asarray(aligned[name]), np.asarray(source[name]), name)
    merged_path = tmp_path / "merged.laz"
    assert main(["reconstruct", str(tmp_path / "s*.las"), "-o", str(merged_path)]) == 0
    merged = laspy.read(str(merged_path))
    assert merged.header.point_format.id == 3
    assert list(merged.point_format.extra_dimension_names) == ["reflectance"]
    for name in (*_KEPT, "red", "blue", "reflectance"):
        joined = np.concatenate([np.asarray(las[name]) for las in inputs])
        np.testing.assert_array_equal(np.asarray(merged[name]), joined, name)
    assert merged.intensity.max() == 65534 and set(np.unique(merged.classification)) == {2, 5, 6}


def test_reconstruct_keeps_the_colours_of_the_scans_that_have_them(tmp_path):
    """One scan without colours among coloured ones: the others keep theirs (before,
    every colour was dropped), its points are grey, and a warning says which."""
    import warnings

    from helpers import partial_views

    from o3d_rpointhop import register_multiway
    from o3d_rpointhop.registration.result import UNCOLOURED

    scans, _ = partial_views(3, seed=1)
    clouds = []
    for k, scan in enumerate(scans):
        cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(scan))
        if k != 1:
            cloud.paint_uniform_color([0.1 * (k + 1), 0.2, 0.3])
        clouds.append(cloud)
    result = register_multiway(clouds, random_state=0)
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        merged = result.merge(clouds, voxel_size=None, colour=False)
    assert merged.has_colors() and any(
        "scans [1] have no colours" in str(w.message) for w in caught
    )
    colours = np.asarray(merged.colors)
    sizes = np.cumsum([0] + [len(s) for s in scans])
    np.testing.assert_allclose(colours[: sizes[1]], [[0.1, 0.2, 0.3]] * sizes[1])
    np.testing.assert_allclose(colours[sizes[1] : sizes[2]], [UNCOLOURED] * len(scans[1]))
    np.testing.assert_allclose(colours[sizes[2] :], [[0.3, 0.2, 0.3]] * len(scans[2]))


def test_a_mesh_is_built_at_survey_coordinates(tmp_path):
    """The merged scans are meshed about their centre (at UTM coordinates Qhull, in
    orienting the normals, failed) and the mesh is put back where the scans are."""
    from helpers import partial_views

    from o3d_rpointhop import register_multiway

    scans, _ = partial_views(3, seed=1)
    far = [scan + OFFSET for scan in scans]
    result = register_multiway(far, random_state=0)
    mesh = result.mesh(far, depth=6)
    vertices = np.asarray(mesh.vertices)
    assert len(mesh.triangles) > 100
    assert np.abs(vertices.mean(axis=0) - np.vstack(far).mean(axis=0)).max() < 1.0


def test_every_reader_of_float32_files_says_when_they_are_too_coarse(tmp_path):
    """A float32 PLY, a PCD (Open3D writes float32) and a single-precision E57 scan at
    UTM coordinates warn when read (pointing at the caller), a PCD warns when written
    there too; the same clouds in float64 (or our E57, stored about its centre) read
    silently."""
    import warnings

    from o3d_rpointhop.io import PrecisionWarning, write_cloud

    rng = np.random.default_rng(6)
    far = rng.uniform(-5, 5, (400, 3)) + [512_345.0, 4_123_456.0, 87.0]
    header = (
        "ply\nformat binary_little_endian 1.0\nelement vertex 400\n"
        "property float x\nproperty float y\nproperty float z\nend_header\n"
    )
    (tmp_path / "f32.ply").write_bytes(header.encode() + far.astype("<f4").tobytes())
    with pytest.warns(PrecisionWarning, match="f32.ply holds float32") as caught:
        read_cloud(tmp_path / "f32.ply")
    assert caught[0].filename == __file__
    cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(far))
    with pytest.warns(PrecisionWarning, match="c.pcd holds float32") as caught:
        write_cloud(tmp_path / "c.pcd", cloud)
    assert caught[0].filename == __file__
    with pytest.warns(PrecisionWarning, match="c.pcd holds float32"):
        read_cloud(tmp_path / "c.pcd")
    pye57 = pytest.importorskip("pye57")
    with pye57.E57(str(tmp_path / "raw.e57"), mode="w") as e57:
        e57.write_scan_raw({f"cartesian{a}": far[:, k] for k, a in enumerate("XYZ")})
    with pytest.warns(PrecisionWarning, match="raw.e57 holds float32") as caught:
        read_cloud(tmp_path / "raw.e57")
    assert caught[0].filename == __file__
    write_cloud(tmp_path / "ours.e57", cloud)
    write_cloud(tmp_path / "f64.ply", cloud)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        read_cloud(tmp_path / "ours.e57")
        read_cloud(tmp_path / "f64.ply")


def test_meshes_of_flat_triangles_and_of_vertex_colours(tmp_path):
    """A mesh whose triangles all have zero area is refused; vertex colours are carried
    to the samples, each a blend of its triangle's corners."""
    flat = o3d.geometry.TriangleMesh()
    flat.vertices = o3d.utility.Vector3dVector([[0, 0, 0], [1, 0, 0], [2, 0, 0.0]])
    flat.triangles = o3d.utility.Vector3iVector([[0, 1, 2]])
    assert o3d.io.write_triangle_mesh(str(tmp_path / "flat.obj"), flat)
    with pytest.raises(ValueError, match="every triangle of this mesh has zero area"):
        read_cloud(tmp_path / "flat.obj")
    box = o3d.geometry.TriangleMesh.create_box()
    red = np.tile([1.0, 0.0, 0.0], (len(box.vertices), 1))
    red[np.asarray(box.vertices)[:, 2] > 0.5] = [0.0, 0.0, 1.0]  # the top corners blue
    box.vertex_colors = o3d.utility.Vector3dVector(red)
    assert o3d.io.write_triangle_mesh(str(tmp_path / "box.off"), box)
    cloud = read_cloud(tmp_path / "box.off", mesh_points=4000)
    colours, z = np.asarray(cloud.colors), np.asarray(cloud.points)[:, 2]
    assert colours.shape == (4000, 3) and np.allclose(colours.sum(axis=1), 1.0, atol=1e-6)
    np.testing.assert_allclose(colours[np.isclose(z, 0.0), 0], 1.0, atol=1e-6)  # bottom: red
    np.testing.assert_allclose(colours[np.isclose(z, 1.0), 2], 1.0, atol=1e-6)  # top: blue
    side = ~np.isclose(z, 0.0) & ~np.isclose(z, 1.0)
    np.testing.assert_allclose(colours[side, 2], z[side], atol=1e-6)  # blended by height


def test_odd_files_get_one_clear_line(tmp_path):
    """PLY headers that say something unreadable, a path that is not a regular file,
    and .npz archives: several arrays without one named 'points' are refused, a single
    array is read whatever its name."""
    vertex = b"element vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
    headers = {
        "word.ply": (b"ply\nformat ascii 1.0\nbogus line\nend_header\n", "bad header line"),
        "format.ply": (
            b"ply\nformat weird 1.0\n" + vertex + b"end_header\n0 0 0\n",
            "unknown PLY format 'weird'",
        ),
        "faces.ply": (
            b"ply\nformat ascii 1.0\nelement face 0\n"
            b"property list uchar int vertex_indices\nend_header\n",
            "it has no vertex element",
        ),
    }
    for name, (data, message) in headers.items():
        (tmp_path / name).write_bytes(data)
        with pytest.raises(ValueError, match=f"{name}: damaged or unreadable .ply file.*{message}"):
            read_cloud(tmp_path / name)
    with pytest.raises(ValueError, match="not a regular file"):
        read_cloud("/dev/null")
    points = make_object(50, shape_seed=2)
    np.savez(tmp_path / "two.npz", a=points, b=points)
    with pytest.raises(ValueError, match=r"has arrays \['a', 'b'\] but none named 'points'"):
        read_cloud(tmp_path / "two.npz")
    np.savez(tmp_path / "one.npz", points)
    np.testing.assert_allclose(np.asarray(read_cloud(tmp_path / "one.npz").points), points)
