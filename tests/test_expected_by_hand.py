"""Behaviours checked against values worked out by hand, not against the code's own
output: pose files (good and broken), mesh normals, azimuth and octant bins, the
ambiguity flag of ``evaluate()``, and readers on files that differ."""

import numpy as np
import open3d as o3d
import pytest

from o3d_rpointhop.descriptors.pointhop._octants import bin_index
from o3d_rpointhop.io import read_cloud
from o3d_rpointhop.poses import read_poses, write_poses
from o3d_rpointhop.registration import evaluate

# A turn of 90 degrees about z, then a move by (1, 2, 3).
TURN = np.array([[0.0, -1, 0, 1], [1, 0, 0, 2], [0, 0, 1, 3], [0, 0, 0, 1]])


def _log(path, header, rows):
    path.write_text(header + "\n" + "\n".join(" ".join(str(v) for v in r) for r in rows) + "\n")
    return path


def test_a_log_record_written_by_hand_reads_exactly(tmp_path):
    path = _log(tmp_path / "good.log", "4 9 12", TURN.tolist())
    assert list(read_poses(path, "3dmatch")) == [(4, 9)]
    np.testing.assert_array_equal(read_poses(path, "3dmatch")[(4, 9)], TURN)


@pytest.mark.parametrize(
    "change",
    [
        lambda m: m.__setitem__((3, 3), 2.0),  # the bottom row is not 0 0 0 1
        lambda m: m.__setitem__((3, 0), 0.5),
        lambda m: m.__setitem__(slice(0, 3), m[:3] * [[1.01], [1.01], [1.01]]),  # scaled
        lambda m: m.__setitem__((0, 1), -0.9),  # not orthonormal
        lambda m: m.__setitem__((2, 2), -1.0),  # a reflection (det -1)
    ],
)
def test_a_log_record_that_is_not_rigid_is_refused(tmp_path, change):
    matrix = TURN.copy()
    change(matrix)
    path = _log(tmp_path / "bad.log", "0 1 2", matrix.tolist())
    with pytest.raises(ValueError, match="not a rigid transformation"):
        read_poses(path, "3dmatch")


def test_a_kitti_line_by_hand_and_a_broken_one(tmp_path):
    path = tmp_path / "good.txt"
    path.write_text("0 -1 0 1 1 0 0 2 0 0 1 3\n")
    np.testing.assert_array_equal(read_poses(path)[0], TURN)
    path.write_text("0 -1 0 1 1 0 0 2 0 0 1.01 3\n")  # a stretched z axis
    with pytest.raises(ValueError, match="pose 0: not a rigid"):
        read_poses(path)


def test_log_pair_ids_and_fragment_count_are_written_as_given(tmp_path):
    path = tmp_path / "out.log"
    write_poses(path, [TURN, np.eye(4)], "3dmatch", pairs=[(3, 7), (1, 2)], n_fragments=10)
    lines = path.read_text().splitlines()
    assert lines[0].split() == ["3", "7", "10"] and lines[5].split() == ["1", "2", "10"]
    assert [float(v) for v in lines[1].split()] == [0, -1, 0, 1]
    write_poses(path, [TURN, TURN], "3dmatch")  # default: scan k into scan 0
    headers = [ln.split() for ln in path.read_text().splitlines()[::5]]
    assert headers == [["0", "0", "2"], ["0", "1", "2"]]


def test_mesh_samples_carry_their_triangles_unit_normals(tmp_path):
    # A 2 x 2 square in z = 0 (counter-clockwise seen from +z) and a small triangle in
    # the plane x = 5 (counter-clockwise seen from +x): normals +z and +x.
    mesh = o3d.geometry.TriangleMesh()
    mesh.vertices = o3d.utility.Vector3dVector(
        [[0, 0, 0], [2, 0, 0], [2, 2, 0], [0, 2, 0], [5, 0, 0], [5, 1, 0], [5, 0, 1]]
    )
    mesh.triangles = o3d.utility.Vector3iVector([[0, 1, 2], [0, 2, 3], [4, 5, 6]])
    path = tmp_path / "mesh.obj"
    o3d.io.write_triangle_mesh(str(path), mesh)
    cloud = read_cloud(path, mesh_points=3000)
    points, normals = np.asarray(cloud.points), np.asarray(cloud.normals)
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1.0, atol=1e-12)
    on_square = points[:, 2] < 1e-12
    np.testing.assert_allclose(normals[on_square], [[0, 0, 1]] * on_square.sum(), atol=1e-12)
    np.testing.assert_allclose(normals[~on_square], [[1, 0, 0]] * (~on_square).sum(), atol=1e-12)
    np.testing.assert_allclose(points[~on_square, 0], 5.0)
    # By area: the square holds 4 / 4.5 of the samples (binomial, about 17 sd margin).
    assert abs(on_square.mean() - 4 / 4.5) < 0.1


