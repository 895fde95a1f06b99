"""Registration chains (global first, then local) and the one-call ``register``."""

from __future__ import annotations

import logging
import time
import warnings
from numbers import Integral, Real
from typing import Any

import numpy as np
from sklearn.base import clone
from sklearn.utils.metaestimators import _BaseComposition
from sklearn.utils.validation import check_is_fitted

from .._utils.params import (
    HasMethods,
    Interval,
    InvalidParameterError,
    StrOptions,
    validate_params,
)
from .._utils.threads import core_budget
from .._utils.validation import check_rigid_transformation, renamed_seed
from ..descriptors import PRETRAINED_MODELS
from .checks import RegistrationWarning
from .context import RegistrationContext
from .defaults import FPFH_FALLBACK, default_descriptor, resolve_global_method
from .flags import assess, warn_flags
from .matching import PooledMatcher
from .model_choice import resolve_model
from .result import RegistrationResult
from .scoring import check_pairs, registration_scorer
from .settings import RegistrationSettings
from .steps import (
    ConsensusGlobal,
    FGRGlobal,
    GeneralizedICP,
    MultiScaleICP,
    PointToPlaneICP,
    PointToPointICP,
    RANSACGlobal,
    RegistrationStep,
    SVDGlobal,
    SymmetryCheck,
)

log = logging.getLogger(__name__)

__all__ = ["RegistrationPipeline", "build_chain", "register", "GLOBAL_METHODS", "REFINE_METHODS"]

#: The global steps by name (each step's ``name``).
GLOBAL_METHODS = {step.name: step for step in (RANSACGlobal, ConsensusGlobal, FGRGlobal, SVDGlobal)}
#: The refinements by name (each step's ``name``).
REFINE_METHODS = {
    step.name: step
    for step in (PointToPointICP, PointToPlaneICP, GeneralizedICP, MultiScaleICP, SymmetryCheck)
}


def _check_steps(steps: Any) -> list[tuple[str, RegistrationStep]]:
    if not isinstance(steps, (list, tuple)) or not steps:
        raise ValueError("steps must be a non-empty list of (name, step) pairs")
    names = set()
    for item in steps:
        if not (isinstance(item, tuple) and len(item) == 2 and isinstance(item[0], str)):
            raise ValueError(f"each step must be a (name, step) pair, got {item!r}")
        name, step = item
        if "__" in name or name in names:
            raise ValueError(f"step names must be unique and free of '__', got {name!r}")
        if not isinstance(step, RegistrationStep):
            raise ValueError(f"step {name!r} is not a RegistrationStep: {step!r}")
        names.add(name)
    return list(steps)


