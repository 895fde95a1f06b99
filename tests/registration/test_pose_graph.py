"""The pose graph's spanning tree, the poses along it and its bridges, on hand-made and
random graphs."""

from __future__ import annotations

import dataclasses
import logging

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from o3d_rpointhop.cli._trust import report_reconstruction
from o3d_rpointhop.registration.pose_graph import bridges, poses_from_tree, spanning_tree
from o3d_rpointhop.registration.result import MultiwayResult


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


# A triangle 0-1-2 with a tail 2-3-4, a triangle 4-5-6 at its end and a leaf 1-7.
GRAPH = [(0, 1), (1, 2), (0, 2), (2, 3), (3, 4), (4, 5), (5, 6), (4, 6), (1, 7)]


def test_bridges_are_the_edges_no_loop_holds_with_what_lies_beyond():
    """Worked by hand, from two roots; the order of the edges changes nothing."""
    assert bridges(GRAPH, 0) == [((1, 7), [7]), ((2, 3), [3, 4, 5, 6]), ((3, 4), [4, 5, 6])]
    assert bridges(GRAPH, 5) == [((1, 7), [7]), ((2, 3), [0, 1, 2, 7]), ((3, 4), [0, 1, 2, 3, 7])]
    assert bridges(GRAPH[::-1], 0) == bridges(GRAPH, 0)
    assert bridges(GRAPH, 9) == []  # a scan no edge touches
    assert bridges([(0, 1), (1, 2), (2, 0)], 1) == []


@settings(max_examples=60, deadline=None)
@given(st.sets(st.tuples(st.integers(0, 9), st.integers(0, 9)), max_size=20), st.integers(0, 9))
def test_bridges_match_removing_each_edge_in_turn(pairs, root):
    """An edge is a bridge when removing it cuts scans off the root, and its far side
    is what is cut off (what the root then reaches no longer)."""
    edges = sorted({(min(p), max(p)) for p in pairs if p[0] != p[1]})

    def reach(kept):
        seen, todo = {root}, [root]
        while todo:
            x = todo.pop()
            for i, j in kept:
                for a, b in ((i, j), (j, i)):
                    if a == x and b not in seen:
                        seen.add(b)
                        todo.append(b)
        return seen

    whole = reach(edges)
    want = []
    for e in edges:
        if e[0] in whole:
            cut = whole - reach([x for x in edges if x != e])
            if cut:
                want.append((e, sorted(cut)))
    assert bridges(edges, root) == want


def test_a_reconstruction_names_the_scans_on_the_small_side_of_its_bridges(caplog):
    """``MultiwayResult.unverified``: every placed scan on the smaller side of a bridge
    (of two alike, the less supported), with its bridges from the larger sides to the
    smaller and their fitness, whichever scan is the frame; the summary holds it and
    the command line warns once and names each with -v."""
    poses = [np.eye(4)] * 8 + [None]
    pairs = {e: (np.eye(4), 0.5 + 0.01 * k) for k, e in enumerate(GRAPH)}
    result = MultiwayResult(poses=poses, pose_graph=None, pairs=pairs, edges=GRAPH, frame=0)
    reasons = result.unverified()
    # 2-3 cuts 0, 1, 2, 7 (kept fitness 2.11) from 3-6 (2.22); 3-4 cuts 4-6, 1-7 cuts 7.
    assert sorted(reasons) == [0, 1, 2, 4, 5, 6, 7]
    assert reasons[7] == (
        "joined to the other scans through 2 edges that no loop of the pose graph checks: "
        "scan 2 - scan 3 (edge fitness 0.53), then scan 1 - scan 7 (edge fitness 0.58)"
    )
    assert reasons[5] == (
        "joined to the other scans through 1 edge that no loop of the pose graph checks: "
        "scan 3 - scan 4 (edge fitness 0.54)"
    )
    for frame in range(8):  # the same sides seen from any scan
        assert dataclasses.replace(result, frame=frame).unverified() == reasons
    names = [f"s{k}.ply" for k in range(9)]
    summary = result.as_dict(names)
    assert sorted(summary["unverified"]) == [f"s{k}.ply" for k in (0, 1, 2, 4, 5, 6, 7)]
    with caplog.at_level(logging.INFO, logger="o3d_rpointhop.cli"):
        report_reconstruction(summary, names[0])
    lines = [r.getMessage() for r in caplog.records]
    assert lines[0].startswith("7 placed scans are joined to the others by edges no loop")
    assert lines[1].startswith("unverified: s0.ply: joined to the other scans through 1 edge")
    triangle = MultiwayResult(
        poses=poses[:3], pose_graph=None, pairs=pairs, edges=GRAPH[:3], frame=0
    )
    assert triangle.unverified() == {}
