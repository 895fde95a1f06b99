"""Viewpoints (frames and normals that face the sensor) and azimuth pooling (bins that use
the frame's normal axis only): exact invariance when the viewpoint moves with the cloud,
nothing depending on the in-plane axes, clear errors."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import random_motion, relative_difference
from scipy.spatial.transform import Rotation

from o3d_rpointhop import FPFHTransformer, RPointHopTransformer
from o3d_rpointhop.datasets import make_blob, make_object, make_room
from o3d_rpointhop.descriptors.pointhop._frames import local_reference_frames
from o3d_rpointhop.descriptors.pointhop._geometry import _normal_means
from o3d_rpointhop.descriptors.pointhop._octants import bin_index, cylindrical_of


@pytest.fixture(scope="module")
def azimuth_model() -> RPointHopTransformer:
    clouds = [make_object(500, shape_seed=s) for s in range(5)]
    return RPointHopTransformer(
        pooling="azimuth", attributes=("xyz", "normal", "eigen"), random_state=0
    ).fit(clouds, viewpoints=[[0.0, 0.0, 3.0]] * 5)


def _scan(n=900, seed=3):
    """A scan-like cloud: a room's points in front of a sensor at the origin."""
    return make_room(n, random_state=seed) + [1.0, 1.3, 2.5]


# ----------------------------------------------------------------------------- frames
def test_the_normal_axis_faces_the_sensor_and_the_moment_rule_decides_without_one():
    rng = np.random.default_rng(3)
    patch = np.c_[rng.uniform(-1, 1, (60, 2)), 0.01 * rng.exponential(size=60)]
    offsets = (patch[1:] - patch[0]).T[:, None, :]
    towards = np.array([[0.0], [0.0], [-5.0]])  # the centroid below: the fallback's way
    free, _ = local_reference_frames(offsets, 60, towards)
    for side in (1.0, -1.0):
        sensor = np.array([[0.3], [0.2], [side * 4.0]])
        frames, _ = local_reference_frames(offsets, 60, towards, sensor=sensor)
        assert np.sign(frames[0, 2, 2]) == side  # whatever the skew says
        np.testing.assert_allclose(np.linalg.det(frames), 1.0)
        # only the normal's sign may change: the first axis keeps the moment rule
        np.testing.assert_allclose(frames[0, :, 0], free[0, :, 0])
    # A sensor in the tangent plane of an exactly flat patch says nothing: the rule
    # without a sensor decides (there, the reference point's side).
    flat = offsets.copy()
    flat[2] = 0.0
    edge_on, _ = local_reference_frames(flat, 60, towards, sensor=np.array([[4.0], [0], [0]]))
    np.testing.assert_allclose(edge_on, local_reference_frames(flat, 60, towards)[0])
    assert edge_on[0, 2, 2] < 0  # towards the reference point, below


def test_viewpoints_reach_the_frames_of_the_transformer(fitted):
    scan = _scan()
    free = fitted.local_frames(scan)
    seen = fitted.local_frames(scan, viewpoints="origin")
    facing = np.einsum("nd,nd->n", seen[:, :, 2], -scan)  # normal . (sensor - point)
    assert (facing >= 0).all()
    assert (np.einsum("nd,nd->n", free[:, :, 2], -scan) < 0).any()  # the rule alone differs
    assert fitted.local_frames([scan, scan[:400]], viewpoints="origin")[1].shape == (400, 3, 3)


@pytest.mark.parametrize("seed", [0, 1])
def test_descriptors_are_invariant_when_the_viewpoint_moves_with_the_cloud(
    fitted, azimuth_model, seed
):
    scan = _scan(seed=seed)
    rot, shift = random_motion(seed, 20.0)
    moved = scan @ rot.T + shift
    for model in (fitted, azimuth_model):
        base = model.transform(scan, viewpoints="origin")
        again = model.transform(moved, viewpoints=shift)  # the sensor, moved
        assert relative_difference(base, again) < 1e-5
        # a sensor left behind is another viewpoint: the descriptors change
        assert relative_difference(base, model.transform(moved, viewpoints="origin")) > 1e-3
    frames = fitted.local_frames(scan, viewpoints="origin")
    np.testing.assert_allclose(
        fitted.local_frames(moved, viewpoints=shift), rot @ frames, atol=1e-8
    )


