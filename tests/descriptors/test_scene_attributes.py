"""The scene variant: normals and eigenvalue features pooled with the coordinates."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import SMALL, random_motion, relative_difference
from hypothesis import given, settings
from hypothesis import strategies as st

from o3d_rpointhop import RPointHopTransformer
from o3d_rpointhop.datasets import make_object, make_room

SCENE = ("xyz", "normal", "eigen")


def _room(n: int = 3000, seed: int = 0) -> np.ndarray:
    """A corner of a room, every piece exactly planar (the worst case for eigen
    features and normals)."""
    return make_room(n, random_state=seed)


def _assert_moves_with_the_cloud(model, cloud, seed: int, bound: float) -> None:
    """Finite descriptors, within ``bound`` (relative) after a seeded rigid motion and
    equal to 1e-5 after a seeded permutation of the points."""
    rot, shift = random_motion(seed, 100.0)
    perm = np.random.default_rng(seed).permutation(len(cloud))
    base = model.transform(cloud)
    assert np.isfinite(base).all()
    assert relative_difference(model.transform(cloud @ rot.T + shift), base) < bound
    np.testing.assert_allclose(model.transform(cloud[perm]), base[perm], rtol=0, atol=1e-5)


@pytest.fixture(scope="module")
def scene_model():
    clouds = [make_object(1200, shape_seed=s) for s in range(4)] + [_room(1600, 1)]
    return RPointHopTransformer(attributes=SCENE, random_state=0, **SMALL).fit(clouds)


def test_scene_model_layout(scene_model):
    assert scene_model.kernels_[0].shape == (1, 104, 104)  # 8 octants x (3 + 3 + 7)
    xyz = RPointHopTransformer(random_state=0, **SMALL).fit(make_object(1200))
    assert xyz.kernels_[0].shape == (1, 24, 24)


@settings(max_examples=8, deadline=None)
@given(st.integers(0, 10_000))
def test_scene_attributes_are_rigid_invariant_and_permutation_equivariant(scene_model, seed):
    cloud = _room(2000, seed) if seed % 2 else make_object(1500, shape_seed=seed % 40)
    _assert_moves_with_the_cloud(scene_model, cloud, seed, 1e-4)


def test_planes_edges_and_duplicates_stay_finite(scene_model):
    room = _room(2400, 3)
    wall = room[np.abs(room[:, 0]) < 1e-12]  # one wall alone: every point coplanar
    doubled = np.vstack([room, room])  # every point twice
    for cloud in (room, wall, doubled):
        out = scene_model.transform(cloud)
        assert out.shape[0] == len(cloud) and np.isfinite(out).all()


def test_wide_lrf_and_round_trip(tmp_path):
    clouds = [_room(3000, s) for s in range(2)]
    model = RPointHopTransformer(
        attributes=SCENE,
        lrf_neighbors=256,
        n_neighbors=(32, 32),
        hop_sizes=(1.0, 0.5),
        random_state=0,
    ).fit(clouds)
    model.training_scenes_ = ["room-a", "room-b"]
    model.save(tmp_path / "scene.npz")
    loaded = RPointHopTransformer.load(tmp_path / "scene.npz")
    assert loaded.attributes == SCENE and loaded.lrf_neighbors == 256
    assert loaded.training_scenes_ == ["room-a", "room-b"]
    cloud = _room(2500, 9)
    np.testing.assert_array_equal(loaded.transform(cloud), model.transform(cloud))
    with pytest.raises(ValueError, match="too few"):
        model.transform(cloud[:200])  # fewer points than the 256-point frames need


def test_shipped_scene_model():
    from importlib.resources import files

    path = files("o3d_rpointhop") / "data" / "rpointhop_scene.npz"
    assert path.stat().st_size < 2 * 1024**2
    model = RPointHopTransformer.pretrained("scene")
    assert model.attributes == SCENE
    assert len(model.training_scenes_) == 4 and all("-" in s for s in model.training_scenes_)
    # Scene folder names of 3DMatch test scenes; the other four are kept for held-out use.
    assert "7-scenes-redkitchen" in model.training_scenes_
    room = _room(3000, 5)
    out = model.transform(room)
    assert out.shape == (3000, 96) and np.isfinite(out).all()
    rot, shift = random_motion(5, 10.0)
    assert relative_difference(model.transform(room @ rot.T + shift), out) < 1e-4
    with pytest.raises(ValueError, match="unknown pretrained model 'kitchen'"):
        RPointHopTransformer.pretrained("kitchen")


def test_shipped_scene_model_with_fpfh_registers_a_room():
    from o3d_rpointhop import register

    model = RPointHopTransformer.pretrained("scene-fpfh")
    assert model.attributes == (*SCENE, "fpfh") and model.n_features_out_ == 96
    assert model.training_scenes_ == RPointHopTransformer.pretrained("scene").training_scenes_
    room = _room(4000, 6)
    rot, shift = random_motion(6, 0.5)
    moved = room @ rot.T + shift
    result = register(room, moved, model)
    expected = np.eye(4)
    expected[:3, :3], expected[:3, 3] = rot, shift
    np.testing.assert_allclose(result.transformation, expected, atol=1e-3)


def test_fpfh_attribute_is_rigid_invariant_and_permutation_equivariant():
    clouds = [make_object(1200, shape_seed=s) for s in range(3)] + [_room(1600, 1)]
    model = RPointHopTransformer(attributes=(*SCENE, "fpfh"), random_state=0, **SMALL).fit(clouds)
    assert model.kernels_[0].shape == (1, 368, 368)  # 8 octants x (3 + 3 + 7 + 33)
    for seed, cloud in enumerate([_room(2000, 5), make_object(1500, shape_seed=7)]):
        _assert_moves_with_the_cloud(model, cloud, seed, 1e-5)


def test_fpfh_attribute_on_a_sampled_first_hop():
    # A first hop on half the points: every point still needs its own histogram.
    params = dict(n_neighbors=(16, 16), hop_sizes=(0.5, 0.25), lrf_neighbors=32)
    model = RPointHopTransformer(attributes=("xyz", "fpfh"), random_state=0, **params)
    out = model.fit([_room(1600, s) for s in range(2)]).transform(_room(1500, 9))
    assert out.shape == (1500, model.n_features_out_) and np.isfinite(out).all()
