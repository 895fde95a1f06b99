"""Scene models of the 3DMatch benchmark: leave-one-scene-out, on a synthetic scene folder."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import SMALL

from o3d_rpointhop.datasets import make_object
from o3d_rpointhop.evaluation.scene_models import (
    REGISTRATION_POINTS,
    leave_one_scene_out,
    scene_names,
)
from o3d_rpointhop.io import write_cloud


@pytest.fixture
def scene_folder(tmp_path):
    """A 3DMatch-like folder: three scenes of two fragments each."""
    for k, scene in enumerate(("scene-a", "scene-b", "scene-c")):
        folder = tmp_path / "3dmatch" / "fragments" / scene
        folder.mkdir(parents=True)
        for j in range(2):
            write_cloud(folder / f"cloud_bin_{j}.ply", make_object(2500, shape_seed=10 * k + j))
    return tmp_path


@pytest.mark.slow
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
        assert model.registration_global_method_ == "consensus"
        assert model.attributes == ("xyz", "normal", "eigen")
    cloud = make_object(1500, shape_seed=99)
    a, c = (models[s].transform(cloud) for s in ("scene-a", "scene-c"))
    assert np.isfinite(a).all() and not np.allclose(a, c)  # different training data
    again = leave_one_scene_out(["scene-a"], scene_folder, **SMALL)["scene-a"]
    np.testing.assert_array_equal(again.transform(cloud), a)  # deterministic
    with pytest.raises(FileNotFoundError, match="fragments"):
        scene_names(scene_folder / "nowhere")
