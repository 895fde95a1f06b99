"""The pose graph's spanning tree and the poses along it, on hand-made graphs."""

from __future__ import annotations

import numpy as np

from o3d_rpointhop.registration.pose_graph import poses_from_tree, spanning_tree


def _edges(fitness: dict) -> dict:
    return {pair: (np.eye(4), f, None) for pair, f in fitness.items()}


def test_the_spanning_tree_keeps_the_best_fitting_edges():
    """Worked by hand: the two best edges, then of the two tied at 0.5 the first given
    (Kruskal's order), never the edge that would close a loop; scan 4 touches no edge."""
    edges = _edges({(0, 1): 0.9, (1, 2): 0.5, (0, 2): 0.5, (2, 3): 0.7, (1, 3): 0.2})
    assert spanning_tree(edges, 5) == [(0, 1), (2, 3), (1, 2)]
    assert spanning_tree({}, 3) == []


def test_poses_follow_the_tree_from_scan_0():
    shift = np.eye(4)
    shift[0, 3] = 1.0
    edges = {(0, 1): (shift, 0.9, None), (1, 2): (shift, 0.8, None)}
    poses = poses_from_tree(spanning_tree(edges, 4), edges, 4)
    assert [p[0, 3] for p in poses[:3]] == [0.0, 1.0, 2.0] and poses[3] is None
