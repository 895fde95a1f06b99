"""The multiway benchmark's peer: Open3D's multiway tutorial recipe."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from o3d_rpointhop.datasets import make_object
from o3d_rpointhop.evaluation.multiway import open3d_multiway_recipe
from o3d_rpointhop.registration.settings import common_voxel
from o3d_rpointhop.transforms import apply_transform, rotation_error_deg, translation_error


@pytest.mark.slow
def test_the_recipe_places_moved_copies_in_the_first_scans_frame():
    clouds, truth = [], []
    for k in range(3):
        motion = np.eye(4)
        if k:
            motion[:3, :3] = Rotation.random(random_state=k).as_matrix()
            motion[:3, 3] = [0.2 * k, -0.1, 0.05]
        clouds.append(apply_transform(make_object(2500, shape_seed=4, sample_seed=k), motion))
        truth.append(np.linalg.inv(motion))  # scan k back into scan 0's frame
    result = open3d_multiway_recipe(clouds, common_voxel(clouds, 1024), seed=0)
    assert len(result.poses) == 3 and np.allclose(result.poses[0], np.eye(4))
    for pose, true in zip(result.poses[1:], truth[1:], strict=True):
        assert rotation_error_deg(pose, true) < 2.0
        assert translation_error(pose, true) < 0.02
    # Pairs are stored as the library stores them: (i, j) maps scan j into scan i.
    t01, _ = result.pairs[(0, 1)]
    assert rotation_error_deg(t01, truth[1]) < 2.0
    assert set(result.edges) <= {(0, 1), (0, 2), (1, 2)} and (0, 1) in result.edges
