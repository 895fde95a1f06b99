"""Per-cloud geometry of the R-PointHop hops, in compiled passes.

The geometry of a cloud (its local reference frames, hop samples, neighbourhoods and
their bins) does not depend on the learned kernels. :func:`build_geometry` computes it
once per cloud and keeps

* the hop-1 attributes: octant means of the neighbours' coordinates (24-D), and with
  the scene variant's ``attributes`` also of their normals and eigenvalue features
  (:mod:`._attributes`), and
* for every later hop, its :class:`HopNeighbourhood`: each query's neighbours among
  the previous hop's points and their bins, what the hop's pooling reads
  (:mod:`._pooling`).

Hop ``h`` (1-based) takes its queries from the sample ``S_h`` and its neighbours from
``S_{h-1}``, where ``S_0`` is the whole cloud and ``S_h`` is a sample of size
``hop_sizes[h-1]`` drawn from ``S_{h-1}`` (farthest points for clouds of up to
:data:`~._sampling.FPS_MAX_POINTS` points, Poisson disks above; see
:mod:`._sampling`). When transforming, the last hop takes every input point as
a query, so every point gets a descriptor.

The passes: one k-d tree over the cloud and one search serve the frames and every hop
whose neighbours come from the whole cloud (the first ``s`` neighbours of each point
are its ``s`` nearest, for every size ``s`` asked for); a compiled pass over each point
orients its frame, bins its neighbours and pools hop 1; every hop whose neighbours
come from a sample searches a tree over that sample and bins its neighbours in the
queries' frames in one compiled pass. Each query's work is its own, so nothing depends
on the number of threads.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..._utils.compiled import kernel
from ..._utils.kdtree import QUERY_CHUNK
from ..._utils.threads import run_blocks, start_beside
from ._attributes import eigen_features, fpfh_features
from ._config import HopConfig
from ._frames import frame_of
from ._neighbors import HopSearch, tie_ranks
from ._octants import N_OCTANTS, bins_of, cylindrical_of, means_of
from ._sampling import hop_subsets, resolve_method

__all__ = ["CloudGeometry", "HopNeighbourhood", "build_geometry", "cloud_frames", "cloud_scale"]

#: Points whose whole-cloud neighbourhoods are in memory at once (about 0.4 kB each):
#: a bounded chunking, so that memory grows linearly with the cloud.
GEOMETRY_CHUNK = 65536


@dataclass
class HopNeighbourhood:
    """Who each query of a hop pools, and into which bin.

    Attributes
    ----------
    neighbours : ndarray of shape (n_queries, k), int32
        Positions among the ``n_sources`` points of the previous hop.
    bins : ndarray of shape (n_queries, k), uint8
        The bin (0..7) of each neighbour in the query's frame.
    n_sources : int
    """

    neighbours: np.ndarray
    bins: np.ndarray
    n_sources: int

    @property
    def n_queries(self) -> int:
        return len(self.neighbours)

    @property
    def nbytes(self) -> int:
        return self.neighbours.nbytes + self.bins.nbytes


@dataclass
class CloudGeometry:
    """Kernel-independent structure of one cloud.

    Attributes
    ----------
    n_points : int
    hop1_attributes : ndarray of shape (|S_1|, config.hop1_dim)
    hops : list of HopNeighbourhood
        ``hops[h - 2]`` serves hop ``h`` (1-based), from hop 2 on.
    """

    n_points: int
    hop1_attributes: np.ndarray | None
    hops: list[HopNeighbourhood | None]

    @property
    def nbytes(self) -> int:
        parts = [self.hop1_attributes, *self.hops]
        return sum(p.nbytes for p in parts if p is not None)

    def release(self, hop: int) -> None:
        """Drop the structure that enters ``hop`` (0-based) once it has been used."""
        if hop == 0:
            self.hop1_attributes = None
        else:
            self.hops[hop - 1] = None


def cloud_scale(mean_dist: np.ndarray, scale: str | float) -> float:
    """The length that hop-1 coordinates are divided by.

    ``"auto"``: the median over points of ``mean_dist``, each point's mean distance to
    its LRF neighbours, so descriptors do not depend on the unit (metres, millimetres,
    unit sphere).
    """
    if scale != "auto":
        return float(scale)
    value = float(np.median(mean_dist))
    if value <= 0.0:
        value = float(mean_dist.mean())
    if value <= 0.0:
        raise ValueError(
            "the cloud has no spatial extent: every point coincides with its neighbours"
        )
    return value


@kernel(nogil=True)
def _frames_pass(
    start,
    stop,
    points,
    first,
    neighbours,
    k_lrf,
    centroid,
    viewpoint,
    has_view,
    hop1_rows,
    k1,
    azimuth,
    frames,
    eigenvalues,
    bins,
    hop1,
):  # pragma: no cover - compiled
    """Rows ``first + start : first + stop`` of the cloud (``neighbours`` and ``bins``
    hold one row per point from ``first`` on): each point's frame (``frames``,
    ``eigenvalues``: the cloud's arrays), its neighbours' bins in it and, for the
    points with a hop-1 row (``hop1_rows[row] >= 0``), the octant means of the first
    ``k1`` neighbours' coordinates (cylindrical ones with ``azimuth``) into that row of
    ``hop1``."""
    m = neighbours.shape[1]
    offsets = np.empty((3, m))
    local = np.empty((3, m))
    values = np.empty((3, m))
    cov = np.empty((3, 3))
    work = np.empty(k_lrf)
    towards = np.empty(3)
    sensor = np.empty(3)
    counts = np.empty(N_OCTANTS, np.int64)
    for i in range(start, stop):
        row = first + i
        for d in range(3):
            towards[d] = centroid[d] - points[row, d]
            sensor[d] = viewpoint[d] - points[row, d]
            for j in range(m):
                offsets[d, j] = points[neighbours[i, j], d] - points[row, d]
        frame_of(
            offsets,
            m,
            k_lrf,
            towards,
            sensor,
            has_view,
            frames[row],
            eigenvalues[row],
            local,
            cov,
            work,
        )
        bins_of(local, m, azimuth, bins[i])
        target = hop1_rows[row]
        if target >= 0:
            if azimuth:
                cylindrical_of(local, k1, values)
                means_of(values, k1, bins[i], counts, hop1[target], 0)
            else:
                means_of(local, k1, bins[i], counts, hop1[target], 0)


@kernel(nogil=True)
def _sampled_bins(
    start, stop, points, queries, sources, neighbours, frames, azimuth, out
):  # pragma: no cover - compiled
    """Bins of queries ``start:stop``'s neighbours (positions among ``sources``, rows of
    the cloud) in the query's frame (``queries``: rows of the cloud) into ``out``."""
    k = neighbours.shape[1]
    local = np.empty((3, k))
    for i in range(start, stop):
        row = queries[i]
        f = frames[row]
        for j in range(k):
            s = sources[neighbours[i, j]]
            x = points[s, 0] - points[row, 0]
            y = points[s, 1] - points[row, 1]
            z = points[s, 2] - points[row, 2]
            for a in range(3):
                local[a, j] = x * f[0, a] + y * f[1, a] + z * f[2, a]
        bins_of(local, k, azimuth, out[i])


