"""The shipped models and what a model states for registration (registration_points_,
registration_global_method_)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from o3d_rpointhop import (
    RPointHopTransformer,
)
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
