"""The R-PointHop feature learner as a scikit-learn transformer: parameters, fit,
transform, save and load around the hop maths of :mod:`.pointhop`."""

from __future__ import annotations

import copy
import threading
from collections.abc import Sequence
from numbers import Integral, Real
from os import PathLike
from typing import Any

import numpy as np
from sklearn.base import _fit_context
from sklearn.utils import check_random_state
from sklearn.utils.validation import check_is_fitted

from .._utils.parallel import map_clouds
from .._utils.params import Interval, StrOptions
from .._utils.threads import kernel_threads
from .._utils.validation import as_cloud_list, as_viewpoints
from ._base import BaseDescriptor
from ._persistence import load_model, save_model
from ._pretrained import PRETRAINED_COMPONENTS, PRETRAINED_MODELS, pretrained_path
from .pointhop import (
    N_TURNS_ALLOWED,
    POOLINGS,
    SAMPLING_METHODS,
    HopConfig,
    HopTree,
    cloud_frames,
)

__all__ = ["RPointHopTransformer"]


class RPointHopTransformer(BaseDescriptor):
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
        variant; ``"fpfh"``, their Fast Point Feature Histograms (33 bins, each over
        the neighbour's own first-hop neighbourhood, the frames' normal axes as
        normals), as the authors' PCRP puts them in the first hop. Every attribute is
        rigid-invariant and finite on planes and edges; see
        ``o3d_rpointhop.descriptors.pointhop._attributes``.
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
    pooling : {"octants", "azimuth"}, default="octants"
        How each neighbourhood is split into the eight bins its features are averaged
        over. ``"octants"``: the octants of the point's local frame, R-PointHop's
        pooling, which needs all three axes. ``"azimuth"``: above or below the tangent
        plane, times four distance shells of equal area, with hop 1's coordinates as
        distance from the normal axis, height and distance, and the neighbours' normals
        as radial, tangential and normal components: only the frame's normal axis
        counts, so nothing depends on the in-plane axes, which flat and cylindrical
        surfaces (walls, floors, indoor scenes) leave undetermined. Best with
        ``viewpoints``, which orient the normal axis.
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
        Cores to use. ``None``: every core, clouds one after another, each cloud's
        compiled passes on threads (within ``OMP_NUM_THREADS``, ``threadpoolctl``
        limits, ``joblib.parallel_config`` and, inside a joblib worker, one thread). An
        int ``k``: ``k`` threads over one cloud's points, ``k`` joblib processes of one
        thread each over several clouds (``fit``, and ``transform`` of a list); ``-1``:
        every core. Honoured by joblib's ``parallel_config``, so a Dask cluster can run
        it. The descriptors are the same bytes on any number of cores.
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
        shift every descriptor by one constant vector; see
        ``o3d_rpointhop.descriptors.pointhop._saab``.)
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
    registration_global_method_ : str
        Only on models that state it: the global step :func:`~o3d_rpointhop.register`
        runs with ``global_method="auto"`` (the shipped scene model: ``"consensus"``,
        chosen on its training scenes). Stored in the model file.

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
        "pooling": [StrOptions(set(POOLINGS))],
        "n_components": [None, Interval(Integral, 1, None, closed="left")],
        "progress": [None, "boolean"],
        "n_jobs": [None, Integral],
        "random_state": ["random_state"],
    }

    def __init__(
        self,
        n_neighbors: Sequence[int] = (64, 32, 48, 48),
        *,
        hop_sizes: Sequence[float | int] = (1.0, 0.75, 0.5, 0.375),
        lrf_neighbors: int = 64,
        attributes: Sequence[str] = ("xyz",),
        energy_threshold: float = 1e-3,
        scale: str | float = "auto",
        fit_subsample: int | None = None,
        sampling: str = "auto",
        pooling: str = "octants",
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
        self.pooling = pooling
        self.n_components = n_components
        self.progress = progress
        self.n_jobs = n_jobs
        self.random_state = random_state

    # ------------------------------------------------------------------ parameters
    def _hop_config(self) -> HopConfig:
        """The hop parameters, with the checks that relate them to each other (one hop
        size per neighbourhood size, sizes that do not grow); the declarative
        ``_parameter_constraints`` are checked by the caller."""
        return HopConfig.from_params(
            self.n_neighbors,
            self.hop_sizes,
            self.lrf_neighbors,
            self.scale,
            self.sampling,
            self.attributes,
            self.pooling,
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
    @_fit_context(prefer_skip_nested_validation=True)
    def fit(self, X: Any, y: Any = None, viewpoints: Any = None) -> RPointHopTransformer:
        """Learn the Saab kernels of every hop from unlabelled point clouds.

        Parameters
        ----------
        X : array-like of shape (n_points, 3) or (n_clouds, n_points, 3), \
                open3d.geometry.PointCloud, or list of those
            Training clouds; their sizes may differ.
        y : None
            Ignored.
        viewpoints : None, "origin", array-like of shape (3,) or (n_clouds, 3), \
                default=None
            Where each training cloud's sensor stood (see :meth:`transform`): fit
            with the viewpoints the model will be used with.

        Returns
        -------
        self : RPointHopTransformer
            The fitted transformer.
        """
        config = self._hop_config()
        clouds, kind = as_cloud_list(X)
        views = as_viewpoints(viewpoints, len(clouds))
        if self.fit_subsample is not None:
            rng = check_random_state(self.random_state)
            clouds = [
                c[np.sort(rng.choice(len(c), self.fit_subsample, replace=False))]
                if len(c) > self.fit_subsample
                else c
                for c in clouds
            ]
        self._check_sizes(clouds, config, kind)
        tree = HopTree.fit(
            clouds,
            config,
            energy_threshold=self.energy_threshold,
            n_components=self.n_components,
            n_jobs=self.n_jobs,
            progress=self.progress,
            viewpoints=views,
        )
        self._set_tree(tree)
        self.n_features_in_ = 3
        self.n_training_clouds_ = len(clouds)
        return self

    def _set_tree(self, tree: HopTree) -> None:
        """Store a fitted hop tree as the estimator's fitted attributes."""
        self.kernels_, self.means_ = tree.kernels, tree.means
        self.energies_, self.selected_ = tree.energies, tree.selected
        self.components_ = tree.components
        self.explained_variance_ = tree.explained_variance
        self.pca_mean_ = tree.pca_mean

    def _tree(self) -> HopTree:
        """The fitted attributes as a :class:`~.pointhop.HopTree` (no copy)."""
        return HopTree(
            kernels=self.kernels_,
            means=self.means_,
            energies=self.energies_,
            selected=self.selected_,
            components=getattr(self, "components_", None),
            explained_variance=getattr(self, "explained_variance_", None),
            pca_mean=getattr(self, "pca_mean_", None),
        )

    @property
    def n_features_out_(self) -> int:
        check_is_fitted(self, "kernels_")
        n_full = int(self.selected_[-1].size)
        return n_full if self.n_components is None else int(self.n_components)

    def _projection(self) -> tuple[np.ndarray, np.ndarray] | None:
        """``(mean, axes.T)`` for the current ``n_components``, or None; a clear error
        when the model holds fewer axes."""
        return self._tree().projection(self.n_components)

    # ------------------------------------------------------------------ transform
    def _check_transform(self) -> HopConfig:
        check_is_fitted(self, "kernels_")
        self._validate_params()
        config = self._hop_config()
        self._projection()  # n_components against the fitted axes, before any work
        return config

    def _per_cloud(self, X: Any, clouds: list[np.ndarray], kind: str, config: HopConfig) -> list:
        self._check_sizes(clouds, config, kind)
        return [config] * len(clouds)

    def _describe(self, points: np.ndarray, config: HopConfig, viewpoint) -> np.ndarray:
        return self._describe_turns(points, config, viewpoint, None)

    def transform_turns(
        self, X: Any, n_turns: int = 4, viewpoints: Any = None
    ) -> np.ndarray | list[np.ndarray]:
        """Describe every point under its local frame and that frame turned about its
        normal axis.

        A frame's normal axis repeats between two scans far more often than its in-plane
        axes (on walls and floors the two largest spreads are nearly equal, and the
        first axis's sign is a matter of sampling): at true correspondences of 3DMatch
        training pairs the whole frame agrees within 25 degrees at 17 %, up to a half
        turn at 31 % and up to a quarter turn at 47 %. Matching a point's descriptor
        against every turn of the other cloud's (``Matcher(frame_turns=...)``, the
        matcher of a global step) lets those correspondences match. The turns
        reuse the frames and neighbours: each costs one more Saab projection (for a
        multi-hop model, one more last hop), not a description.

        Parameters
        ----------
        X : point cloud(s)
            As in :meth:`transform`.
        n_turns : {1, 2, 4}, default=4
            1: the descriptors alone; 2: also under the frames turned by a half turn;
            4: under every quarter turn.
        viewpoints : None, "origin" or positions, default=None
            As in :meth:`transform`.

        Returns
        -------
        descriptors : ndarray of shape (n_turns, n_points, n_features_out_), or a list
            or stack of them as :meth:`transform` answers
            Turn ``t`` is the frames turned by ``t * 4 / n_turns`` quarter turns
            (``x' = y, y' = -x`` per quarter); turn 0 equals :meth:`transform`'s
            output. Octants are relabelled, not recomputed: a neighbour exactly on a
            frame plane moves with its octant (recomputed, it would stay on the plane's
            positive side).

        Raises
        ------
        ValueError
            If ``n_turns`` is not 1, 2 or 4, or the model pools by azimuth (whose
            bins do not change with a turn).
        """
        if (
            not isinstance(n_turns, Integral)
            or isinstance(n_turns, bool)
            or (n_turns not in N_TURNS_ALLOWED)
        ):
            raise ValueError(f"n_turns must be one of {N_TURNS_ALLOWED}, got {n_turns!r}")
        config = self._check_transform()
        if config.pooling == "azimuth" and n_turns > 1:
            raise ValueError(
                "pooling='azimuth' describes without the frames' in-plane axes: its "
                "descriptors are the same under every turn; use n_turns=1"
            )
        clouds, kind = as_cloud_list(X)
        views = as_viewpoints(viewpoints, len(clouds))
        extras = self._per_cloud(X, clouds, kind, config)
        turns = [int(n_turns)] * len(clouds)
        return map_clouds(self._describe_turns, clouds, kind, self.n_jobs, extras, views, turns)

    def _describe_turns(
        self, points: np.ndarray, config: HopConfig, viewpoint, n_turns: int | None
    ) -> np.ndarray:
        """One cloud's descriptors, ``(n, width)`` for ``n_turns`` None, else under each
        turn, ``(n_turns, n, width)``."""
        return self._tree().describe(
            points,
            config,
            n_components=self.n_components,
            n_threads=kernel_threads(self.n_jobs),
            progress=self.progress,
            viewpoint=viewpoint,
            n_turns=n_turns,
        )

    def local_frames(self, X: Any, viewpoints: Any = None) -> np.ndarray | list[np.ndarray]:
        """The local reference frame of every point, as the hops orient it.

        Useful to look at, and to measure how well frames repeat between two scans
        (:func:`o3d_rpointhop.evaluation.diagnostics.frame_repeatability`). Needs no
        fitting: the frames depend only on ``lrf_neighbors`` and the viewpoints.

        Parameters
        ----------
        X : point cloud(s)
            As in :meth:`transform`.
        viewpoints : None, "origin" or positions, default=None
            As in :meth:`transform`.

        Returns
        -------
        frames : ndarray of shape (n_points, 3, 3), or a list or stack of them
            ``frames[i, :, j]`` is unit axis ``j`` of point ``i``, largest spread first;
            axis 2 is the normal; ``det = +1``.
        """
        self._validate_params()
        config = self._hop_config()
        clouds, kind = as_cloud_list(X)
        views = as_viewpoints(viewpoints, len(clouds))
        for i, cloud in enumerate(clouds):
            if len(cloud) < config.lrf_neighbors:
                name = "X" if kind == "single" else f"X[{i}]"
                raise ValueError(
                    f"{name} has {len(cloud)} points, too few for lrf_neighbors="
                    f"{config.lrf_neighbors}"
                )
        frames = [cloud_frames(c, config, v) for c, v in zip(clouds, views, strict=True)]
        if kind == "single":
            return frames[0]
        return np.stack(frames) if kind == "batch" else frames

    def __sklearn_tags__(self):
        tags = super().__sklearn_tags__()
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
        name : {"modelnet40", "object", "scene", "scene-fpfh"}
            ``"modelnet40"``: paper object settings (four hops), fitted on a ModelNet40
            train subset (144 shapes, 1024 random points each); see
            ``docs/model_card.md``. ``"object"``: one hop of 96 neighbours (24-D),
            fitted on the same shapes, chosen on them for registration success and time
            together: what :func:`~o3d_rpointhop.register` and
            :func:`~o3d_rpointhop.register_multiway` describe with by default.
            ``"scene"``: the paper's scene attributes (normals and eigenvalue features),
            one hop of 96 neighbours, fitted with frames facing the sensor on 3DMatch
            fragments of four scenes, named in its ``training_scenes_``; made by
            ``scripts/fit_scene_model.py``. Describe with ``viewpoints`` (see
            ``docs/model_card.md``). ``"scene-fpfh"``: the same with FPFH histograms
            among the hop-1 attributes (``scripts/fit_scene_model.py --fpfh``), an
            option: more of its matches are right than the scene model's, for more
            time (docs/low_overlap.md).
        n_components : int, None or "default", default="default"
            ``None``: the full descriptor (1624-D for ``"modelnet40"``, 24-D for
            ``"object"``, 104-D for ``"scene"``, 368-D for ``"scene-fpfh"``). An int
            up to the axes the file holds (128 for ``"modelnet40"``, 96 for the scene
            models, none for ``"object"``): the
            descriptor's projection on that many principal axes, fitted on the same
            training data. ``"default"``: the model's own choice
            (``PRETRAINED_COMPONENTS``): the full descriptor for ``"modelnet40"`` and
            ``"object"``, the 96 axes every scene result was measured with for
            the scene models.

        Returns
        -------
        RPointHopTransformer
            A fitted model, loaded without pickle. The file is read once per process:
            every model this returns shares its fitted arrays, which are read-only
            (``copy.deepcopy(model)`` gives writable ones; a new ``fit`` replaces them).
        """
        if name not in PRETRAINED_MODELS:
            raise ValueError(
                f"unknown pretrained model {name!r}; available: {sorted(PRETRAINED_MODELS)}"
            )
        if n_components == "default":
            n_components = PRETRAINED_COMPONENTS[name]
        model = copy.copy(_shipped(cls, name))
        for attr, value in vars(model).items():
            if isinstance(value, list):  # a list of its own, the same read-only arrays
                setattr(model, attr, list(value))
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


#: Each shipped model as read from its file, read once per process and per class:
#: ``register()`` asks for the default descriptor on every call, and reading the
#: archive cost as much as describing a 1k-point cloud. Sharing the same arrays also
#: lets the last hop's folded projection be computed once.
_SHIPPED: dict[tuple[type, str], Any] = {}
_SHIPPED_LOCK = threading.Lock()


def _shipped(cls: type, name: str) -> Any:
    """The shipped model ``name`` loaded as ``cls``, its fitted arrays read-only."""
    with _SHIPPED_LOCK:
        model = _SHIPPED.get((cls, name))
        if model is None:
            with pretrained_path(name) as path:
                model = cls.load(path)
            for value in vars(model).values():
                for arr in value if isinstance(value, list) else [value]:
                    if isinstance(arr, np.ndarray):
                        arr.flags.writeable = False
            _SHIPPED[(cls, name)] = model
        return model
