"""The edge-length test of matched samples, shared by RANSAC's draws and FGR's tuple
test: a rigid motion keeps every distance, so the edges of a sample of true matches have
the same length on both sides."""

from __future__ import annotations

import numpy as np

from ..._utils.compiled import kernel

__all__ = ["consistent_edges"]


@kernel()
def consistent_edges(samples, source, target, edge_length):  # pragma: no cover - compiled
    """Which samples (rows of match indices) hold distinct matches whose edges agree in
    length between ``source`` and ``target`` (matched points, row ``i`` with row ``i``):
    every edge longer than ``edge_length`` times its partner, both ways; the length test
    is skipped when ``edge_length`` is 0. Open3D's edge-length checker for RANSAC's
    samples, and FGR's tuple test for its triples.

    One pass per sample, without the gathered ``(b, n, 3)`` copies a numpy check needs.
    Lengths are computed as ``numpy.linalg.norm`` rounds them, ``sqrt((x^2 + y^2) +
    z^2)``, so the samples kept are exactly the ones the numpy expression keeps.
    """
    n, r = samples.shape
    ok = np.ones(n, dtype=np.bool_)
    for i in range(n):
        good = True
        for a in range(r):
            for b in range(a + 1, r):
                if samples[i, a] == samples[i, b]:
                    good = False
        if good and edge_length > 0.0:
            for a in range(r):
                for b in range(a + 1, r):
                    p, q = samples[i, a], samples[i, b]
                    dx = source[p, 0] - source[q, 0]
                    dy = source[p, 1] - source[q, 1]
                    dz = source[p, 2] - source[q, 2]
                    ls = np.sqrt((dx * dx + dy * dy) + dz * dz)
                    dx = target[p, 0] - target[q, 0]
                    dy = target[p, 1] - target[q, 1]
                    dz = target[p, 2] - target[q, 2]
                    lt = np.sqrt((dx * dx + dy * dy) + dz * dz)
                    if not (ls > edge_length * lt and lt > edge_length * ls):
                        good = False
        ok[i] = good
    return ok
