"""Where the viewer puts things, read from the scene it builds (no browser): the aligned
source lies where the transformation sends the source, on the target, and each scan of a
reconstruction where its pose sends it."""

from __future__ import annotations

import numpy as np
import pytest
from helpers import free_port, partial_views, random_motion
from scipy.spatial import cKDTree

from o3d_rpointhop import register, register_multiway
from o3d_rpointhop.datasets import make_object
from o3d_rpointhop.transforms import apply_transform

viser = pytest.importorskip("viser")


@pytest.fixture
def drawn(monkeypatch):
    """Every point cloud a viewer adds, by node name (points as served)."""
    from viser import _scene_api

    clouds = {}
    original = _scene_api.SceneApi.add_point_cloud

    def record(self, name, points, *args, **kwargs):
        clouds[name] = np.asarray(points, dtype=np.float64)
        return original(self, name, points, *args, **kwargs)

    monkeypatch.setattr(_scene_api.SceneApi, "add_point_cloud", record)
    return clouds


def test_the_aligned_source_is_drawn_where_the_transformation_sends_it(drawn):
    from o3d_rpointhop.viewer import show_registration

    target = make_object(2000, shape_seed=4, sample_seed=1) + [500.0, -300.0, 20.0]
    rot, shift = random_motion(1, 0.3)
    source = make_object(2000, shape_seed=4, sample_seed=2) @ rot.T + shift
    result = register(source, target)
    server = show_registration(source, target, result, port=free_port(), block=False)
    server.stop()
    # The scene is drawn about some origin: compare offsets from the drawn target's mean.
    offset = target.mean(axis=0) - drawn["/target"].mean(axis=0)
    expected = apply_transform(source, result.transformation)
    gap, _ = cKDTree(expected).query(drawn["/aligned"] + offset)
    assert gap.max() < 1e-3  # float32 on screen
    gap, _ = cKDTree(source).query(drawn["/source"] + offset)
    assert gap.max() < 1e-3  # the source as given
    # and, the registration being right, on the target
    near, _ = cKDTree(target).query(drawn["/aligned"] + offset)
    assert np.median(near) < 0.05  # about the samples' spacing; the object spans ~1


def test_each_scan_is_drawn_where_its_pose_sends_it(drawn):
    from o3d_rpointhop.viewer import show_multiway

    scans, _ = partial_views(3, seed=1)
    result = register_multiway(scans, seed=0)
    server = show_multiway(scans, result, port=free_port(), block=False)
    server.stop()
    placed = [k for k, pose in enumerate(result.poses) if pose is not None]
    assert placed == [0, 1, 2]
    first = apply_transform(scans[0], result.poses[0])
    offset = first.mean(axis=0) - drawn["/scan_0"].mean(axis=0)
    for k in placed:
        expected = apply_transform(scans[k], result.poses[k])
        gap, _ = cKDTree(expected).query(drawn[f"/scan_{k}"] + offset)
        assert gap.max() < 1e-4, k
