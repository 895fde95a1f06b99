"""The R-PointHop feature learner as a scikit-learn transformer."""

from __future__ import annotations

from collections.abc import Sequence
from numbers import Integral, Real
from os import PathLike
from typing import Any

import numpy as np
from joblib import Parallel, delayed, effective_n_jobs
from sklearn.base import BaseEstimator, ClassNamePrefixFeaturesOutMixin, TransformerMixin
from sklearn.utils import check_random_state
from sklearn.utils._param_validation import Interval, StrOptions
from sklearn.utils.validation import check_is_fitted

from ._hops import SAMPLING_METHODS, CloudGeometry, HopConfig, build_geometry
from ._persistence import load_model, save_model
from ._progress import progress_bar
from ._saab import MomentAccumulator, apply_saab, fit_saab
from ._threads import one_blas_thread
from ._validation import as_cloud_list, describe_each

__all__ = ["RPointHopTransformer", "default_descriptor", "REGISTRATION_COMPONENTS"]

#: Principal axes of the descriptor that registration uses by default, chosen on pairs
#: of ModelNet40 *training* shapes (seed 7; success of register() with 64 / 128 axes /
#: the full 1624-D descriptor): resampled 66.7 / 68.8 / 60.4 %, paper-partial 83.3 /
#: 87.5 / 89.6 %, resampled-partial 43.8 / 45.8 / 45.8 %. 128 axes also make matching
#: and RANSAC several times cheaper than 1624.
REGISTRATION_COMPONENTS = 128

# Fitting keeps each cloud's hop structure and current features in memory while their
# total stays under this many bytes (about 2 MB per 1024-point cloud); the clouds beyond
# it are recomputed in every hop's pass instead, so memory stays bounded for any number
# of training clouds.
_FIT_CACHE_BYTES = 2 * 1024**3
# Clouds whose structure is computed per parallel batch.
_CHUNK_PER_JOB = 8