class RegistrationPipeline(_BaseComposition):
    """A chain of registration steps, run in order: a global estimate, then refinements.

    Built on scikit-learn's composition machinery, like ``sklearn.pipeline.Pipeline``:
    its steps are named, and every parameter of the steps and of the descriptor is
    reachable as ``<step>__<parameter>`` or ``descriptor__<parameter>`` through
    :meth:`get_params` / :meth:`set_params`, so ``clone`` and ``GridSearchCV`` work.
    :meth:`register` aligns one pair; :meth:`fit`, :meth:`predict` and :meth:`score`
    take a list of ``(source, target)`` pairs (and, for scoring, their true
    transformations) so that the pipeline can be cross-validated.

    Parameters
    ----------
    steps : list of (str, RegistrationStep)
    descriptor : transformer, default=None
        Descriptor for global steps that do not name their own; ``None`` is the
        shipped one-hop object model (``pretrained("object")``). :meth:`fit` fits a
        clone of it on the pairs' clouds (wrap a pretrained model in
        ``sklearn.frozen.FrozenEstimator`` to keep it as it is); :meth:`register` uses
        the fitted clone after :meth:`fit`, the descriptor as given before.
    voxel_size : float or "auto", default="auto"
        Resolution of the registration. ``"auto"``: clouds of up to ``n_global_points``
        points are used as they are, with their point spacing as the resolution; larger
        clouds are voxel-downsampled for the global step to about ``n_global_points``
        points. ICP steps always use the full clouds.
    n_global_points : int or "auto", default="auto"
        ``"auto"``: what the descriptor states in its ``registration_points_`` (4096
        for ``RPointHopTransformer.pretrained("scene")``), else 2048.
    random_state : int, default=0
        Seeds the random parts (RANSAC, FGR): results are repeatable. (An int only:
        every pair's draws start from it, so a result can be repeated from its record.)
    seed : int, default="deprecated"
        The former name of ``random_state``; given, it wins with a ``FutureWarning``.
    settings : RegistrationSettings, default=None
        The multiples of the resolution that distances the steps leave unset are
        derived from; ``None`` is ``RegistrationSettings()``.
    viewpoints : None, "origin" or (array-like, array-like), default=None
        Where the sensors that saw the source and the target stood, each in its own
        cloud's coordinates; ``"origin"``: every cloud is in its sensor's frame (3DMatch
        fragments, LiDAR sweeps, depth images). The descriptor's normals and local
        frames then face the sensor, which makes them repeat between scans of a scene
        (docs/algorithm.md, "Viewpoints"). ``None``: no sensor is known.
    up : None, array-like of shape (3,) or (array-like, array-like), default=None
        Which way is up in the source and the target (one vector for both, or one
        each): RANSAC and the consensus reject hypotheses that turn the source upside
        down (its up more than 90 degrees from the target's). For data that has an up
        (a LiDAR's z, a handheld camera's -y); off by default.
    n_jobs : int, default=None
        Cores the registration may use: the threads of the compiled kernels, of
        Open3D's searches and of BLAS (the descriptor matches' products), for every
        step and descriptor whose own ``n_jobs`` is None.
        ``None``: every core (within an enclosing ``joblib.parallel_config``); ``-1``:
        every core; the result does not depend on it.

    Attributes
    ----------
    descriptor_ : transformer
        After :meth:`fit`: the descriptor fitted on the pairs' clouds (the pretrained
        model when ``descriptor`` is None).

    Examples
    --------
    >>> from o3d_rpointhop import RegistrationPipeline, RANSACGlobal, PointToPlaneICP
    >>> pipe = RegistrationPipeline([("global", RANSACGlobal()), ("icp", PointToPlaneICP())])
    >>> pipe.set_params(icp__max_iteration=100).named_steps["icp"].max_iteration
    100
    """

    _parameter_constraints = {
        "steps": [list, tuple],
        "descriptor": [None, HasMethods(["transform"])],
        "voxel_size": [Interval(Real, 0, None, closed="neither"), StrOptions({"auto"})],
        "n_global_points": [Interval(Integral, 3, None, closed="left"), StrOptions({"auto"})],
        "random_state": [Interval(Integral, 0, None, closed="left")],
        "seed": [Interval(Integral, 0, None, closed="left"), StrOptions({"deprecated"})],
        "settings": [None, RegistrationSettings],
        "viewpoints": [None, StrOptions({"origin"}), "array-like"],
        "up": [None, "array-like"],
        "n_jobs": [None, Integral],
    }

    def __init__(
        self,
        steps: list[tuple[str, RegistrationStep]],
        *,
        descriptor: Any = None,
        voxel_size: float | str = "auto",
        n_global_points: int | str = "auto",
        random_state: int = 0,
        settings: RegistrationSettings | None = None,
        viewpoints: Any = None,
        up: Any = None,
        n_jobs: int | None = None,
        seed: int | str = "deprecated",
    ) -> None:
        self.steps = steps
        self.descriptor = descriptor
        self.voxel_size = voxel_size
        self.n_global_points = n_global_points
        self.random_state = random_state
        self.seed = seed
        self.settings = settings
        self.viewpoints = viewpoints
        self.up = up
        self.n_jobs = n_jobs

    @property
    def named_steps(self) -> dict[str, RegistrationStep]:
        return dict(_check_steps(self.steps))

    def get_params(self, deep: bool = True) -> dict:
        """Parameters of the pipeline, and with ``deep`` those of its steps
        (``<step>__<parameter>``) and of the descriptor (``descriptor__<parameter>``)."""
        return self._get_params("steps", deep=deep)

    def set_params(self, **params) -> RegistrationPipeline:
        """Set parameters, including ``<step>__<parameter>`` and whole steps by name."""
        names = [name for name, _ in _check_steps(self.steps)]
        for key in params:
            head = key.split("__", 1)[0]
            if "__" in key and head not in names and head not in self._parameter_constraints:
                raise ValueError(f"no step named {head!r} (steps: {names})")
        self._set_params("steps", **params)
        return self

    def _check(self, own: bool = True) -> list[tuple[str, RegistrationStep]]:
        """Validate the pipeline (unless ``own`` is False: a caller that checked the same
        parameters already) and every step, once per public call."""
        if own:
            self._validate_params()
        steps = _check_steps(self.steps)
        for name, step in steps:
            try:
                step.validate()
            except InvalidParameterError as exc:  # say which step, whoever called
                raise ValueError(f"step {name!r}: {exc}") from None
        return steps

    def fit(self, X: Any, y: Any = None) -> RegistrationPipeline:
        """Fit a clone of the descriptor on the clouds of the pairs ``X``.

        Parameters
        ----------
        X : list of (source, target)
            Pairs of clouds (arrays or Open3D clouds).
        y : ignored
            The true transformations are only needed by :meth:`score`.

        Returns
        -------
        self : RegistrationPipeline
        """
        self._check()
        pairs = check_pairs(X)
        if self.descriptor is None:
            self.descriptor_ = default_descriptor()
        else:
            clouds = [cloud for pair in pairs for cloud in pair]
            self.descriptor_ = clone(self.descriptor).fit(clouds, None)
        return self

    def predict(self, X: Any) -> np.ndarray:
        """The source-to-target transformation of every pair.

        Parameters
        ----------
        X : list of (source, target)

        Returns
        -------
        ndarray of shape (n_pairs, 4, 4)
        """
        check_is_fitted(self, "descriptor_")
        return np.stack([result.transformation for result in self.register_pairs(X)])

    def register_pairs(self, X: Any) -> list[RegistrationResult]:
        """:meth:`register` for every ``(source, target)`` pair of ``X``, in order."""
        steps = self._check()
        with warnings.catch_warnings():  # the flags are on the results
            warnings.simplefilter("ignore", RegistrationWarning)
            return [self._register(steps, s, t, None) for s, t in check_pairs(X)]

    def score(self, X: Any, y: Any) -> float:
        """Registration recall: the share of pairs registered within 5 deg and two
        resolutions of their true transformation (:func:`registration_scorer`'s defaults).

        Parameters
        ----------
        X : list of (source, target)
        y : array-like of shape (n_pairs, 4, 4)
            True source-to-target transformations.

        Returns
        -------
        float
        """
        return registration_scorer()(self, X, y)

    def register(self, source: Any, target: Any, init: np.ndarray | None = None):
        """Align ``source`` to ``target``.

        Parameters
        ----------
        source, target : array-like (n, 3) or Open3D point cloud
            Not modified.
        init : ndarray of shape (4, 4), default=None
            Starting transformation for refinement steps that come before any global
            step (e.g. ICP alone); global steps start from scratch. ``None`` is the
            identity.

        Returns
        -------
        RegistrationResult
        """
        return self._register(self._check(), source, target, init)

    def _register(self, steps, source, target, init, stacklevel: int = 4) -> RegistrationResult:
        start = time.perf_counter()
        with core_budget(self.n_jobs):  # the context's spacing searches too
            context = RegistrationContext(
                source,
                target,
                voxel_size=self.voxel_size,
                n_global_points=self.n_global_points,
                random_state=renamed_seed(self.random_state, self.seed, "RegistrationPipeline"),
                descriptor=getattr(self, "descriptor_", self.descriptor),
                settings=self.settings,
                viewpoints=self.viewpoints,
                up=self.up,
            )
            return self._run(steps, context, init, start, True, stacklevel)

    def run(
        self,
        context: RegistrationContext,
        init: np.ndarray | None = None,
        *,
        assess_ambiguity: bool = True,
    ) -> RegistrationResult:
        """Align the clouds of a prepared :class:`RegistrationContext`: the form for a
        caller that prepares clouds once and registers them many times (global clouds
        and descriptors computed once per scan, as :func:`register_multiway` does). The
        pipeline's ``voxel_size``, ``n_global_points``, ``random_state``, ``descriptor`` and
        ``settings`` are the context's own then.

        Parameters
        ----------
        context : RegistrationContext
        init : ndarray of shape (4, 4), default=None
            As in :meth:`register`, in the caller's coordinates.
        assess_ambiguity : bool, default=True
            Measure ``result.ambiguous`` (three more evaluations on the global clouds).

        Returns
        -------
        RegistrationResult
        """
        steps = self._check()
        with core_budget(self.n_jobs):
            return self._run(steps, context, init, time.perf_counter(), assess_ambiguity, 3)

    def _run(self, steps, context, init, start, ambiguity, stacklevel) -> RegistrationResult:
        """Prepare the clouds, run every step in order on ``context``, then set the
        result's flags."""
        current = np.eye(4) if init is None else context.to_local(check_rigid_transformation(init))
        # First stage: the global clouds and their descriptors, for every global step.
        described = [d for _, step in steps for d in step._descriptors()]
        preparation = context.prepare(described) if described else 0.0
        log.debug("prepared the clouds in %.3f s", preparation)
        results = []
        for name, step in steps:
            outcome = step._run_timed(context, current)
            outcome.name = name
            if not np.isfinite(outcome.transformation).all():
                raise ValueError(
                    f"step {name!r} found no finite transformation: the clouds are too "
                    "degenerate to register (nearly all points coincide, or too few distinct "
                    "points for the neighbourhoods)"
                )
            current = outcome.transformation  # in the context's centred frame
            outcome.transformation = context.to_world(current)
            results.append(outcome)
            log.debug(
                "step %s: fitness %.3f, inlier RMSE %.4g within %.4g, %.3f s",
                name,
                outcome.fitness,
                outcome.inlier_rmse,
                outcome.distance,
                outcome.seconds,
            )
        distance = results[-1].distance
        margin = min((r.info["margin"] for r in results if "margin" in r.info), default=1.0)
        quality = assess(context, current, distance, ambiguity, margin)
        log.info(
            "registered at resolution %.4g: fitness %.3f within %.4g, converged %s, "
            "ambiguous %s, %.2f s",
            context.voxel_size,
            quality.final.fitness,
            distance,
            quality.converged,
            quality.ambiguous,
            time.perf_counter() - start,
        )
        warn_flags(quality, distance, stacklevel)
        return RegistrationResult.from_quality(
            quality,
            context.to_world(current),
            results,
            voxel_size=context.voxel_size,
            seconds=time.perf_counter() - start,
            distance=distance,
            preparation_seconds=preparation,
        )