@kernel(nogil=True)
def _normal_means(
    start, stop, points, queries, neighbours, bins, frames, azimuth, out
):  # pragma: no cover - compiled
    """Octant means of the neighbours' normals (their frames' third axes) in each
    query's frame into ``out`` ``(q, 24)``. With ``azimuth``, a normal is given by its
    components along the direction from the query's axis to the neighbour (radial),
    across it (tangential) and along the query's normal: nothing depends on the
    query's in-plane axes (a neighbour on the axis has no radial direction: both are 0
    there)."""
    k = neighbours.shape[1]
    values = np.empty((3, k))
    counts = np.empty(N_OCTANTS, np.int64)
    for i in range(start, stop):
        row = queries[i]
        f = frames[row]
        for j in range(k):
            nb = neighbours[i, j]
            n0 = frames[nb, 0, 2]
            n1 = frames[nb, 1, 2]
            n2 = frames[nb, 2, 2]
            for a in range(3):
                values[a, j] = (n0 * f[0, a] + n1 * f[1, a]) + n2 * f[2, a]
            if azimuth:
                ex = points[nb, 0] - points[row, 0]
                ey = points[nb, 1] - points[row, 1]
                ez = points[nb, 2] - points[row, 2]
                x = ex * f[0, 0] + ey * f[1, 0] + ez * f[2, 0]
                y = ex * f[0, 1] + ey * f[1, 1] + ez * f[2, 1]
                rho = np.sqrt(x * x + y * y)
                inv = 1.0 / rho if rho > 0.0 else 0.0
                a0 = values[0, j]
                a1 = values[1, j]
                values[0, j] = (a0 * x + a1 * y) * inv
                values[1, j] = (a1 * x - a0 * y) * inv
        means_of(values, k, bins[i], counts, out[i], 0)