def test_permutation_equivariance_with_viewpoints_and_azimuth_pooling(azimuth_model):
    scan = _scan(seed=5)
    perm = np.random.default_rng(0).permutation(len(scan))
    base = azimuth_model.transform(scan, viewpoints="origin")
    shuffled = azimuth_model.transform(scan[perm], viewpoints="origin")
    assert relative_difference(base[perm], shuffled) < 1e-6


def test_fpfh_normals_face_the_viewpoint():
    """FPFH's histograms are invariant up to pairs on a bin's edge once its normals are:
    with the viewpoint moved along, they agree closely; left behind, they do not. (Radii
    wide enough that every point has a normal: with fewer than three neighbours Open3D
    gives a fixed one, which no viewpoint can turn.)"""
    scan = make_object(900, shape_seed=3) + [0.0, 0.0, 3.0]
    fpfh = FPFHTransformer(radius=0.4, normal_radius=0.2)
    rot, shift = random_motion(2, 5.0)
    seen = fpfh.transform(scan, viewpoints="origin")
    moved = scan @ rot.T + shift
    assert np.abs(seen - fpfh.transform(moved, viewpoints=shift)).mean() < 0.05
    assert np.abs(seen - fpfh.transform(moved, viewpoints="origin")).mean() > 1.0
    assert np.abs(seen - fpfh.transform(moved)).mean() > 1.0


@pytest.mark.parametrize(
    "views, n_clouds, message",
    [
        ("camera", 1, "viewpoints must be None, 'origin' or positions"),
        ([1.0, 2.0], 1, r"one per cloud \(1, 3\)"),
        ([[0.0, 0.0, np.nan]], 1, "NaN or infinite"),
        ([[0.0, 0.0, 0.0]] * 3, 2, r"one per cloud \(2, 3\)"),
    ],
)
def test_bad_viewpoints_raise_a_clear_error(fitted, views, n_clouds, message):
    clouds = [make_blob(300, shape_seed=s) for s in range(n_clouds)]
    with pytest.raises(ValueError, match=message):
        fitted.transform(clouds if n_clouds > 1 else clouds[0], viewpoints=views)
    with pytest.raises(ValueError, match=message):
        FPFHTransformer().transform(clouds if n_clouds > 1 else clouds[0], viewpoints=views)


# ----------------------------------------------------------------------------- azimuth
def _turned_about_z(local: np.ndarray, angles: np.ndarray) -> np.ndarray:
    """Neighbours ``(3, q, k)`` with each query's frame turned about its normal axis."""
    c, s = np.cos(angles)[:, None], np.sin(angles)[:, None]
    return np.stack([c * local[0] - s * local[1], s * local[0] + c * local[1], local[2]])


def _cylindrical(local: np.ndarray) -> np.ndarray:
    out = np.empty_like(local)
    for i in range(local.shape[1]):
        block = np.ascontiguousarray(local[:, i])
        cylindrical_of(block, block.shape[1], out[:, i])
    return out


def test_azimuth_bins_and_coordinates_ignore_any_turn_about_the_normal():
    rng = np.random.default_rng(0)
    local = rng.normal(size=(3, 50, 40))
    angles = rng.uniform(0, 2 * np.pi, 50)
    turned = _turned_about_z(local, angles)
    np.testing.assert_array_equal(bin_index(turned, "azimuth"), bin_index(local, "azimuth"))
    np.testing.assert_allclose(_cylindrical(turned), _cylindrical(local), atol=1e-12)
    assert not np.array_equal(bin_index(turned, "octants"), bin_index(local, "octants"))
    bins = bin_index(local, "azimuth")
    assert bins.min() >= 0 and bins.max() <= 7
    # Four shells of equal area: about a quarter of points spread evenly over a disc.
    disc = np.sqrt(rng.uniform(size=(1, 4000))) * np.exp(2j * np.pi * rng.uniform(size=(1, 4000)))
    flat = np.stack([disc.real, disc.imag, np.zeros_like(disc.real)])
    shares = np.bincount(bin_index(flat, "azimuth").ravel() % 4, minlength=4) / 4000
    np.testing.assert_allclose(shares, 0.25, atol=0.03)