def test_azimuth_bins_of_hand_placed_neighbours():
    # The farthest neighbour is at distance 2, so the shells' squared outer radii are
    # 1, 2, 3 and 4; bit 2 is "above the tangent plane" (z >= 0).
    local = np.array(
        [
            [0.5, 0, 0.1],  # squared distance 0.26: shell 0, above -> 4
            [0, 0.9, -0.3],  # 0.90: shell 0, below -> 0
            [1.2, 0, 0],  # 1.44: shell 1, on the plane counts as above -> 5
            [0, -1.3, -0.2],  # 1.73: shell 1, below -> 1
            [1.5, 0, 0],  # 2.25: shell 2 -> 6
            [0, 0, -1.5],  # 2.25: shell 2, below -> 2
            [2, 0, 0],  # 4.00: shell 3 -> 7
            [0, -1.8, -0.2],  # 3.28: shell 3, below -> 3
        ]
    ).T[:, None, :]
    np.testing.assert_array_equal(bin_index(local, "azimuth")[0], [4, 0, 5, 1, 6, 2, 7, 3])
    flipped = local.copy()
    flipped[2] *= -1  # the height's sign decides the upper bit
    np.testing.assert_array_equal(bin_index(flipped, "azimuth")[0], [0, 4, 5, 5, 6, 6, 7, 7])


def test_octant_bins_of_hand_placed_neighbours():
    local = np.array([[1, -1, 1], [-1, 1, -1], [1, 1, 1], [-1, -1, -1], [0, -1, 0]]).T[:, None]
    # bit 2: x >= 0, bit 1: y >= 0, bit 0: z >= 0 (zero counts as positive)
    np.testing.assert_array_equal(bin_index(local.astype(float), "octants")[0], [5, 2, 7, 0, 5])


def _box(sides, n=4000, seed=0):
    rng = np.random.default_rng(seed)
    pts = rng.uniform(-0.5, 0.5, (n, 3)) * sides
    face = rng.integers(0, 3, n)
    pts[np.arange(n), face] = np.sign(rng.standard_normal(n)) * sides[face] / 2
    return pts


def test_a_pair_whose_half_turn_fits_as_well_is_ambiguous():
    # A box with three different sides: a half turn about any axis maps it onto itself.
    box = _box(np.array([2.0, 1.0, 0.6]))
    assert evaluate(box, box.copy(), np.eye(4)).ambiguous
    # The same box with a cube standing on its top face, off every axis: a half turn
    # leaves the cube's surface (about a fifth of the area) without a partner.
    bump = _box(np.array([0.6, 0.6, 0.6]), 2000, seed=1) + [0.6, 0.2, 0.6]
    shape = np.vstack([box, bump])
    result = evaluate(shape, shape.copy(), np.eye(4))
    assert result.fitness > 0.99 and not result.ambiguous


def test_readers_return_each_files_own_points(tmp_path):
    rng = np.random.default_rng(3)
    first, second = rng.normal(size=(500, 3)), rng.normal(size=(700, 3)) + 10
    for k, pts in enumerate((first, second)):
        cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(pts))
        o3d.io.write_point_cloud(str(tmp_path / f"{k}.ply"), cloud)
        np.save(tmp_path / f"{k}.npy", pts)
    for suffix in ("ply", "npy"):
        got = [np.asarray(read_cloud(tmp_path / f"{k}.{suffix}").points) for k in (0, 1)]
        np.testing.assert_allclose(got[0], first)
        np.testing.assert_allclose(got[1], second)