def _make_step(spec: str | RegistrationStep, table: dict, params: dict) -> RegistrationStep:
    """A step given by name (checked against ``table``, built with ``params[name]``) or
    as a step object (used as given)."""
    if isinstance(spec, RegistrationStep):
        return spec
    if spec not in table:
        raise ValueError(f"unknown step {spec!r}; known: {sorted(table)}")
    return table[spec](**params.get(spec, {}))


def _check_refinements(refine: Any) -> list:
    """``refine`` as a list of names (of :data:`REFINE_METHODS`) and steps."""
    items = list(refine) if isinstance(refine, (list, tuple)) else [refine]
    items = [r for r in items if r is not None and r != "none"]
    for item in items:
        if not (isinstance(item, RegistrationStep) or item in REFINE_METHODS):
            raise ValueError(
                f"refine must hold names of {sorted(REFINE_METHODS)}, None or "
                f"RegistrationStep objects, got {item!r}"
            )
    return items


def build_chain(
    global_method: str | RegistrationStep | None = "auto",
    refine: str | RegistrationStep | list | None = "point_to_plane",
    descriptor: Any = None,
    params: dict[str, dict] | None = None,
    fpfh_fallback: bool = True,
) -> list[tuple[str, RegistrationStep]]:
    """The named steps :func:`register` runs for these arguments, in order.

    The one place a chain is built from names: ``register()``, the command line's
    config files and multiway's pair registrations all come here.

    Parameters
    ----------
    global_method : str, RegistrationStep or None, default="auto"
        A name of :data:`GLOBAL_METHODS`, ``"auto"`` (the step the descriptor states,
        :func:`~o3d_rpointhop.registration.defaults.resolve_global_method`), a step, or
        None for no global step.
    refine : str, RegistrationStep, list or None, default="point_to_plane"
        Names of :data:`REFINE_METHODS` and steps, in order; ``"symmetry_check"`` by name
        refines the twins with a copy of the refinement before it.
    descriptor : transformer, default=None
        What ``"auto"`` is resolved for.
    params : dict, default=None
        Parameters of the steps given by name, by name (a config file's sections).
    fpfh_fallback : bool, default=True
        Whether the consensus ``"auto"`` resolves to asks FPFH's consensus too where
        the model's estimate is weak
        (:data:`~o3d_rpointhop.registration.defaults.FPFH_FALLBACK`); multiway's
        screening passes False (its pairs were measured with the model alone).

    Returns
    -------
    list of (str, RegistrationStep)
        Named ``"global"``, ``"refine"``, ``"refine1"``..., ``"symmetry_check"``.

    Raises
    ------
    ValueError
        For an unknown name, or an empty chain.
    """
    params = params or {}
    steps: list[tuple[str, RegistrationStep]] = []
    stated = global_method == "auto"
    global_method = resolve_global_method(global_method, descriptor)
    if isinstance(global_method, str) and global_method not in GLOBAL_METHODS:
        what = "the descriptor's registration_global_method_" if stated else "global_method"
        raise ValueError(f"{what} {global_method!r} is not one of {sorted(GLOBAL_METHODS)}")
    if global_method is not None:
        step = _make_step(global_method, GLOBAL_METHODS, params)
        if stated and global_method == "consensus" and FPFH_FALLBACK and fpfh_fallback:
            own = step.matcher  # None: the consensus's default, as PooledMatcher takes it
            step.set_params(matcher=PooledMatcher.with_fpfh(own, combine="fallback"))
        steps.append(("global", step))
    previous = None
    for i, spec in enumerate(_check_refinements(refine)):
        if isinstance(spec, SymmetryCheck):
            steps.append(("symmetry_check", spec))
            continue
        if spec == "symmetry_check":  # twins are refined like the estimate was
            refined = None if previous is None else clone(previous)
            step = SymmetryCheck(refine=refined, **params.get("symmetry_check", {}))
            steps.append(("symmetry_check", step))
            continue
        previous = _make_step(spec, REFINE_METHODS, params)
        steps.append((f"refine{i}" if i else "refine", previous))
    if not steps:
        raise ValueError("nothing to do: global_method and refine are both None")
    return steps