class RPointHopTransformer(ClassNamePrefixFeaturesOutMixin, TransformerMixin, BaseEstimator):
    """Unsupervised, rotation- and translation-invariant point descriptors (R-PointHop).

    R-PointHop (Kadam et al., IEEE TIP 2022) learns a multi-hop descriptor without
    labels. Each point gets a local reference frame (LRF) from the PCA of its nearest
    neighbours. Hop 1 takes the eight octant means of the neighbours' LRF coordinates
    (24 numbers) through a Saab transform (a DC kernel and PCA "AC" kernels; outputs are
    centred rather than biased, which only shifts every descriptor by one constant).
    Every later hop samples the cloud down by farthest point sampling, pools each
    surviving channel of the previous hop over the eight LRF octants of a larger
    neighbourhood and applies a channel-wise Saab transform. Channels whose energy falls
    below ``energy_threshold`` are dropped. The descriptor of a point is the output of the
    last hop, evaluated with every input point as a query, so ``transform`` returns one
    row per input point, in input order.

    Parameters
    ----------
    n_neighbors : sequence of int, default=(64, 32, 48, 48)
        Neighbourhood size of each hop; its length is the number of hops.
    hop_sizes : sequence of float or int, default=(1.0, 0.75, 0.5, 0.375)
        Size of each hop's farthest point sample: a float in (0, 1] is a fraction of the
        cloud, an int a number of points (at most the cloud's size). Must not increase.
        The defaults are the paper's 1024/768/512/384 points for a 1024-point cloud and
        scale with the cloud. The last size only sets which points train the last hop:
        when transforming, the last hop is evaluated at every input point.
    lrf_neighbors : int, default=64
        Number of nearest points (the point itself included) whose PCA gives the LRF
        (the paper's scene variant: 256).
    attributes : tuple of str, default=("xyz",)
        What hop 1 pools over the eight LRF octants of each neighbourhood: ``"xyz"``,
        the neighbours' LRF coordinates (the object variant), and optionally
        ``"normal"``, their normals expressed in the point's LRF, and ``"eigen"``, seven
        features of their covariance eigenvalues (linearity, planarity, scattering,
        omnivariance, anisotropy, eigenentropy, change of curvature): the paper's scene
        variant. Every attribute is rigid-invariant and finite on planes and edges; see
        ``o3d_rpointhop._attributes``.
    energy_threshold : float, default=0.001
        Channels whose energy (share of the variance, multiplied down the tree) is below
        this are not passed to the next hop. The last hop keeps all outputs of the
        channels it receives, as the authors' model does.
    scale : "auto" or float, default="auto"
        Length that hop-1 coordinates are divided by. ``"auto"`` uses each cloud's median
        distance between a point and its LRF neighbours, which makes descriptors
        independent of the unit and of uniform scaling (a unit-sphere object and a scan
        in metres are treated alike, as long as their point spacing is similar relative
        to their shape). A float fixes the unit, as the paper does (objects in the unit
        sphere).
    fit_subsample : int, default=None
        If set, ``fit`` draws at most this many points of each training cloud at random
        (e.g. 1024 of ModelNet40's 2048, as in the paper). ``transform`` never subsamples.
    sampling : {"auto", "fps", "poisson"}, default="auto"
        How each hop's sample is drawn. ``"fps"``: farthest point sampling from the
        point farthest from the centroid (the paper's choice; its cost grows with the
        square of the cloud). ``"poisson"``: a rigid-invariant Poisson-disk subsample
        in ``O(n log n)`` (see ``docs/algorithm.md``). ``"auto"``: FPS up to 16384
        points, Poisson disks above.
    n_components : int, default=None
        If set, descriptors are projected on their ``n_components`` principal axes,
        learned by ``fit`` from the training descriptors (a PCA without whitening
        folded into the last hop): a short descriptor that Open3D's k-d tree matches
        fast and that keeps a million-point cloud's descriptors small. A model fitted
        with ``n_components=K`` also serves any smaller value set later.
    progress : bool, default=None
        Show a progress bar on stderr (``tqdm``) for long fits and transforms. ``None``:
        only when stderr is a terminal and the job is large.
    n_jobs : int, default=None
        Parallel workers: processes over clouds (``fit``, and ``transform`` of several
        clouds), threads over blocks of points when transforming one cloud. ``None``
        means 1 and ``-1`` all cores. Honoured by joblib's ``parallel_config``, so a
        Dask cluster can run it.
    random_state : int, RandomState instance or None, default=None
        Seeds ``fit_subsample``. Everything else is deterministic: sampling depends on
        the geometry only, so it moves with the cloud.

    Attributes
    ----------
    n_features_in_ : int
        Always 3 (x, y, z).
    n_features_out_ : int
        Length of a descriptor: ``n_components`` if set, else every output of the last
        hop.
    kernels_ : list of ndarray of shape (n_channels, dim, dim)
        Saab kernels of each hop (hop 1: one channel, 8 octants x the attribute
        channels: 24-D for ``"xyz"``, 104-D with normals and eigen features; later hops:
        one 8-D channel per channel passed on). Column 0 is the DC kernel.
    means_ : list of ndarray of shape (n_channels, dim)
        Training mean of every Saab output of each hop, subtracted so that features are
        centred. (The paper instead adds a bias that makes them non-negative; both only
        shift every descriptor by one constant vector, see ``o3d_rpointhop._saab``.)
    energies_ : list of ndarray of shape (n_channels, dim)
        Energy of every output node of each hop (normalised variance times the parent's
        energy).
    selected_ : list of ndarray of int
        Indices into each hop's flattened ``(n_channels * dim)`` outputs of the nodes passed
        to the next hop, or, for the last hop, of the descriptor's components.
    n_training_clouds_ : int
        Number of clouds the model was fitted on.
    components_ : ndarray of shape (n_fitted_components, n_full_features) or None
        Principal axes of the training descriptors (``None`` if fitted without
        ``n_components``), by decreasing variance.
    explained_variance_ : ndarray of shape (n_fitted_components,) or None
        Variance of the training descriptors along each axis.
    pca_mean_ : ndarray of shape (n_full_features,) or None
        Mean of the training descriptors, subtracted before projecting.
    training_scenes_ : list of str
        Only on scene models: the scene folders the model was fitted on (set by
        ``scripts/fit_scene_model.py``, stored in the model file).
    registration_points_ : int
        Only on models that state it: the size each cloud should be downsampled to
        when :func:`~o3d_rpointhop.register` describes it (its ``n_global_points="auto"``
        reads it; the shipped scene model: 4096, chosen on its training scenes). Stored
        in the model file.

    See Also
    --------
    o3d_rpointhop.FPFHTransformer : Open3D's FPFH behind the same interface.

    Notes
    -----
    The descriptor is exactly invariant to rotations and translations of the input and
    equivariant to permutations of its rows, up to floating point rounding, as long as
    the geometry is generic: PCA axes of a neighbourhood with (near) equal eigenvalues,
    and points exactly on an octant boundary after rounding, are the known limits of any
    PCA-based LRF. Such degenerate neighbourhoods still get finite descriptors.

    Examples
    --------
    >>> import numpy as np
    >>> from o3d_rpointhop import RPointHopTransformer
    >>> rng = np.random.default_rng(0)
    >>> clouds = [rng.normal(size=(256, 3)) for _ in range(4)]
    >>> model = RPointHopTransformer().fit(clouds)
    >>> model.transform(clouds[0]).shape[0]
    256
    """

    _parameter_constraints = {
        "n_neighbors": ["array-like"],
        "hop_sizes": ["array-like"],
        "lrf_neighbors": [Interval(Integral, 3, None, closed="left")],
        "attributes": [tuple, list, str],
        "energy_threshold": [Interval(Real, 0, 1, closed="left")],
        "scale": [Interval(Real, 0, None, closed="neither"), StrOptions({"auto"})],
        "fit_subsample": [None, Interval(Integral, 1, None, closed="left")],
        "sampling": [StrOptions(set(SAMPLING_METHODS))],
        "n_components": [None, Interval(Integral, 1, None, closed="left")],
        "progress": [None, "boolean"],
        "n_jobs": [None, Integral],
        "random_state": ["random_state"],
    }

    def __init__(
        self,
        n_neighbors: Sequence[int] = (64, 32, 48, 48),
        hop_sizes: Sequence[float | int] = (1.0, 0.75, 0.5, 0.375),
        lrf_neighbors: int = 64,
        attributes: Sequence[str] = ("xyz",),
        energy_threshold: float = 1e-3,
        scale: str | float = "auto",
        fit_subsample: int | None = None,
        sampling: str = "auto",
        n_components: int | None = None,
        progress: bool | None = None,
        n_jobs: int | None = None,
        random_state: int | np.random.RandomState | None = None,
    ) -> None:
        self.n_neighbors = n_neighbors
        self.hop_sizes = hop_sizes
        self.lrf_neighbors = lrf_neighbors
        self.attributes = attributes
        self.energy_threshold = energy_threshold
        self.scale = scale
        self.fit_subsample = fit_subsample
        self.sampling = sampling
        self.n_components = n_components
        self.progress = progress
        self.n_jobs = n_jobs
        self.random_state = random_state

    # ------------------------------------------------------------------ parameters
    def _hop_config(self) -> HopConfig:
        """Validate every parameter (declaratively, then the ones that depend on each
        other: one hop size per neighbourhood size, sizes that do not grow); return the
        ones that shape the hops."""
        self._validate_params()
        return HopConfig.from_params(
            self.n_neighbors,
            self.hop_sizes,
            self.lrf_neighbors,
            self.scale,
            self.sampling,
            self.attributes,
        )

    def _check_sizes(self, clouds: list[np.ndarray], config: HopConfig, kind: str) -> None:
        for i, cloud in enumerate(clouds):
            reason = config.shortfall(len(cloud))
            if reason is not None:
                name = "X" if kind == "single" else f"X[{i}]"
                raise ValueError(
                    f"{name} has {len(cloud)} points, too few: {reason}; these settings need at "
                    f"least {config.min_points()} points per cloud"
                )

    # ------------------------------------------------------------------ fitting
    def fit(self, X: Any, y: Any = None) -> RPointHopTransformer:
        """Learn the Saab kernels of every hop from unlabelled point clouds.

        Parameters
        ----------
        X : array-like of shape (n_points, 3) or (n_clouds, n_points, 3), \
                open3d.geometry.PointCloud, or list of those
            Training clouds; their sizes may differ.
        y : None
            Ignored.

        Returns
        -------
        self : RPointHopTransformer
            The fitted transformer.
        """
        config = self._hop_config()
        clouds, kind = as_cloud_list(X)
        if self.fit_subsample is not None:
            rng = check_random_state(self.random_state)
            clouds = [
                c[np.sort(rng.choice(len(c), self.fit_subsample, replace=False))]
                if len(c) > self.fit_subsample
                else c
                for c in clouds
            ]
        self._check_sizes(clouds, config, kind)
        self._fit_hops(clouds, config)
        self.n_features_in_ = 3
        self.n_training_clouds_ = len(clouds)
        return self

    def _bar(self, total: int, unit: str, large: bool, desc: str):
        """A tqdm bar on stderr, or None (see the ``progress`` parameter)."""
        return progress_bar(total, desc=desc, unit=unit, enabled=self.progress, large=large)

    def _geometry_batches(
        self, clouds: list[np.ndarray], config: HopConfig, cache: dict[int, CloudGeometry]
    ):
        """Yield ``(index, geometry)`` for every cloud; uncached ones are computed in
        parallel batches."""
        n_jobs = effective_n_jobs(self.n_jobs)
        chunk = max(1, n_jobs * _CHUNK_PER_JOB)
        with Parallel(n_jobs=n_jobs) as parallel:
            for start in range(0, len(clouds), chunk):
                idx = range(start, min(start + chunk, len(clouds)))
                missing = [i for i in idx if i not in cache]
                computed = parallel(
                    delayed(build_geometry)(clouds[i], config, True) for i in missing
                )
                fresh = dict(zip(missing, computed, strict=True))
                for i in idx:
                    yield i, cache[i] if i in cache else fresh[i]

    def _fit_hops(self, clouds: list[np.ndarray], config: HopConfig) -> None:
        """Fit hop after hop; every hop needs the previous hop's outputs of every cloud.

        Clouds whose structure and current features fit in ``_FIT_CACHE_BYTES`` are kept
        in memory between hops; the others are recomputed from scratch in every pass.
        With ``n_components``, one more pass gathers the covariance of the descriptors.
        """
        n_hops = config.n_hops
        self.kernels_, self.means_, self.energies_, self.selected_ = [], [], [], []
        self.components_ = self.explained_variance_ = self.pca_mean_ = None
        cache: dict[int, CloudGeometry] = {}
        features: dict[int, np.ndarray] = {}  # current hop's output of the cached clouds
        used = 0
        parent_energy = np.ones(1)
        passes = n_hops + (self.n_components is not None)
        bar = self._bar(passes * len(clouds), "cloud", len(clouds) >= 200, "fit")
        for hop in range(passes):
            pca = hop == n_hops
            moments = (
                MomentAccumulator(1, self.selected_[-1].size)
                if pca
                else MomentAccumulator(len(parent_energy), config.hop1_dim if hop == 0 else 8)
            )
            for i, geometry in self._geometry_batches(clouds, config, cache):
                # Room for the structure and, later, the features it produces.
                if hop == 0 and used + 2 * geometry.nbytes <= _FIT_CACHE_BYTES:
                    cache[i] = geometry
                    used += 2 * geometry.nbytes
                if pca:
                    previous = features.get(i) if i in cache else self._forward(geometry, hop - 1)
                    moments.update(self._hop(hop - 1, geometry, previous)[None])
                else:
                    previous = features.get(i) if i in cache else self._forward(geometry, hop)
                    moments.update(self._hop_inputs(hop, geometry, previous))
                if bar is not None:
                    bar.update(1)
            if pca:
                self._add_pca(moments)
                break
            parent_energy = self._add_hop(moments, parent_energy, last=hop == n_hops - 1)
            if hop < n_hops - 1:
                for i, geometry in cache.items():
                    features[i] = self._hop(hop, geometry, features.get(i))
        if bar is not None:
            bar.close()

    def _add_pca(self, moments: MomentAccumulator) -> None:
        """Principal axes of the descriptors (the last hop's outputs)."""
        n_full = self.selected_[-1].size
        if self.n_components > n_full:
            raise ValueError(
                f"n_components={self.n_components} exceeds the {n_full} outputs of the last "
                "hop; choose at most that many"
            )
        variance, axes = np.linalg.eigh(moments.covariance()[0])
        order = np.argsort(variance, kind="stable")[::-1][: self.n_components]
        axes = axes[:, order].T  # (k, n_full)
        # Sign fix, as for the Saab kernels: the largest-magnitude weight is positive.
        pivot = axes[np.arange(len(axes)), np.abs(axes).argmax(axis=1)]
        axes *= np.where(pivot < 0, -1.0, 1.0)[:, None]
        # Rounded to float32 as the model file stores them: a saved and reloaded model
        # projects exactly as the fitted one.
        self.components_ = axes.astype(np.float32).astype(np.float64)
        self.explained_variance_ = np.clip(variance[order], 0.0, None)
        self.pca_mean_ = moments.mean[0].copy()

    @property
    def n_features_out_(self) -> int:
        check_is_fitted(self, "kernels_")
        n_full = int(self.selected_[-1].size)
        return n_full if self.n_components is None else int(self.n_components)

    def _projection(self) -> tuple[np.ndarray, np.ndarray] | None:
        """``(mean, axes.T)`` in float64 for the current ``n_components``, or None."""
        if self.n_components is None:
            return None
        stored = 0 if getattr(self, "components_", None) is None else len(self.components_)
        if self.n_components > stored:
            raise ValueError(
                f"n_components={self.n_components}, but this model was fitted with "
                f"{'no' if not stored else stored} principal axes; refit with "
                f"n_components={self.n_components} (or set a smaller value)"
            )
        axes = np.ascontiguousarray(self.components_[: self.n_components].T, dtype=np.float64)
        return self.pca_mean_, axes

    def _add_hop(
        self, moments: MomentAccumulator, parent_energy: np.ndarray, last: bool
    ) -> np.ndarray:
        """Fit one hop's Saab kernels and select its channels; return their energies."""
        saab = fit_saab(moments)
        energy = parent_energy[:, None] * saab.energy
        flat = energy.ravel()
        threshold = float(self.energy_threshold)
        # The last hop keeps every output of the channels it receives (the descriptor).
        selected = np.arange(flat.size) if last else np.flatnonzero(flat >= threshold)
        if selected.size == 0 or not np.any(flat > 0):
            raise ValueError(
                f"no channel of hop {len(self.kernels_) + 1} has energy above "
                f"energy_threshold={threshold}: the training clouds carry no usable "
                "variation (are they all the same degenerate shape?); fit on more varied "
                "clouds or lower the threshold"
            )
        self.kernels_.append(saab.kernels)
        self.means_.append(saab.mean)
        self.energies_.append(energy)
        self.selected_.append(selected)
        return flat[selected]

    # ------------------------------------------------------------------ forward pass
    @staticmethod
    def _hop_inputs(hop: int, geometry: CloudGeometry, previous: np.ndarray | None) -> np.ndarray:
        """Attributes entering ``hop`` (0-based), channel-major float32
        ``(n_channels, dim, n_queries)``; ``previous`` is the former hop's output,
        ``(n_channels, n_points)``."""
        if hop == 0:
            return geometry.hop1_attributes.T[None].astype(np.float32)
        return geometry.poolings[hop - 1](previous)

    def _hop(self, hop: int, geometry: CloudGeometry, previous: np.ndarray | None) -> np.ndarray:
        """Outputs of ``hop`` (0-based) that go on, float32 ``(n_selected, n_queries)``."""
        selected = self.selected_[hop]
        if hop == 0:
            attrs = self._hop_inputs(0, geometry, None)
            out = apply_saab(attrs, self.kernels_[0], self.means_[0])
            return out.reshape(-1, out.shape[2])[selected]
        pooling = geometry.poolings[hop - 1]
        out = np.empty((selected.size, pooling.n_queries), dtype=np.float32)
        pooling.map_blocks(
            previous, self._block_writer(hop, out, transposed=False), self._threads()
        )
        return out

    def _threads(self) -> int:
        """Threads over blocks of one cloud's points (``n_jobs``)."""
        return max(1, effective_n_jobs(self.n_jobs))

    def _forward(self, geometry: CloudGeometry, n_hops: int | None = None) -> np.ndarray:
        """Run the first ``n_hops`` fitted hops (all by default) on a cloud's geometry;
        return the last one's output, ``(n_selected, n_queries)``."""
        n_hops = len(self.kernels_) if n_hops is None else n_hops
        feats = None
        for hop in range(n_hops):
            feats = self._hop(hop, geometry, feats)
        return feats

    def _block_writer(self, hop: int, out: np.ndarray, transposed: bool, projection=None, bar=None):
        """A ``consume`` for :meth:`OctantPooling.map_blocks`: Saab-transform a block and
        store its selected outputs in ``out[:, start:stop]`` (or, ``transposed``, in rows
        ``out[start:stop]``, projected on ``projection = (mean, axes)`` if given)."""
        kernels, means, selected = self.kernels_[hop], self.means_[hop], self.selected_[hop]
        keep_all = selected.size == kernels.shape[0] * kernels.shape[2]

        def write(start: int, stop: int, attrs: np.ndarray) -> None:
            block = apply_saab(attrs, kernels, means).reshape(-1, stop - start)
            if not keep_all:
                block = block[selected]
            if projection is not None:
                # A BLAS product rounds a row by where it sits in the kernel's tiles. In
                # float64 that is far below float32's resolution, so once rounded to
                # float32 the rows come out the same wherever they sit: permuting the
                # cloud permutes the result (measured: no difference in 320k values).
                mean, axes = projection
                out[start:stop] = (block.T - mean) @ axes
            elif transposed:
                out[start:stop] = block.T
            else:
                out[:, start:stop] = block
            if bar is not None:
                bar.update(stop - start)

        return write

    def _describe(self, points: np.ndarray, config: HopConfig) -> np.ndarray:
        """One row per point. The last hop is evaluated block by block, each block's
        outputs transposed into their rows while still in cache (one transposed copy of
        the whole result would cost about a quarter of the transform). BLAS runs on one
        thread meanwhile: the blocks' threads are ``n_jobs``, and nothing else."""
        with one_blas_thread():
            return self._describe_blocks(points, config)

    def _describe_blocks(self, points: np.ndarray, config: HopConfig) -> np.ndarray:
        projection = self._projection()
        bar = self._bar(len(points), "pt", len(points) >= 100_000, "describe")
        geometry = build_geometry(points, config, for_fit=False)
        last = len(self.kernels_) - 1
        if last == 0:
            out = np.ascontiguousarray(self._forward(geometry).T)
            if projection is not None:
                out = ((out - projection[0]) @ projection[1]).astype(np.float32)
        else:
            previous = self._forward(geometry, last)
            out = np.empty((geometry.n_points, self.n_features_out_), dtype=np.float32)
            writer = self._block_writer(last, out, True, projection, bar)
            geometry.poolings[last - 1].map_blocks(previous, writer, self._threads())
        if bar is not None:
            bar.close()
        return out

    # ------------------------------------------------------------------ transform
    def transform(self, X: Any) -> np.ndarray | list[np.ndarray]:
        """Describe every point of one or several clouds.

        Parameters
        ----------
        X : array-like of shape (n_points, 3) or (n_clouds, n_points, 3), \
                open3d.geometry.PointCloud, or list of those

        Returns
        -------
        descriptors : ndarray of shape (n_points, n_features_out_), or a list of such
            arrays for a list input, or an ndarray of shape
            (n_clouds, n_points, n_features_out_) for a 3-D array input. Row ``i``
            describes input point ``i``.
        """
        check_is_fitted(self, "kernels_")
        config = self._hop_config()
        self._projection()  # n_components against the fitted axes, before any work
        clouds, kind = as_cloud_list(X)
        self._check_sizes(clouds, config, kind)
        return describe_each(self._describe, clouds, kind, self.n_jobs, [config] * len(clouds))

    @property
    def _n_features_out(self) -> int:
        return self.n_features_out_

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
        tags.input_tags.three_d_array = True
        tags.transformer_tags.preserves_dtype = []
        return tags

    # ------------------------------------------------------------------ persistence
    def save(self, path: str | PathLike) -> None:
        """Write the fitted model to an ``.npz`` file that loads without pickle.

        Parameters
        ----------
        path : str or path-like
            Destination, written exactly (no extension is added).
        """
        check_is_fitted(self, "kernels_")
        save_model(self, path)

    @classmethod
    def pretrained(
        cls, name: str = "modelnet40", *, n_components: int | str | None = "default"
    ) -> RPointHopTransformer:
        """The model shipped with the package, ready to transform.

        Parameters
        ----------
        name : {"modelnet40", "scene"}
            ``"modelnet40"``: paper object settings, fitted on a ModelNet40 train subset
            (144 shapes, 1024 random points each); see ``docs/model_card.md``.
            ``"scene"``: the paper's scene attributes (normals and eigenvalue features),
            fitted on 3DMatch fragments of four scenes, named in its
            ``training_scenes_``; made by ``scripts/fit_scene_model.py``.
        n_components : int, None or "default", default="default"
            ``None``: the full descriptor (1624-D for ``"modelnet40"``, 880-D for
            ``"scene"``). An int up to 128: the descriptor's projection on that many
            principal axes, fitted on the same training data. ``"default"``: the model's
            own choice (:data:`PRETRAINED_COMPONENTS`): the full paper descriptor for
            ``"modelnet40"``, the 128 axes every scene result was measured with for
            ``"scene"``.

        Returns
        -------
        RPointHopTransformer
            A fitted model, loaded without pickle.
        """
        from importlib.resources import as_file, files

        if name not in PRETRAINED_MODELS:
            raise ValueError(
                f"unknown pretrained model {name!r}; available: {sorted(PRETRAINED_MODELS)}"
            )
        if n_components == "default":
            n_components = PRETRAINED_COMPONENTS[name]
        with as_file(files("o3d_rpointhop") / "data" / PRETRAINED_MODELS[name]) as path:
            model = cls.load(path)
        model.set_params(n_components=n_components)
        model._projection()  # a clear error for more axes than the file holds
        return model

    @classmethod
    def load(cls, path: str | PathLike) -> RPointHopTransformer:
        """Read a model written by :meth:`save`.

        Raises
        ------
        ValueError
            If the file is not an o3d-rpointhop model, was written by a newer format
            version, or is damaged.
        """
        return load_model(cls, path)


#: The models shipped in ``o3d_rpointhop/data``, by name.
PRETRAINED_MODELS = {"modelnet40": "rpointhop_modelnet40.npz", "scene": "rpointhop_scene.npz"}
#: What :meth:`RPointHopTransformer.pretrained` returns by default, by name: the
#: ModelNet40 model's full descriptor (the paper's), and the scene model on the 128
#: principal axes it was chosen and measured with (docs/model_card.md).
PRETRAINED_COMPONENTS = {"modelnet40": None, "scene": 128}


def default_descriptor() -> RPointHopTransformer:
    """The descriptor ``register()``, the CLI and the benchmarks use when given none: the
    pretrained ModelNet40 model projected on :data:`REGISTRATION_COMPONENTS` axes."""
    return RPointHopTransformer.pretrained(n_components=REGISTRATION_COMPONENTS)
