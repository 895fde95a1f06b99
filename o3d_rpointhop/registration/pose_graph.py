"""The pose graph of a scan set: starting poses along a maximum spanning tree of the
registered pairs, and Open3D's global optimisation over every edge (the tree's edges
certain, the others loop closures its line process may prune)."""

from __future__ import annotations

import numpy as np
import open3d as o3d

from .settings import RegistrationSettings

__all__ = [
    "bridges",
    "largest_part",
    "optimise",
    "optimise_pose_graph",
    "parts",
    "poses_from_tree",
    "spanning_tree",
]

reg = o3d.pipelines.registration


def spanning_tree(edges: dict, n: int) -> list[tuple[int, int]]:
    """Maximum spanning forest by fitness (scipy's minimum spanning tree), its edges
    listed from the best fitting down. Equal fitnesses are ranked by the edges' order,
    so the forest is the one Kruskal's algorithm takes in that order."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import minimum_spanning_tree

    ordered = sorted(edges.items(), key=lambda e: -e[1][1])
    if not ordered:
        return []
    rows = [i for (i, _), _ in ordered]
    cols = [j for (_, j), _ in ordered]
    # Weights by rank (distinct, never zero): the best edge the most negative.
    weights = np.arange(-len(ordered), 0, dtype=np.float64)
    forest = minimum_spanning_tree(coo_matrix((weights, (rows, cols)), shape=(n, n)).tocsr())
    kept = {(min(i, j), max(i, j)) for i, j in zip(*forest.nonzero(), strict=True)}
    return [pair for pair, _ in ordered if (min(pair), max(pair)) in kept]


def bridges(edges: list[tuple[int, int]], root: int) -> list[tuple[tuple[int, int], list[int]]]:
    """The edges of ``root``'s part that no loop of the graph contains, each with the
    scans it alone joins to ``root`` (its far side, sorted), in O(scans + edges).

    A wrong edge inside a loop pulls against the loop's other edges, which the pose
    graph's optimisation weighs (and may prune); a wrong bridge moves everything beyond
    it, and nothing in the graph can tell. The bridges and their far sides do not depend
    on the order of ``edges``; they are listed by edge.
    """
    graph: dict[int, list[tuple[int, int]]] = {}
    for k, (i, j) in enumerate(edges):
        graph.setdefault(i, []).append((j, k))
        graph.setdefault(j, []).append((i, k))
    if root not in graph:
        return []
    # Tarjan's bridges, depth first without recursion: an edge to a child is a bridge
    # when nothing under the child reaches back above it.
    order, low, through = {root: 0}, {root: 0}, {root: -1}
    children: dict[int, list[int]] = {root: []}
    found = []
    stack = [(root, iter(graph[root]))]
    while stack:
        node, neighbours = stack[-1]
        for other, k in neighbours:
            if k == through[node]:
                continue
            if other in order:
                low[node] = min(low[node], order[other])
                continue
            order[other] = low[other] = len(order)
            through[other] = k
            children[node].append(other)
            children[other] = []
            stack.append((other, iter(graph[other])))
            break
        else:
            stack.pop()
            if stack:
                parent = stack[-1][0]
                low[parent] = min(low[parent], low[node])
                if low[node] > order[parent]:
                    found.append(node)
    out = []
    for node in found:
        side, todo = [], [node]
        while todo:
            x = todo.pop()
            side.append(x)
            todo.extend(children[x])
        i, j = edges[through[node]]
        out.append(((i, j), sorted(side)))
    return sorted(out)


def parts(edges: dict, n: int) -> list[list[int]]:
    """The connected parts of ``n`` scans joined by ``edges`` (``(i, j) -> (.., fitness,
    ..)``), each sorted, every scan in one (alone if no edge joins it)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components

    rows = [i for i, _ in edges]
    cols = [j for _, j in edges]
    graph = coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n))
    _, labels = connected_components(graph, directed=False)
    found: dict[int, list[int]] = {}
    for k, label in enumerate(labels):
        found.setdefault(int(label), []).append(k)
    return list(found.values())


def largest_part(edges: dict, n: int) -> tuple[list[int], list[list[int]]]:
    """The part of the scan set the reconstruction is rooted in, and every part, that
    one first, the others from the largest down: the most scans, then the most total
    edge fitness, then the lowest scan (the scans' order is a canonical one, by
    content, so no position decides)."""

    def rank(part: list[int]):
        inside = set(part)
        support = sum(e[1] for (i, j), e in edges.items() if i in inside and j in inside)
        return (-len(part), -support, part[0])

    ranked = sorted(parts(edges, n), key=rank)
    return ranked[0], ranked


def poses_from_tree(tree, edges, n: int, root: int = 0) -> list:
    """Poses (scan -> scan ``root``) along the tree; None where ``root`` cannot be
    reached."""
    poses: list = [None] * n
    poses[root] = np.eye(4)
    changed = True
    while changed:
        changed = False
        for i, j in tree:
            t_ij = edges[(i, j)][0]  # maps j into i
            if poses[i] is not None and poses[j] is None:
                poses[j] = poses[i] @ t_ij
                changed = True
            elif poses[j] is not None and poses[i] is None:
                poses[i] = poses[j] @ np.linalg.inv(t_ij)
                changed = True
    return poses


def optimise_pose_graph(graph, option) -> None:
    """Open3D's Levenberg-Marquardt global optimisation of ``graph`` in place, with
    ``option`` (a ``GlobalOptimizationOption``) and Open3D's default convergence
    criteria, its progress messages silenced."""
    with o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error):
        reg.global_optimization(
            graph,
            reg.GlobalOptimizationLevenbergMarquardt(),
            reg.GlobalOptimizationConvergenceCriteria(),
            option,
        )


def optimise(edges: dict, tree: list, poses: list, settings: RegistrationSettings, root: int = 0):
    """Open3D's global optimisation over the scans with a pose (``root`` held fixed);
    returns the graph, the optimised poses (into ``root``'s frame; None for the scans
    without a pose) and the edges it kept."""
    nodes = [k for k, p in enumerate(poses) if p is not None]
    index = {k: m for m, k in enumerate(nodes)}
    graph = reg.PoseGraph()
    for k in nodes:
        graph.nodes.append(reg.PoseGraphNode(poses[k]))
    tree_set = set(tree)
    listed = []
    for (i, j), (t_ij, _, information) in edges.items():
        if i not in index or j not in index:
            continue
        # Open3D's edge maps its source node into its target node: j into i.
        graph.edges.append(
            reg.PoseGraphEdge(
                index[j], index[i], t_ij, information, uncertain=(i, j) not in tree_set
            )
        )
        listed.append((i, j))
    optimise_pose_graph(
        graph,
        reg.GlobalOptimizationOption(
            max_correspondence_distance=settings.edge_distance,
            edge_prune_threshold=0.25,
            preference_loop_closure=1.0,
            reference_node=index[root],
        ),
    )
    optimised: list = [None] * len(poses)
    # Relative to the root's optimised pose, so that the root is exactly the identity.
    reference = np.linalg.inv(np.array(graph.nodes[index[root]].pose))
    for k in nodes:
        optimised[k] = reference @ np.array(graph.nodes[index[k]].pose)
    optimised[root] = np.eye(4)
    # Open3D removes the edges its line process pruned; what remains was kept.
    remaining = {(nodes[e.target_node_id], nodes[e.source_node_id]) for e in graph.edges}
    kept = [e for e in listed if e in remaining]
    return graph, optimised, kept