@validate_params(
    {
        "source": "no_validation",
        "target": "no_validation",
        "global_method": [StrOptions({*GLOBAL_METHODS, "auto"}), RegistrationStep, None],
        "refine": [StrOptions({*REFINE_METHODS, "none"}), RegistrationStep, list, tuple, None],
        "init": ["array-like", None],
        "seed": [None, Interval(Integral, 0, None, closed="left")],
        "descriptor": [None, StrOptions({"auto", *PRETRAINED_MODELS}), HasMethods(["transform"])],
        "viewpoints": [None, StrOptions({"origin", "auto"}), "array-like"],
        **{
            name: RegistrationPipeline._parameter_constraints[name]
            for name in (
                "voxel_size",
                "n_global_points",
                "random_state",
                "settings",
                "up",
                "n_jobs",
            )
        },
    },
    prefer_skip_nested_validation=False,  # steps given as objects are checked by the pipeline
)
def register(
    source: Any,
    target: Any,
    descriptor: Any = "auto",
    *,
    global_method: str | RegistrationStep | None = "auto",
    refine: str | RegistrationStep | list | None = "point_to_plane",
    voxel_size: float | str = "auto",
    n_global_points: int | str = "auto",
    init: np.ndarray | None = None,
    random_state: int = 0,
    settings: RegistrationSettings | None = None,
    viewpoints: Any = "auto",
    up: Any = None,
    n_jobs: int | None = None,
    seed: int | None = None,
) -> RegistrationResult:
    """Register ``source`` to ``target``: a global estimate from descriptors, then ICP.

    Parameters
    ----------
    source, target : array-like (n, 3) or Open3D point cloud
        Any size and metric scale; not modified.
    descriptor : "auto", a shipped model's name, transformer or None, \
            default="auto"
        ``"auto"``: the shipped model that serves these clouds, chosen from them
        (:func:`~o3d_rpointhop.registration.model_choice.choose_model`): the scene model,
        facing a sensor at each cloud's origin, when both clouds read as rooms scanned
        from their origin (every point in front of the origin, inside a cone about the
        mean viewing direction, clear of it, and 1-30 units across, read as metres:
        3DMatch fragments, depth frames); else the one-hop object model (objects, scans
        of objects, outdoor LiDAR sweeps). ``result.model`` says which and why. A name:
        that shipped model (``RPointHopTransformer.pretrained(name)``); a fitted
        ``RPointHopTransformer``, an ``FPFHTransformer`` or any descriptor; ``None``:
        the one-hop object model (``pretrained("object")``, 24-D).
    global_method : {"auto", "ransac", "consensus", "fgr", "svd"}, RegistrationStep or \
            None, default="auto"
        ``"ransac"`` is :class:`RANSACGlobal`, ``"consensus"`` the correspondence-graph
        :class:`ConsensusGlobal`, ``"fgr"`` Open3D's Fast Global Registration, ``"svd"``
        the paper's one-shot estimate; ``None`` skips the global step (ICP from
        ``init``). ``"auto"``: the step that won on the descriptor's training data
        (:func:`~o3d_rpointhop.registration.defaults.resolve_global_method`): the
        consensus for the shipped scene model, which states it, with FPFH's consensus
        beside it for a pair where the model's estimate explains under 1.5 % of its
        matches (``PooledMatcher(..., combine="fallback")``, docs/low_overlap.md;
        ``"consensus"`` is the model alone); RANSAC for the ModelNet40 model, FPFH and
        anything that states nothing.
        For FPFH on indoor scans pass ``"consensus"`` (it wins there; see
        docs/consensus.md).
    refine : {"point_to_plane", "point_to_point", "generalized", "multiscale", \
            "symmetry_check"}, step, list of those, or None, default="point_to_plane"
        Run in order. ``"symmetry_check"`` (:class:`SymmetryCheck`) after an ICP step
        also tries the estimate's 180-degree twins, refined by a copy of that step, and
        takes one that fits better on every count: it corrects near-symmetric objects
        registered turned over, at the cost of four more ICP runs on the global clouds.
    voxel_size : float or "auto", default="auto"
        See :class:`RegistrationPipeline`.
    n_global_points : int or "auto", default="auto"
        Size of the global step's clouds. ``"auto"``: the descriptor's
        ``registration_points_`` if it states one (the shipped scene model: 4096, so
        ``register(source, target, RPointHopTransformer.pretrained("scene"))`` is the
        3DMatch benchmark's setting), else 2048.
    init : ndarray of shape (4, 4), default=None
        Start for ICP when there is no global step.
    random_state : int, default=0
        Seeds the random parts (RANSAC's draws, FGR's tuples): the same input and
        ``random_state`` give the same result.
    settings : RegistrationSettings, default=None
        The multiples of the resolution every unset distance is derived from (RANSAC's
        inlier distance, ICP's passes, the normals' radius, ...); ``None`` is
        ``RegistrationSettings()``.
    viewpoints : "auto", None, "origin" or (array-like, array-like), default="auto"
        Where the sensors stood: ``"origin"`` for scans in their sensor's frame (3DMatch
        fragments, LiDAR sweeps, depth images), or ``(source_sensor, target_sensor)``,
        each in its own cloud's coordinates. Normals and local frames then face the
        sensor, so they repeat between scans (on indoor scans this is worth more than
        any setting; docs/benchmarks.md). ``None``: no sensor is known. ``"auto"``:
        chosen with the model when ``descriptor="auto"`` (``"origin"`` with the scene
        model), else None.
    up : None, array-like of shape (3,) or (array-like, array-like), default=None
        See :class:`RegistrationPipeline`.
    n_jobs : int, default=None
        Cores the registration may use: the threads of the compiled kernels, of
        Open3D's searches and of BLAS (the descriptor matches' products), for every
        step and descriptor whose own ``n_jobs`` is None.
        ``None``: every core (within an enclosing ``joblib.parallel_config``); ``-1``:
        every core; the result does not depend on it.
    seed : int, default=None
        The former name of ``random_state``; given, it wins with a ``FutureWarning``.

    Returns
    -------
    RegistrationResult
        ``result.transformation`` maps the source into the target frame;
        ``result.model`` the automatic choice (None for a given descriptor).

    Examples
    --------
    >>> from o3d_rpointhop import register
    >>> from o3d_rpointhop.datasets import make_object
    >>> cloud = make_object(1024)
    >>> result = register(cloud + [0.1, 0.0, 0.0], cloud)
    >>> bool(abs(result.transformation[0, 3] + 0.1) < 1e-3)
    True
    """
    descriptor, viewpoints, choice = resolve_model(
        descriptor, viewpoints, [source, target], ["source", "target"]
    )
    steps = build_chain(global_method, refine, descriptor)
    pipeline = RegistrationPipeline(
        steps,
        descriptor=descriptor,
        voxel_size=voxel_size,
        n_global_points=n_global_points,
        random_state=renamed_seed(random_state, seed, "register"),
        settings=settings,
        viewpoints=viewpoints,
        up=up,
        n_jobs=n_jobs,
    )
    # validate_params checked the pipeline's parameters; the steps are checked here.
    # The warnings of a flagged result point at register()'s caller.
    result = pipeline._register(pipeline._check(own=False), source, target, init, stacklevel=5)
    result.model = None if choice is None else choice.as_dict()
    return result
