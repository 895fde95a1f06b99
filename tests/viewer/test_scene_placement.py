"""Where the viewer puts things, read from the scene it builds (no browser): the aligned
source lies where the transformation sends the source, on the target, and each scan of a
reconstruction where its pose sends it."""

from __future__ import annotations

import dataclasses

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
    result = register_multiway(scans, random_state=0)
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


@pytest.fixture
def panel(monkeypatch):
    """The legend HTML and the toggles' labels a viewer adds to its panel."""
    from viser import _gui_api

    added = {"html": [], "checkbox": []}
    html, checkbox = _gui_api.GuiApi.add_html, _gui_api.GuiApi.add_checkbox

    def record_html(self, content, *args, **kwargs):
        added["html"].append(content)
        return html(self, content, *args, **kwargs)

    def record_checkbox(self, label, *args, **kwargs):
        added["checkbox"].append(label)
        return checkbox(self, label, *args, **kwargs)

    monkeypatch.setattr(_gui_api.GuiApi, "add_html", record_html)
    monkeypatch.setattr(_gui_api.GuiApi, "add_checkbox", record_checkbox)
    return added


def test_a_legend_with_distinct_colours_and_scans_named_by_file(drawn, panel):
    """Every drawn kind in its own colour, each named in the legend with that colour;
    a reconstruction's scans toggled and listed under the names given."""
    from o3d_rpointhop.viewer import COLOURS, show_multiway, show_registration

    assert len(set(COLOURS.values())) == len(COLOURS)
    target = make_object(1500, shape_seed=4, sample_seed=1)
    source = make_object(1500, shape_seed=4, sample_seed=2) + [0.2, 0.0, 0.0]
    result = register(source, target)
    show_registration(source, target, result, port=free_port(), block=False).stop()
    (legend,) = panel["html"]
    for label, kind in (
        ("aligned source", "aligned"),
        ("target", "target"),
        ("global step: matches it kept", "matches_kept"),
        ("inlier correspondences", "correspondences"),
    ):
        assert label in legend and f"rgb{COLOURS[kind]}" in legend, label
    scans, _ = partial_views(3, seed=1)
    names = ["north.las", "east.las", "roof.las"]
    multiway = register_multiway(scans, random_state=0)
    show_multiway(scans, multiway, port=free_port(), block=False, names=names).stop()
    legend = panel["html"][-1]
    assert all(name in legend for name in names) and "pose graph edges" in legend
    assert set(names) <= set(panel["checkbox"]) and "scan 0" not in panel["checkbox"]
    with pytest.raises(ValueError, match="2 names for 3 scans"):
        show_multiway(scans, multiway, port=free_port(), block=False, names=names[:2])
    # A chain of edges: each is a bridge, drawn and listed in its own colour.
    chain = dataclasses.replace(multiway, edges=[(0, 1), (1, 2)])
    show_multiway(scans, chain, port=free_port(), block=False, names=names).stop()
    legend = panel["html"][-1]
    assert "edges no loop checks" in legend and "pose graph edges" not in legend
    assert f"rgb{COLOURS['unchecked_edges']}" in legend
    assert "edges no loop checks" in panel["checkbox"]


def test_the_address_printed_is_the_one_served():
    from o3d_rpointhop.viewer import served_address

    assert served_address("127.0.0.1", 8080) == "http://127.0.0.1:8080"
    assert served_address("192.168.1.7", 9000) == "http://192.168.1.7:9000"
    assert served_address("::1", 8080) == "http://[::1]:8080"
    anywhere = served_address("0.0.0.0", 8080)  # another machine's way in, and this one's
    assert anywhere.startswith("http://") and anywhere.split()[0].endswith(":8080")
    assert "every interface" in anywhere and "http://127.0.0.1:8080" in anywhere
    assert not anywhere.startswith("http://0.0.0.0")