def _normals(points, queries, nb, frames, azimuth):
    bins = np.zeros(nb.shape, np.uint8)
    bins[:, ::2] = 5  # two bins: octant 0 the odd neighbours, 5 the even
    out = np.empty((len(queries), 24))
    _normal_means(0, len(queries), points, queries, nb, bins, frames, azimuth, out)
    return out.reshape(len(queries), 8, 3)[:, [0, 5]]  # (q, 2 bins, 3 components)


def test_neighbour_normals_in_the_query_frame_by_hand():
    """Octant means of the neighbours' normals (their frames' third axes) in the
    query's frame; about the normal, as radial, tangential and normal components."""
    points = np.array([[0.0, 0.0, 0.0], [2.0, 0.0, 0.5], [0.0, 3.0, 0.0]])
    frames = np.tile(np.eye(3), (3, 1, 1))
    frames[1] = Rotation.from_rotvec([0.0, np.pi / 2, 0.0]).as_matrix()  # normal along +x
    frames[2] = Rotation.from_rotvec([np.pi / 2, 0.0, 0.0]).as_matrix()  # normal along -y
    nb = np.array([[2, 1]], dtype=np.int32)  # even: point 2, odd: point 1
    plain = _normals(points, np.array([0]), nb, frames, False)
    np.testing.assert_allclose(plain[0, 1], frames[2][:, 2], atol=1e-12)  # bin 5: point 2
    np.testing.assert_allclose(plain[0, 0], frames[1][:, 2], atol=1e-12)
    about = _normals(points, np.array([0]), nb, frames, True)
    # Point 2 lies along +y from the query's axis: its normal (0, -1, 0) is radial -1.
    np.testing.assert_allclose(about[0, 1], [-1.0, 0.0, 0.0], atol=1e-12)
    # Point 1 lies along +x: its normal (1, 0, 0) is radial +1.
    np.testing.assert_allclose(about[0, 0], [1.0, 0.0, 0.0], atol=1e-12)


def test_neighbour_normals_about_the_normal_ignore_a_turn_of_the_frame():
    rng = np.random.default_rng(1)
    points = rng.normal(size=(30, 3))
    frames = Rotation.random(30, random_state=2).as_matrix()
    queries = np.arange(5)
    nb = rng.integers(5, 30, size=(5, 8)).astype(np.int32)
    base = _normals(points, queries, nb, frames, True)
    spun = frames.copy()
    turn = Rotation.from_rotvec(np.c_[np.zeros((5, 2)), rng.uniform(0, 6, 5)]).as_matrix()
    spun[queries] = frames[queries] @ turn  # each query's frame turned about its own axis 2
    spun[5:] = frames[5:]
    np.testing.assert_allclose(_normals(points, queries, nb, spun, True), base, atol=1e-12)
    assert not np.allclose(
        _normals(points, queries, nb, spun, False), _normals(points, queries, nb, frames, False)
    )


def test_azimuth_model_is_rigid_invariant_saved_and_reloaded(azimuth_model, tmp_path):
    obj = make_object(700, shape_seed=40)
    rot, shift = random_motion(4, 3.0)
    base = azimuth_model.transform(obj)
    assert relative_difference(base, azimuth_model.transform(obj @ rot.T + shift)) < 1e-5
    assert azimuth_model.kernels_[0].shape == (1, 104, 104)
    path = tmp_path / "azimuth.npz"
    azimuth_model.save(path)
    loaded = RPointHopTransformer.load(path)
    assert loaded.pooling == "azimuth"
    np.testing.assert_array_equal(loaded.transform(obj), base)


def test_pooling_is_checked(train_clouds):
    with pytest.raises(ValueError, match="'pooling' parameter"):
        RPointHopTransformer(pooling="spiral").fit(train_clouds)