@kernel(nogil=True)
def _feature_means(start, stop, neighbours, bins, features, out):  # pragma: no cover
    """Octant means of per-point features ``(n, c)`` over each query's neighbours into
    ``out`` ``(q, 8 * c)``."""
    k = neighbours.shape[1]
    c = features.shape[1]
    values = np.empty((c, k))
    counts = np.empty(N_OCTANTS, np.int64)
    for i in range(start, stop):
        for j in range(k):
            for d in range(c):
                values[d, j] = features[neighbours[i, j], d]
        means_of(values, k, bins[i], counts, out[i], 0)


def _rows(sample: np.ndarray | None, n: int) -> np.ndarray:
    """Each cloud row's position in a sample of rows (-1 for rows outside it)."""
    position = np.full(n, -1, dtype=np.int64)
    position[slice(None) if sample is None else sample] = np.arange(
        n if sample is None else len(sample)
    )
    return position


def _whole(sample: np.ndarray, n: int) -> np.ndarray | None:
    """None for a sample of every row (the whole cloud), else the sample."""
    return None if len(sample) == n else sample


def _frames_and_full_hops(
    points, config, search, k_search, full, queries, viewpoint, n_threads, found=None
):
    """The frames pass over every point in chunks: frames, eigenvalues, the scale's
    mean distances, hop 1's coordinate means, and for every hop ``h`` in ``full``
    (neighbours from the whole cloud) its queries' neighbours and bins. ``found``:
    the whole cloud's search, ``(neighbours, mean_dist)``, if made already."""
    n = len(points)
    k_lrf = config.lrf_neighbors
    azimuth = config.pooling == "azimuth"
    frames = np.empty((n, 3, 3))
    eigenvalues = np.empty((n, 3))
    mean_dist = np.empty(n) if found is None else found[1]
    hop1_rows = _rows(queries[0], n)
    hop1 = np.empty((n if queries[0] is None else len(queries[0]), 24))
    # Hop 1 is pooled in the pass; its neighbours are kept only for the scene attributes.
    kept = {h: _rows(queries[h], n) for h in full if h > 0 or len(config.attributes) > 1}
    stored = {
        h: (
            np.empty((int((kept[h] >= 0).sum()), config.n_neighbors[h]), np.int32),
            np.empty((int((kept[h] >= 0).sum()), config.n_neighbors[h]), np.uint8),
        )
        for h in kept
    }
    levels = tuple(config.n_neighbors[h] for h in full)
    centroid = points.mean(axis=0)
    view = centroid if viewpoint is None else np.asarray(viewpoint, dtype=np.float64)
    step = -(-GEOMETRY_CHUNK // QUERY_CHUNK) * QUERY_CHUNK  # where the searches restart
    for start in range(0, n, step):
        rows = np.arange(start, min(n, start + step))
        if found is None:
            neighbours, _, mean_dist[rows] = search.neighbours(
                rows, k_search, levels, n_mean=k_lrf - 1, n_threads=n_threads
            )
        else:
            neighbours = found[0][start : start + len(rows)]
        bins = np.empty(neighbours.shape, np.uint8)
        run_blocks(
            _frames_pass,
            len(rows),
            n_threads,
            points,
            start,
            neighbours,
            k_lrf,
            centroid,
            view,
            viewpoint is not None,
            hop1_rows,
            config.n_neighbors[0],
            azimuth,
            frames,
            eigenvalues,
            bins,
            hop1,
            per_thread=4,
        )
        for h in kept:
            k = config.n_neighbors[h]
            position = kept[h][rows]
            chosen = position >= 0
            stored[h][0][position[chosen]] = neighbours[chosen, :k]
            stored[h][1][position[chosen]] = bins[chosen, :k]
    return frames, eigenvalues, mean_dist, hop1, stored


def _centred(points: np.ndarray, viewpoint: np.ndarray | None):
    """The cloud and the viewpoint moved by the cloud's centroid, in float64: every
    later step (the tie ranks, the sampling's start, the frames' orientation) then
    sees the same numbers, up to rounding near the origin, wherever the cloud lies."""
    points = np.asarray(points, dtype=np.float64)
    centre = points.mean(axis=0)
    if viewpoint is not None:
        viewpoint = np.asarray(viewpoint, dtype=np.float64) - centre
    return np.ascontiguousarray(points - centre), viewpoint


def build_geometry(
    points: np.ndarray,
    config: HopConfig,
    for_fit: bool,
    n_threads: int = 1,
    viewpoint: np.ndarray | None = None,
) -> CloudGeometry:
    """Compute the hop structure of one validated cloud, large enough for ``config``
    (``config.shortfall(len(points))`` is None: the estimator checks it).

    Parameters
    ----------
    points : ndarray of shape (n, 3), float64
        Best in a spatial order (:func:`~._neighbors.spatial_order`): each search
        starts from the previous query's radius.
    config : HopConfig
    for_fit : bool
        If True the last hop's queries are its sample (as in training); otherwise they
        are all ``n`` points (one descriptor per input point).
    n_threads : int, default=1
        Threads of the compiled passes. Every query's neighbourhood is worked on by
        itself, so the result does not depend on them.
    viewpoint : ndarray of shape (3,), default=None
        Where the sensor that saw the cloud stands, in the cloud's coordinates: every
        frame's normal axis then points towards it (see
        :func:`~._frames.local_reference_frames`).
    """
    points, viewpoint = _centred(points, viewpoint)
    n = len(points)
    if not np.any(points != points[0]):
        raise ValueError("the cloud has no spatial extent: all its points coincide")
    n_hops = config.n_hops
    sizes = config.sample_sizes(n)
    # Hops whose neighbours come from the whole cloud share the frames' search.
    full = [0] + [h for h in range(1, n_hops) if sizes[h - 1] == n]
    k_search = max([config.lrf_neighbors - 1] + [config.n_neighbors[h] for h in full])
    levels = tuple(config.n_neighbors[h] for h in full)
    ranks = tie_ranks(points)
    search = HopSearch(points, ranks=ranks)
    method = resolve_method(config.sampling, n)
    found = graph = None
    if method == "fps" or n <= GEOMETRY_CHUNK:
        # The search first: the samples are drawn from its neighbour lists (FPS's
        # updates, the Poisson disks' first competitors). Larger clouds are searched
        # chunk by chunk in the frames' pass, which holds one chunk's lists at a time.
        neighbours, reach, mean_dist = search.neighbours(
            None, k_search, levels, n_mean=config.lrf_neighbors - 1, n_threads=n_threads
        )
        found, graph = (neighbours, mean_dist), (neighbours, reach)
    drawn_sizes = sizes if for_fit else sizes[:-1]
    if method == "fps" and n_threads > 1 and sizes[0] == n:
        # FPS is serial and the frames pass needs none of its picks (hop 1 describes
        # every point): the pass runs on the other threads meanwhile, keeping the
        # full hops' neighbours of every row, which the samples then select.
        sampling = start_beside(hop_subsets, points, drawn_sizes, method, graph, 1, ranks)
        try:
            everyone: list[np.ndarray | None] = [None] * n_hops
            frames, eigenvalues, mean_dist, hop1, stored = _frames_and_full_hops(
                points, config, search, k_search, full, everyone, viewpoint, n_threads, found
            )
        finally:
            drawn = sampling.result()
        samples = [_whole(s, n) for s in drawn]
        queries = samples if for_fit else samples + [None]
        for h, (neighbours, bins) in stored.items():
            if queries[h] is not None:
                stored[h] = (neighbours[queries[h]], bins[queries[h]])
    else:
        drawn = hop_subsets(points, drawn_sizes, method, graph, n_threads, ranks)
        samples = [_whole(s, n) for s in drawn]
        queries = samples if for_fit else samples + [None]
        frames, eigenvalues, mean_dist, hop1, stored = _frames_and_full_hops(
            points, config, search, k_search, full, queries, viewpoint, n_threads, found
        )
    sources = [None] + samples[: n_hops - 1]
    del search  # the whole cloud's tree
    hop1 /= cloud_scale(mean_dist, config.scale)
    hops: list[HopNeighbourhood | None] = [None] * (n_hops - 1)
    azimuth = config.pooling == "azimuth"
    for h in range(1, n_hops):
        k, src, qry = config.n_neighbors[h], sources[h], queries[h]
        n_sources = n if src is None else len(src)
        if h in full:
            neighbours, bins = stored.pop(h)
        else:
            hop_search = HopSearch(points, src, ranks)
            neighbours = hop_search.neighbours(qry, k, n_threads=n_threads)[0]
            rows = np.arange(n) if qry is None else qry
            bins = np.empty(neighbours.shape, np.uint8)
            run_blocks(
                _sampled_bins,
                len(rows),
                n_threads,
                points,
                rows,
                src,
                neighbours,
                frames,
                azimuth,
                bins,
            )
        hops[h - 1] = HopNeighbourhood(neighbours, bins, n_sources)
    if len(config.attributes) > 1:
        neighbours, bins = stored.pop(0)
        rows = np.arange(n) if queries[0] is None else queries[0]
        blocks = [hop1]
        for name in config.attributes[1:]:
            if name == "normal":
                out = np.empty((len(rows), 3 * N_OCTANTS))
                arrays = (points, rows, neighbours, bins, frames, azimuth, out)
                run_blocks(_normal_means, len(rows), n_threads, *arrays)
            else:
                if name == "eigen":
                    features = np.ascontiguousarray(eigen_features(eigenvalues))
                else:
                    every = neighbours
                    if queries[0] is not None:  # a sample: every point needs its own list
                        every = HopSearch(points, ranks=ranks).neighbours(
                            None, config.n_neighbors[0], n_threads=n_threads
                        )[0]
                    features = fpfh_features(points, frames[:, :, 2], every, n_threads)
                out = np.empty((len(rows), features.shape[1] * N_OCTANTS))
                run_blocks(_feature_means, len(rows), n_threads, neighbours, bins, features, out)
            blocks.append(out)
        hop1 = np.hstack(blocks)
    return CloudGeometry(n_points=n, hop1_attributes=hop1, hops=hops)


def cloud_frames(
    points: np.ndarray, config: HopConfig, viewpoint: np.ndarray | None = None
) -> np.ndarray:
    """The local reference frame of every point of a validated cloud, as the hops use
    it: ``(n, 3, 3)``, ``frames[i, :, j]`` axis ``j`` of point ``i`` (the third is the
    normal)."""
    points, viewpoint = _centred(points, viewpoint)
    frames_only = HopConfig(
        hop_sizes=(1.0,),
        n_neighbors=(config.lrf_neighbors - 1,),
        lrf_neighbors=config.lrf_neighbors,
        scale=config.scale,
        pooling=config.pooling,
    )
    search = HopSearch(points)
    nothing = np.empty(0, dtype=np.int64)  # no hop to pool
    return _frames_and_full_hops(
        points, frames_only, search, config.lrf_neighbors - 1, [], [nothing], viewpoint, 1
    )[0]
