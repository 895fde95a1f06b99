"""The fitted hop tree: fitting hop after hop over many clouds, and the forward pass.

A :class:`HopTree` holds, for every hop, the Saab kernels of its channels, the training
mean of every output, every output's energy and the outputs passed on (or, for the last
hop, kept in the descriptor), and optionally the principal axes of the descriptors.
:meth:`HopTree.fit` learns them from clouds; :meth:`HopTree.describe` gives one row per
point of a cloud.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from joblib import Parallel, delayed, effective_n_jobs

from ..._utils.progress import progress_bar
from ..._utils.threads import kernel_threads, one_blas_thread
from ._config import HopConfig
from ._geometry import CloudGeometry, HopNeighbourhood, build_geometry
from ._neighbors import spatial_order
from ._octants import N_OCTANTS
from ._pooling import (
    folded_projection,
    matmul_blocks,
    pool,
    pool_project,
    pool_saab,
    remembered,
)
from ._saab import MomentAccumulator, apply_saab, fit_saab
from ._turns import octant_turn, turn_hop1

__all__ = ["HopTree"]

# Fitting keeps each cloud's hop structure and current features in memory while their
# total stays under this many bytes (about 2 MB per 1024-point cloud); the clouds beyond
# it are recomputed in every hop's pass instead, so memory stays bounded for any number
# of training clouds.
FIT_CACHE_BYTES = 2 * 1024**3
# Clouds whose structure is computed per parallel batch.
_CHUNK_PER_JOB = 8
#: The last hop and the projection run folded into one map while the folded rows of
#: the last hop's sources take at most this many bytes (clouds of up to about 85k
#: points with 128 axes: 25-30 % faster from 2k to 50k points); above, block by block
#: of :data:`UNFOLDED_ROWS` queries, as fast from 200k points on (the folded rows no
#: longer stay in cache) and with a third of the memory.
FOLD_BYTES = 128 * 1024**2
UNFOLDED_ROWS = 4096


#: Projections :meth:`HopTree.projection` remembers (each holds its model's axes alive).
_PROJECTIONS: dict = {}


def _float32_projection(components, pca_mean, n_components: int):
    """``(mean, axes.T)`` in float32, read-only (they are shared between calls)."""
    # float32: 3.4x faster than float64 and, by the contract, the rows may differ in
    # the last float32 places with their position in the BLAS kernel's tiles.
    axes = np.ascontiguousarray(components[:n_components].T, dtype=np.float32)
    axes.setflags(write=False)
    centre = pca_mean.astype(np.float32)
    centre.setflags(write=False)
    return centre, axes


@dataclass
class HopTree:
    """Fitted hops (see the estimator's attributes of the same names, with a ``_``).

    Attributes
    ----------
    kernels, means, energies, selected : list of ndarray
        Per hop: Saab kernels ``(n_channels, dim, dim)``, output means and energies
        ``(n_channels, dim)``, and the flattened indices of the outputs passed on.
    components, explained_variance, pca_mean : ndarray or None
        Principal axes of the descriptors, their variances and the descriptors' mean.
    """

    kernels: list
    means: list
    energies: list
    selected: list
    components: np.ndarray | None = None
    explained_variance: np.ndarray | None = None
    pca_mean: np.ndarray | None = None

    @property
    def n_full_features(self) -> int:
        """Outputs of the last hop (the descriptor before any projection)."""
        return int(self.selected[-1].size)

    # ------------------------------------------------------------------ fitting
    @classmethod
    def fit(
        cls,
        clouds: list[np.ndarray],
        config: HopConfig,
        *,
        energy_threshold: float,
        n_components: int | None,
        n_jobs: int | None,
        progress: bool | None,
        viewpoints: list[np.ndarray | None] | None = None,
    ) -> HopTree:
        """Fit hop after hop; every hop needs the previous hop's outputs of every cloud.

        Clouds whose structure and current features fit in :data:`FIT_CACHE_BYTES` are
        kept in memory between hops; the others are recomputed from scratch in every
        pass. With ``n_components``, one more pass gathers the covariance of the
        descriptors. ``viewpoints``: each cloud's sensor position or None (see
        :func:`~._geometry.build_geometry`).
        """
        viewpoints = viewpoints if viewpoints is not None else [None] * len(clouds)
        tree = cls(kernels=[], means=[], energies=[], selected=[])
        n_threads = kernel_threads(n_jobs)  # over one cloud's points
        n_hops = config.n_hops
        cache: dict[int, CloudGeometry] = {}
        features: dict[int, np.ndarray] = {}  # current hop's output of the cached clouds
        used = 0
        parent_energy = np.ones(1)
        passes = n_hops + (n_components is not None)
        bar = progress_bar(
            passes * len(clouds),
            desc="fit",
            unit="cloud",
            enabled=progress,
            large=len(clouds) >= 200,
        )
        for hop in range(passes):
            pca = hop == n_hops
            moments = (
                MomentAccumulator(1, tree.selected[-1].size)
                if pca
                else MomentAccumulator(len(parent_energy), config.hop1_dim if hop == 0 else 8)
            )
            batches = _geometry_batches(clouds, viewpoints, config, cache, n_jobs, n_threads)
            for i, geometry in batches:
                # Room for the structure and, later, the features it produces.
                if hop == 0 and used + 2 * geometry.nbytes <= FIT_CACHE_BYTES:
                    cache[i] = geometry
                    used += 2 * geometry.nbytes
                if pca:
                    previous = (
                        features.get(i)
                        if i in cache
                        else tree.forward(geometry, hop - 1, n_threads)
                    )
                    last = tree.hop(hop - 1, geometry, previous, n_threads)
                    moments.update(np.ascontiguousarray(last.T)[None])
                else:
                    previous = (
                        features.get(i) if i in cache else tree.forward(geometry, hop, n_threads)
                    )
                    moments.update(_hop_inputs(hop, geometry, previous))
                if bar is not None:
                    bar.update(1)
            if pca:
                tree._add_pca(moments, n_components)
                break
            parent_energy = tree._add_hop(
                moments, parent_energy, energy_threshold, last=hop == n_hops - 1
            )
            if hop < n_hops - 1:
                for i, geometry in cache.items():
                    features[i] = tree.hop(hop, geometry, features.get(i), n_threads)
        if bar is not None:
            bar.close()
        return tree

    def _add_hop(
        self,
        moments: MomentAccumulator,
        parent_energy: np.ndarray,
        energy_threshold: float,
        last: bool,
    ) -> np.ndarray:
        """Fit one hop's Saab kernels and select its channels; return their energies."""
        saab = fit_saab(moments)
        energy = parent_energy[:, None] * saab.energy
        flat = energy.ravel()
        threshold = float(energy_threshold)
        # The last hop keeps every output of the channels it receives (the descriptor).
        selected = np.arange(flat.size) if last else np.flatnonzero(flat >= threshold)
        if selected.size == 0 or not np.any(flat > 0):
            raise ValueError(
                f"no channel of hop {len(self.kernels) + 1} has energy above "
                f"energy_threshold={threshold}: the training clouds carry no usable "
                "variation (are they all the same degenerate shape?); fit on more varied "
                "clouds or lower the threshold"
            )
        self.kernels.append(saab.kernels)
        self.means.append(saab.mean)
        self.energies.append(energy)
        self.selected.append(selected)
        return flat[selected]

    def _add_pca(self, moments: MomentAccumulator, n_components: int) -> None:
        """Principal axes of the descriptors (the last hop's outputs)."""
        n_full = self.n_full_features
        if n_components > n_full:
            raise ValueError(
                f"n_components={n_components} exceeds the {n_full} outputs of the last "
                "hop; choose at most that many"
            )
        variance, axes = np.linalg.eigh(moments.covariance()[0])
        order = np.argsort(variance, kind="stable")[::-1][:n_components]
        axes = axes[:, order].T  # (k, n_full)
        # Sign fix, as for the Saab kernels: the largest-magnitude weight is positive.
        pivot = axes[np.arange(len(axes)), np.abs(axes).argmax(axis=1)]
        axes *= np.where(pivot < 0, -1.0, 1.0)[:, None]
        # Rounded to float32 as the model file stores them: a saved and reloaded model
        # projects exactly as the fitted one.
        self.components = axes.astype(np.float32).astype(np.float64)
        self.explained_variance = np.clip(variance[order], 0.0, None)
        self.pca_mean = moments.mean[0].copy()

    def projection(self, n_components: int | None) -> tuple[np.ndarray, np.ndarray] | None:
        """``(mean, axes.T)`` in float32 for ``n_components`` axes, or None for the full
        descriptor.

        Raises
        ------
        ValueError
            If the tree holds fewer principal axes.
        """
        if n_components is None:
            return None
        stored = 0 if self.components is None else len(self.components)
        if n_components > stored:
            raise ValueError(
                f"n_components={n_components}, but this model was fitted with "
                f"{'no' if not stored else stored} principal axes; refit with "
                f"n_components={n_components} (or set a smaller value)"
            )
        # Remembered for the same arrays: the transposed copy of 128 axes costs about
        # a fortieth of describing 2k points, and every transform asks twice.
        return remembered(
            _PROJECTIONS,
            (self.components, self.pca_mean),
            (int(n_components),),
            lambda: _float32_projection(self.components, self.pca_mean, n_components),
        )

    # ------------------------------------------------------------------ forward pass
    def hop(
        self, hop: int, geometry: CloudGeometry, previous: np.ndarray | None, n_threads: int
    ) -> np.ndarray:
        """Outputs of ``hop`` (0-based) that go on, one row per query: float32
        ``(n_queries, n_selected)``, the layout the next hop's pooling reads."""
        selected = self.selected[hop]
        if hop == 0:
            return self._first_hop(geometry.hop1_attributes)
        nb = geometry.hops[hop - 1]
        return pool_saab(
            previous,
            nb.neighbours,
            nb.bins,
            self.kernels[hop],
            self.means[hop],
            selected,
            n_threads,
        )

    def _first_hop(self, attributes: np.ndarray) -> np.ndarray:
        """Hop 1's outputs that go on from its attributes ``(n_queries, hop1_dim)``."""
        out = apply_saab(attributes.T[None].astype(np.float32), self.kernels[0], self.means[0])
        return np.ascontiguousarray(out.reshape(-1, out.shape[2])[self.selected[0]].T)

    def forward(
        self,
        geometry: CloudGeometry,
        n_hops: int | None = None,
        n_threads: int = 1,
        *,
        release: bool = False,
    ) -> np.ndarray:
        """Run the first ``n_hops`` hops (all by default) on a cloud's geometry; return
        the last one's output, ``(n_queries, n_selected)``.

        With ``release``, each hop's structure is dropped from ``geometry`` once used,
        so a large cloud's memory peaks lower (the geometry cannot be reused).
        """
        n_hops = len(self.kernels) if n_hops is None else n_hops
        feats = None
        for hop in range(n_hops):
            feats = self.hop(hop, geometry, feats, n_threads)
            if release:
                geometry.release(hop)
        return feats

    def describe(
        self,
        points: np.ndarray,
        config: HopConfig,
        *,
        n_components: int | None = None,
        n_threads: int = 1,
        progress: bool | None = None,
        viewpoint: np.ndarray | None = None,
        n_turns: int | None = None,
    ) -> np.ndarray:
        """One descriptor row per point of a validated cloud, float32.

        ``viewpoint``: where the sensor stands, in the cloud's coordinates, or None
        (see :func:`~._geometry.build_geometry`). ``n_turns``: also the descriptors
        under every frame turned about its normal by ``4 / n_turns`` quarter turns
        (:mod:`._turns`), stacked ``(n_turns, n_points, width)``, the first the
        descriptors themselves; None gives ``(n_points, width)``.

        The cloud is described in a spatial order (:func:`~._neighbors.spatial_order`;
        the result does not depend on it beyond rounding). With ``n_components``, the
        last hop and the projection run as one folded map (:func:`~._pooling.pool_project`)
        while the folded rows of its sources fit in :data:`FOLD_BYTES`, and block by
        block otherwise. BLAS runs on one thread meanwhile: the compiled passes and the
        matrix products' blocks run on ``n_threads`` threads, and nothing else.
        """
        with one_blas_thread():
            out = self._describe(
                points, config, n_components, n_threads, progress, viewpoint, n_turns or 1
            )
        return out[0] if n_turns is None else out

    def _describe(
        self, points, config, n_components, n_threads, progress, viewpoint, n_turns
    ) -> np.ndarray:
        projection = self.projection(n_components)
        bar = progress_bar(
            len(points),
            desc="describe",
            unit="pt",
            enabled=progress,
            large=len(points) >= 100_000,
        )
        order = spatial_order(points)
        geometry = build_geometry(
            points[order], config, for_fit=False, n_threads=n_threads, viewpoint=viewpoint
        )
        if bar is not None:
            bar.update(len(points) // 2)  # the geometry: about half of the time
        last = len(self.kernels) - 1
        n_out = self.n_full_features if projection is None else projection[1].shape[1]
        out = np.empty((n_turns, geometry.n_points, n_out), dtype=np.float32)
        quarters = [4 * t // n_turns for t in range(n_turns)]
        if last == 0:
            attributes = geometry.hop1_attributes
            folded = None
            if projection is not None:
                folded = folded_projection(
                    self.kernels[0], self.means[0], self.selected[0], self.components,
                    *projection, first_hop=True,
                )  # fmt: skip
            for t, q in enumerate(quarters):
                turned = attributes if q == 0 else turn_hop1(attributes, config.attributes, q)
                if folded is None:
                    out[t, order] = self._first_hop(turned)
                else:
                    described = matmul_blocks(turned.astype(np.float32), folded[0], n_threads)
                    out[t, order] = described + folded[1]
        else:
            previous = self.forward(geometry, last, n_threads, release=True)
            nb = geometry.hops[last - 1]
            for t, q in enumerate(quarters):
                # Deeper hops pool invariant features: a turn only relabels octants.
                if q:
                    geometry.hops[last - 1] = HopNeighbourhood(
                        nb.neighbours, octant_turn(q)[nb.bins], nb.n_sources
                    )
                self._last_hop(geometry, previous, projection, n_threads, out[t], order)
        if bar is not None:
            bar.update(len(points) - len(points) // 2)
            bar.close()
        return out

    def _last_hop(self, geometry, previous, projection, n_threads, out, rows) -> None:
        """The last hop's outputs of every query ``i``, projected on ``projection`` if
        given, into row ``rows[i]`` of ``out``."""
        last = len(self.kernels) - 1
        nb = geometry.hops[last - 1]
        kernels, means, selected = self.kernels[last], self.means[last], self.selected[last]
        if projection is None:
            pool_saab(
                previous, nb.neighbours, nb.bins, kernels, means, selected, n_threads, out, rows
            )
            return
        centre, axes = projection
        if nb.n_sources * N_OCTANTS * axes.shape[1] * 4 <= FOLD_BYTES:
            weights, bias = folded_projection(
                kernels, means, selected, self.components, centre, axes
            )
            folded = matmul_blocks(previous, weights, n_threads)
            pool_project(folded, nb.neighbours, nb.bins, bias, n_threads, out, rows)
            return
        for start in range(0, nb.n_queries, UNFOLDED_ROWS):
            stop = min(nb.n_queries, start + UNFOLDED_ROWS)
            block = pool_saab(
                previous,
                nb.neighbours[start:stop],
                nb.bins[start:stop],
                kernels,
                means,
                selected,
                n_threads,
            )
            block -= centre
            out[rows[start:stop]] = matmul_blocks(block, axes, n_threads)


def _hop_inputs(hop: int, geometry: CloudGeometry, previous: np.ndarray | None) -> np.ndarray:
    """Attributes entering ``hop`` (0-based), channel-major float32
    ``(n_channels, dim, n_queries)``; ``previous`` is the former hop's output,
    ``(n_points, n_channels)``."""
    if hop == 0:
        return geometry.hop1_attributes.T[None].astype(np.float32)
    nb = geometry.hops[hop - 1]
    return pool(previous, nb.neighbours, nb.bins)


def _geometry_batches(
    clouds: list[np.ndarray],
    viewpoints: list[np.ndarray | None],
    config: HopConfig,
    cache: dict[int, CloudGeometry],
    n_jobs,
    n_threads: int,
):
    """Yield ``(index, geometry)`` for every cloud; uncached ones are computed in
    parallel batches of ``n_jobs`` joblib tasks (one thread each), or in this process
    on ``n_threads`` threads when ``n_jobs`` asks for one process."""
    n_jobs = effective_n_jobs(n_jobs)
    chunk = max(1, n_jobs * _CHUNK_PER_JOB)
    threads = n_threads if n_jobs == 1 else 1
    with Parallel(n_jobs=n_jobs) as parallel:
        for start in range(0, len(clouds), chunk):
            idx = range(start, min(start + chunk, len(clouds)))
            missing = [i for i in idx if i not in cache]
            computed = parallel(
                # In a spatial order, as when describing (the moments are sums over
                # every query, whatever their order).
                delayed(build_geometry)(
                    clouds[i][spatial_order(clouds[i])],
                    config,
                    True,
                    n_threads=threads,
                    viewpoint=viewpoints[i],
                )
                for i in missing
            )
            fresh = dict(zip(missing, computed, strict=True))
            for i in idx:
                yield i, cache[i] if i in cache else fresh[i]
