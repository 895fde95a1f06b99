"""Scene models for register(): the global cloud size a model states, and the
leave-one-scene-out models of the 3DMatch benchmark (on a synthetic scene folder)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from o3d_rpointhop import (
    PointToPlaneICP,
    RegistrationPipeline,
    RPointHopTransformer,
    register,
)
from o3d_rpointhop.datasets import make_object
from o3d_rpointhop.evaluation._common import check_methods
from o3d_rpointhop.evaluation.methods import DEFAULT_METHODS, METHODS
from o3d_rpointhop.evaluation.scene_models import (
    REGISTRATION_POINTS,
    leave_one_scene_out,
    scene_names,
)
from o3d_rpointhop.io import write_cloud
from o3d_rpointhop.registration.context import RegistrationContext
from o3d_rpointhop.registration.defaults import DEFAULT_GLOBAL_POINTS, resolve_global_points

SMALL = dict(n_neighbors=(16, 16), hop_sizes=(1.0, 0.5), lrf_neighbors=32)


class _Stated:
    """A stand-in descriptor that states its global cloud size."""

    registration_points_ = 1000

    def transform(self, cloud):  # pragma: no cover - never called here
        raise AssertionError


def test_resolve_global_points():
    assert resolve_global_points(512) == 512
    assert resolve_global_points("auto") == DEFAULT_GLOBAL_POINTS == 2048
    assert resolve_global_points("auto", _Stated()) == 1000
    assert resolve_global_points(4096, _Stated()) == 4096  # the call wins
    cloud = make_object(200)
    for bad in (2, 0, 1.5, True, "many"):  # refused by the public entry points
        with pytest.raises(ValueError, match="n_global_points"):
            register(cloud, cloud, n_global_points=bad)
        with pytest.raises(ValueError, match="n_global_points"):
            RegistrationPipeline([("icp", PointToPlaneICP())], n_global_points=bad).register(
                cloud, cloud
            )


def test_the_global_step_takes_the_descriptors_size():
    cloud = make_object(8000, shape_seed=3)
    stated = RegistrationContext(cloud, cloud, descriptor=_Stated())
    plain = RegistrationContext(cloud, cloud)
    assert stated.n_global_points == 1000 and plain.n_global_points == 2048
    kept = len(stated.global_cloud("source").points)
    assert 700 < kept <= 1.15 * 1000
    assert stated.voxel_size > plain.voxel_size  # fewer points: a coarser resolution


def test_registration_points_round_trip_and_validation(fitted, tmp_path):
    model = RPointHopTransformer(**fitted.get_params())
    model.__dict__.update(fitted.__dict__)
    model.registration_points_ = 3000
    path = tmp_path / "m.npz"
    model.save(path)
    assert RPointHopTransformer.load(path).registration_points_ == 3000
    fitted.save(tmp_path / "plain.npz")
    assert not hasattr(RPointHopTransformer.load(tmp_path / "plain.npz"), "registration_points_")
    with np.load(path, allow_pickle=False) as archive:
        arrays = {k: archive[k] for k in archive.files}
    meta = json.loads(str(arrays["metadata"]))
    arrays["metadata"] = np.array(json.dumps({**meta, "registration_points": "many"}))
    np.savez(tmp_path / "bad.npz", **arrays)
    with pytest.raises(ValueError, match="registration_points"):
        RPointHopTransformer.load(tmp_path / "bad.npz")


def test_shipped_scene_model_comes_as_measured():
    scene = RPointHopTransformer.pretrained("scene")
    assert scene.registration_points_ == REGISTRATION_POINTS
    assert scene.n_features_out_ == 128  # the axes every scene result was measured with
    assert RPointHopTransformer.pretrained("scene", n_components=None).n_features_out_ == 880
    objects = RPointHopTransformer.pretrained()
    assert objects.n_features_out_ == 1624 and not hasattr(objects, "registration_points_")


@pytest.fixture
def scene_folder(tmp_path):
    """A 3DMatch-like folder: three scenes of two fragments each."""
    for k, scene in enumerate(("scene-a", "scene-b", "scene-c")):
        folder = tmp_path / "3dmatch" / "fragments" / scene
        folder.mkdir(parents=True)
        for j in range(2):
            write_cloud(folder / f"cloud_bin_{j}.ply", make_object(2500, shape_seed=10 * k + j))
    return tmp_path


def test_leave_one_scene_out_never_sees_its_scene(scene_folder):
    assert scene_names(scene_folder) == ["scene-a", "scene-b", "scene-c"]
    seen = []
    models = leave_one_scene_out(["scene-a", "scene-c"], scene_folder, seen.append, **SMALL)
    assert seen == ["scene-a", "scene-c"] and set(models) == {"scene-a", "scene-c"}
    assert models["scene-a"].training_scenes_ == ["scene-b", "scene-c"]
    assert models["scene-c"].training_scenes_ == ["scene-a", "scene-b"]
    for model in models.values():
        assert model.n_training_clouds_ == 4
        assert model.registration_points_ == REGISTRATION_POINTS
        assert model.attributes == ("xyz", "normal", "eigen")
    cloud = make_object(1500, shape_seed=99)
    a, c = (models[s].transform(cloud) for s in ("scene-a", "scene-c"))
    assert np.isfinite(a).all() and not np.allclose(a, c)  # different training data
    again = leave_one_scene_out(["scene-a"], scene_folder, **SMALL)["scene-a"]
    np.testing.assert_array_equal(again.transform(cloud), a)  # deterministic
    with pytest.raises(FileNotFoundError, match="fragments"):
        scene_names(scene_folder / "nowhere")


def test_scene_only_methods_are_refused_on_objects():
    assert METHODS["rpointhop-loso"].scenes_only
    assert not {"rpointhop-loso", "rpointhop-scene"} & set(DEFAULT_METHODS["objects"])
    assert {"rpointhop-scene", "rpointhop-loso", "fpfh-ransac-icp-5cm"} <= set(
        DEFAULT_METHODS["3dmatch"]
    )
    with pytest.raises(ValueError, match="need the 3DMatch scenes"):
        check_methods(["icp", "rpointhop-loso"])
    assert check_methods(["rpointhop-loso"], scenes=True) == ["rpointhop-loso"]
