"""The shipped models and what a model states for registration (registration_points_,
registration_global_method_)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from o3d_rpointhop import (
    RPointHopTransformer,
)
from o3d_rpointhop.datasets import make_object
from o3d_rpointhop.evaluation.scene_models import (
    REGISTRATION_GLOBAL_METHOD,
    REGISTRATION_POINTS,
)


def test_registration_points_round_trip_and_validation(fitted, tmp_path):
    model = RPointHopTransformer(**fitted.get_params())
    model.__dict__.update(fitted.__dict__)
    model.registration_points_ = 3000
    model.registration_global_method_ = "fgr"
    path = tmp_path / "m.npz"
    model.save(path)
    loaded = RPointHopTransformer.load(path)
    assert loaded.registration_points_ == 3000 and loaded.registration_global_method_ == "fgr"
    fitted.save(tmp_path / "plain.npz")
    plain = RPointHopTransformer.load(tmp_path / "plain.npz")
    assert not hasattr(plain, "registration_points_")
    assert not hasattr(plain, "registration_global_method_")
    with np.load(path, allow_pickle=False) as archive:
        arrays = {k: archive[k] for k in archive.files}
    meta = json.loads(str(arrays["metadata"]))
    arrays["metadata"] = np.array(json.dumps({**meta, "registration_points": "many"}))
    np.savez(tmp_path / "bad.npz", **arrays)
    with pytest.raises(ValueError, match="registration_points"):
        RPointHopTransformer.load(tmp_path / "bad.npz")
    arrays["metadata"] = np.array(json.dumps({**meta, "registration_global_method": 3}))
    np.savez(tmp_path / "bad.npz", **arrays)
    with pytest.raises(ValueError, match="registration_global_method"):
        RPointHopTransformer.load(tmp_path / "bad.npz")


def test_shipped_scene_model_comes_as_measured():
    scene = RPointHopTransformer.pretrained("scene")
    assert scene.registration_points_ == REGISTRATION_POINTS
    assert scene.registration_global_method_ == REGISTRATION_GLOBAL_METHOD == "consensus"
    assert scene.n_features_out_ == 96  # the axes every scene result was measured with
    assert scene.n_neighbors == (96,) and scene.hop_sizes == (1.0,)  # one hop
    assert RPointHopTransformer.pretrained("scene", n_components=None).n_features_out_ == 104
    objects = RPointHopTransformer.pretrained()
    assert objects.n_features_out_ == 1624 and not hasattr(objects, "registration_points_")
    assert not hasattr(objects, "registration_global_method_")


def test_shipped_object_model_comes_as_chosen():
    """The one-hop object model of benchmarks/object_model_selection.py: 96 neighbours,
    frames of 96 points, 24-D, no principal axes and no registration hints (register()'s
    own defaults were chosen for it)."""
    from o3d_rpointhop.registration.defaults import DEFAULT_MODEL, default_descriptor

    model = RPointHopTransformer.pretrained("object")
    assert (model.n_neighbors, model.hop_sizes, model.lrf_neighbors) == ((96,), (1.0,), 96)
    assert model.attributes == ("xyz",) and model.pooling == "octants"
    assert model.n_features_out_ == 24 and model.components_ is None
    assert not hasattr(model, "registration_points_")
    assert not hasattr(model, "registration_global_method_")
    with pytest.raises(ValueError, match="principal axes"):
        RPointHopTransformer.pretrained("object", n_components=8)
    assert DEFAULT_MODEL == "object"
    assert default_descriptor().get_params() == model.get_params()


def test_the_object_model_is_rigid_invariant():
    rng = np.random.default_rng(4)
    cloud = make_object(700, shape_seed=8, sample_seed=1)
    model = RPointHopTransformer.pretrained("object")
    rotation = Rotation.random(random_state=5).as_matrix()
    moved = cloud[::-1] @ rotation.T + rng.uniform(-50, 50, 3)
    desc, back = model.transform(cloud), model.transform(moved)[::-1]
    spread = np.abs(desc - desc.mean(0)).max()
    assert desc.shape == (700, 24) and np.isfinite(desc).all()
    assert np.abs(back - desc).max() <= 1e-5 * spread


def test_pretrained_models_share_one_read_only_copy_of_the_file(monkeypatch):
    import copy
    import pickle

    from o3d_rpointhop.datasets import make_object
    from o3d_rpointhop.descriptors import _rpointhop

    first = RPointHopTransformer.pretrained(n_components=32)
    # A second call does not read the file again.
    monkeypatch.setattr(_rpointhop, "pretrained_path", None)
    second = RPointHopTransformer.pretrained(n_components=None)
    assert first.kernels_ is not second.kernels_  # lists of their own ...
    assert all(a is b for a, b in zip(first.kernels_, second.kernels_, strict=True))
    assert first.components_ is second.components_  # ... holding the same arrays
    assert first.n_components == 32 and second.n_components is None
    with pytest.raises(ValueError, match="read-only"):
        first.kernels_[0][0, 0, 0] = 1.0
    with pytest.raises(ValueError, match="read-only"):
        first.components_[0, 0] = 1.0
    second.kernels_.append(None)  # a model's own list: the shared one is untouched
    assert len(RPointHopTransformer.pretrained().kernels_) == len(first.kernels_)
    # A deep copy and a pickled copy are writable; describing does not depend on it.
    own = copy.deepcopy(first)
    own.kernels_[0][0, 0, 0] += 0.0
    cloud = make_object(600, shape_seed=2)
    expected = first.transform(cloud)
    np.testing.assert_array_equal(own.transform(cloud), expected)
    np.testing.assert_array_equal(pickle.loads(pickle.dumps(first)).transform(cloud), expected)
