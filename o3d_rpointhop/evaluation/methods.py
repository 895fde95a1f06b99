"""The registration methods every benchmark table compares, measured in the same run.

R-PointHop methods go through :func:`~o3d_rpointhop.register`, with the global step
they name. The ``fpfh-ransac*`` and ``fpfh-fgr`` methods are Open3D's own pipeline, step
for step as in its global registration tutorial (voxel downsampling, normals at 2
voxels, FPFH at 5 voxels, RANSAC on mutual feature matches at 1.5 voxels or FGR at 0.5
voxels, point-to-plane ICP at 0.4 voxels), so "beats FPFH" means beats what an Open3D
user gets. ``fpfh-pipeline-*`` run FPFH through this library's steps instead, to
separate the descriptor from the pipeline. ``kiss-matcher`` is KISS-Matcher (Lim et
al., 2025) end to end, from its pip wheel (the optional ``[peers]`` extra); without it
installed the method is skipped with a line on stderr.
"""

from __future__ import annotations

import sys
import time
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

import numpy as np
import open3d as o3d
from joblib import parallel_config

from .._utils.threads import repeatable_open3d
from ..descriptors import FPFHTransformer, RPointHopTransformer
from ..open3d_interop import to_point_cloud
from ..registration import RegistrationWarning, register

__all__ = [
    "DATASETS",
    "METHODS",
    "Method",
    "MethodRun",
    "default_methods",
    "check_methods",
    "run_method",
]

reg = o3d.pipelines.registration


def fpfh_recipe_cloud(points, voxel, viewpoint=None):
    """A cloud as Open3D's global registration tutorial prepares it: voxel-downsampled,
    normals at 2 voxels (turned towards ``viewpoint`` when given, with Open3D's
    ``orient_normals_towards_camera_location``), FPFH at 5 voxels; returns the cloud and
    its features."""
    cloud = to_point_cloud(points).voxel_down_sample(voxel)
    cloud.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=2 * voxel, max_nn=30))
    if viewpoint is not None:
        cloud.orient_normals_towards_camera_location(np.asarray(viewpoint, dtype=np.float64))
    feature = reg.compute_fpfh_feature(
        cloud, o3d.geometry.KDTreeSearchParamHybrid(radius=5 * voxel, max_nn=100)
    )
    return cloud, feature


def _fpfh_recipe_inputs(source, target, voxel, viewpoints=None):
    views = (None, None) if viewpoints is None else viewpoints
    return (
        *fpfh_recipe_cloud(source, voxel, views[0]),
        *fpfh_recipe_cloud(target, voxel, views[1]),
    )


def feature_ransac(src, tgt, f_src, f_tgt, voxel, seed, mutual_filter: bool):
    """Open3D's RANSAC on feature matches, as in its global registration tutorial (on one
    thread: only so does a seed repeat it, see ``repeatable_open3d``)."""
    distance = 1.5 * voxel
    o3d.utility.random.seed(seed)
    with repeatable_open3d():
        result = _open3d_ransac(src, tgt, f_src, f_tgt, mutual_filter, distance)
    return np.array(result.transformation)


def _open3d_ransac(src, tgt, f_src, f_tgt, mutual_filter, distance):
    return reg.registration_ransac_based_on_feature_matching(
        src,
        tgt,
        f_src,
        f_tgt,
        mutual_filter,
        distance,
        reg.TransformationEstimationPointToPoint(False),
        3,
        [
            reg.CorrespondenceCheckerBasedOnEdgeLength(0.9),
            reg.CorrespondenceCheckerBasedOnDistance(distance),
        ],
        reg.RANSACConvergenceCriteria(100000, 0.999),
    )


def _fpfh_ransac(source, target, voxel, seed, viewpoints=None):
    src, f_src, tgt, f_tgt = _fpfh_recipe_inputs(source, target, voxel, viewpoints)
    return feature_ransac(src, tgt, f_src, f_tgt, voxel, seed, mutual_filter=True)


def open3d_recipe_descriptor():
    """The descriptor of the Open3D-native recipe: the one-hop object model (24-D), what
    docs/registration.md recommends for Open3D's RANSAC (chosen on training pairs by
    benchmarks/open3d_tutorial.py); Open3D's k-d tree over features searches a few
    dozen dimensions fast (the 1624-D descriptor made its RANSAC 40-230x slower)."""
    return RPointHopTransformer.pretrained("object")


def _rpointhop_open3d_ransac(source, target, voxel, seed, model, viewpoints=None):
    """docs/registration.md, "Inside Open3D's own pipeline", step for step."""
    from ..open3d_interop import to_open3d_feature

    views = (None, None) if viewpoints is None else viewpoints
    src = to_point_cloud(source).voxel_down_sample(voxel)
    tgt = to_point_cloud(target).voxel_down_sample(voxel)
    f_src = to_open3d_feature(model.transform(src, viewpoints=views[0]))
    f_tgt = to_open3d_feature(model.transform(tgt, viewpoints=views[1]))
    # mutual_filter=False: RANSAC does the filtering, and Open3D prints no fallback warning.
    return feature_ransac(src, tgt, f_src, f_tgt, voxel, seed, mutual_filter=False)


def _fpfh_fgr(source, target, voxel, seed, viewpoints=None):
    src, f_src, tgt, f_tgt = _fpfh_recipe_inputs(source, target, voxel, viewpoints)
    o3d.utility.random.seed(seed)
    option = reg.FastGlobalRegistrationOption(maximum_correspondence_distance=0.5 * voxel)
    with repeatable_open3d():
        result = reg.registration_fgr_based_on_feature_matching(src, tgt, f_src, f_tgt, option)
    return np.array(result.transformation)


def _recipe_icp(source, target, voxel, init):
    src, tgt = to_point_cloud(source), to_point_cloud(target)
    tgt.estimate_normals(o3d.geometry.KDTreeSearchParamHybrid(radius=2 * voxel, max_nn=30))
    result = reg.registration_icp(
        src, tgt, 0.4 * voxel, init, reg.TransformationEstimationPointToPlane()
    )
    return np.array(result.transformation)


def shipped_scene_model():
    """The shipped scene model (``pretrained()`` reads its file once per process)."""
    return RPointHopTransformer.pretrained("scene")


#: The pair datasets a method can be run on (multiway has its own descriptor list).
DATASETS = ("modelnet40", "bunny", "3dmatch")
_ALL = frozenset(DATASETS)
_OBJECTS = frozenset({"modelnet40", "bunny"})
_SCENES = frozenset({"3dmatch"})


@dataclass(frozen=True)
class Method:
    """One registration method of the benchmarks.

    Attributes
    ----------
    name, description : str
    run : callable
        ``run(source, target, descriptor, voxel, seed, viewpoints)`` -> the 4x4
        source-to-target transformation and whether the method claims it (``None`` for
        a method that reports no such flag); ``viewpoints`` is None or the sensor
        positions of the source and the target, each in its own coordinates.
    datasets : frozenset of str
        The datasets it can be run on.
    default_on : frozenset of str
        The datasets whose benchmark runs it when no method is named.
    model : {"given", "scene", "loso", "recipe", None}
        The R-PointHop model it describes with: the benchmark's (``"given"``), the
        shipped scene model, each pair's leave-one-scene-out model, the Open3D recipe's
        model (:func:`open3d_recipe_descriptor`: the object model), or none.
    descriptor : {"rpointhop", "fpfh", "open3d-fpfh", "kiss-matcher", "none"}
        What describes the points: R-PointHop (``model`` says which), this library's
        ``FPFHTransformer``, Open3D's FPFH as its tutorial computes it, KISS-Matcher's
        own, or nothing (ICP alone). Records name it (:mod:`.provenance`).
    open3d_only : bool
        Open3D calls from end to end (a recipe).
    """

    name: str
    description: str
    run: Callable[..., np.ndarray] = field(repr=False)
    datasets: frozenset = _ALL
    default_on: frozenset = frozenset()
    model: str | None = "given"
    open3d_only: bool = False
    descriptor: str = "rpointhop"


#: Up in a camera's frame (image rows grow downwards): the up-axis prior of the 3DMatch
#: methods that name it; between fragments the camera tilts by 15-45 degrees, so the
#: prior only refuses upside-down hypotheses.
CAMERA_UP = (0.0, -1.0, 0.0)


def _sc2pcr(*args, **kwargs):
    """The SC2-PCR peer step (:mod:`.sc2pcr`), imported when used."""
    from .sc2pcr import SC2PCRGlobal

    return SC2PCRGlobal(*args, **kwargs)


def _claimed(result) -> tuple[np.ndarray, bool]:
    """A result of :func:`~o3d_rpointhop.register` and whether its flags say it can be
    trusted (converged, not ambiguous)."""
    return result.transformation, bool(result.converged and not result.ambiguous)


def _register_with(**options):
    """A runner through :func:`~o3d_rpointhop.register` with ``options``."""

    def run(source, target, descriptor, voxel, seed, viewpoints):
        result = register(source, target, descriptor, seed=seed, viewpoints=viewpoints, **options)
        return _claimed(result)

    run.options = options  # what the records name (provenance)
    return run


def _fpfh_recipe(voxel_of: Callable[[float], float] = lambda voxel: voxel, icp: bool = True):
    """Open3D's FPFH + RANSAC recipe (then its ICP) at ``voxel_of(voxel)``."""

    def run(source, target, descriptor, voxel, seed, viewpoints):
        voxel = voxel_of(voxel)
        estimate = _fpfh_ransac(source, target, voxel, seed, viewpoints)
        return (_recipe_icp(source, target, voxel, estimate) if icp else estimate), None

    return run


def _run_fpfh_fgr(source, target, descriptor, voxel, seed, viewpoints):
    return _fpfh_fgr(source, target, voxel, seed, viewpoints), None


def _fpfh_pipeline(**options):
    """FPFH through :func:`~o3d_rpointhop.register` (a callable ``global_method`` makes
    a fresh step per pair)."""

    def run(source, target, descriptor, voxel, seed, viewpoints):
        chosen = dict(options)
        if callable(chosen.get("global_method")):
            chosen["global_method"] = chosen["global_method"]()
        result = register(
            source, target, FPFHTransformer(), seed=seed, viewpoints=viewpoints, **chosen
        )
        return _claimed(result)

    run.options = options
    return run


def kiss_matcher_available() -> bool:
    """Whether the optional KISS-Matcher wheel is installed and imports."""
    try:
        import kiss_matcher  # noqa: F401
    except ImportError:
        return False
    return True


def _run_kiss_matcher(source, target, descriptor, voxel, seed, viewpoints):
    """KISS-Matcher's own pipeline (voxelisation, Faster-PFH, matching, ROBIN pruning,
    GNC-TLS) at the resolution the other methods use; no refinement after it. It takes
    no viewpoints; it claims the result it calls valid."""
    import kiss_matcher

    config = kiss_matcher.KISSMatcherConfig(voxel_size=float(voxel))
    matcher = kiss_matcher.KISSMatcher(config)
    src = np.asarray(to_point_cloud(source).points, dtype=np.float32)
    tgt = np.asarray(to_point_cloud(target).points, dtype=np.float32)
    solution = matcher.estimate(src, tgt)
    out = np.eye(4)
    if solution.valid:
        out[:3, :3] = np.asarray(solution.rotation)
        out[:3, 3] = np.asarray(solution.translation).ravel()
    return out, bool(solution.valid)


def _run_rpointhop_open3d(source, target, descriptor, voxel, seed, viewpoints):
    model = open3d_recipe_descriptor()
    estimate = _rpointhop_open3d_ransac(source, target, voxel, seed, model, viewpoints)
    return _recipe_icp(source, target, voxel, estimate), None


def _run_icp(source, target, descriptor, voxel, seed, viewpoints):
    return np.array(
        reg.registration_icp(
            to_point_cloud(source),
            to_point_cloud(target),
            4 * voxel,
            np.eye(4),
            reg.TransformationEstimationPointToPoint(False),
        ).transformation
    ), None


def _methods(*methods: Method) -> dict[str, Method]:
    return {m.name: m for m in methods}


#: Every method, by name; the order of the reports' rows.
METHODS = _methods(
    Method(
        "rpointhop-svd",
        "R-PointHop + the paper's one-shot SVD",
        _register_with(global_method="svd", refine=None),
        default_on=_OBJECTS,
    ),
    Method(
        "rpointhop-svd-icp",
        "R-PointHop + SVD + point-to-plane ICP",
        _register_with(global_method="svd"),
        default_on=_OBJECTS,
    ),
    Method(
        "rpointhop-ransac",
        "R-PointHop + RANSAC",
        _register_with(global_method="ransac", refine=None),
        default_on=_OBJECTS,
    ),
    Method(
        "rpointhop-ransac-icp",
        "R-PointHop + RANSAC + point-to-plane ICP",
        _register_with(global_method="ransac"),
        default_on=_OBJECTS,
    ),
    Method(
        "rpointhop-consensus-icp",
        "R-PointHop + consensus + point-to-plane ICP",
        _register_with(global_method="consensus"),
        default_on=_OBJECTS,
    ),
    Method(
        "rpointhop-scene",
        "R-PointHop, shipped scene model, register() defaults",
        _register_with(),
        default_on=_SCENES,
        model="scene",
    ),
    Method(
        "rpointhop-scene-up",
        "R-PointHop, shipped scene model, register() defaults, up-axis prior (camera -y)",
        _register_with(up=CAMERA_UP),
        datasets=_SCENES,
        model="scene",
    ),
    Method(
        "rpointhop-scene-ransac",
        "R-PointHop, shipped scene model + RANSAC + point-to-plane ICP",
        _register_with(global_method="ransac"),
        default_on=_SCENES,
        model="scene",
    ),
    Method(
        "rpointhop-loso",
        "R-PointHop, scene model fitted on the other scenes, register() defaults",
        _register_with(),
        datasets=_SCENES,
        default_on=_SCENES,
        model="loso",
    ),
    Method(
        "rpointhop-ransac-icp-4096",
        "R-PointHop + RANSAC + point-to-plane ICP, 4096 global points",
        _register_with(global_method="ransac", n_global_points=4096),
    ),
    Method(
        "rpointhop-ransac-icp-sym",
        "R-PointHop + RANSAC + point-to-plane ICP + symmetry check",
        _register_with(global_method="ransac", refine=["point_to_plane", "symmetry_check"]),
        default_on=_OBJECTS,
    ),
    Method(
        "fpfh-ransac",
        "FPFH + RANSAC (Open3D's recipe)",
        _fpfh_recipe(icp=False),
        default_on=_OBJECTS,
        model=None,
        open3d_only=True,
        descriptor="open3d-fpfh",
    ),
    Method(
        "fpfh-fgr",
        "FPFH + FGR (Open3D's recipe)",
        _run_fpfh_fgr,
        default_on=_OBJECTS,
        model=None,
        open3d_only=True,
        descriptor="open3d-fpfh",
    ),
    Method(
        "fpfh-ransac-icp",
        "FPFH + RANSAC + point-to-plane ICP (Open3D's recipe)",
        _fpfh_recipe(),
        default_on=_ALL,
        model=None,
        open3d_only=True,
        descriptor="open3d-fpfh",
    ),
    Method(
        "fpfh-ransac-icp-5cm",
        "FPFH + RANSAC + point-to-plane ICP (Open3D's recipe), 5 cm voxel",
        _fpfh_recipe(lambda voxel: 0.05),
        default_on=_SCENES,
        model=None,
        open3d_only=True,
        descriptor="open3d-fpfh",
    ),
    Method(
        "fpfh-pipeline-ransac-icp",
        "FPFH through this library's RANSAC + ICP",
        _fpfh_pipeline(global_method="ransac"),
        default_on=_ALL,
        model=None,
        descriptor="fpfh",
    ),
    Method(
        "fpfh-pipeline-consensus-icp",
        "FPFH through this library's consensus + ICP",
        _fpfh_pipeline(global_method="consensus"),
        default_on=_ALL,
        model=None,
        descriptor="fpfh",
    ),
    Method(
        "fpfh-pipeline-consensus-icp-4096",
        "FPFH through this library's consensus + ICP, 4096 global points",
        _fpfh_pipeline(global_method="consensus", n_global_points=4096),
        datasets=_SCENES,
        model=None,
        descriptor="fpfh",
    ),
    Method(
        "fpfh-sc2pcr-icp",
        "FPFH + SC2-PCR (from its paper, on the consensus's matches) + ICP",
        _fpfh_pipeline(global_method=_sc2pcr),
        datasets=_SCENES,
        default_on=_SCENES,
        model=None,
        descriptor="fpfh",
    ),
    Method(
        "fpfh-pipeline-consensus-icp-up",
        "FPFH through this library's consensus + ICP, up-axis prior (camera -y)",
        _fpfh_pipeline(global_method="consensus", up=CAMERA_UP),
        datasets=_SCENES,
        model=None,
        descriptor="fpfh",
    ),
    Method(
        "rpointhop-open3d-ransac-icp",
        "R-PointHop (object model) in Open3D's RANSAC recipe + point-to-plane ICP",
        _run_rpointhop_open3d,
        default_on=_OBJECTS,
        model="recipe",
        open3d_only=True,
    ),
    Method(
        "kiss-matcher",
        "KISS-Matcher end to end (pip wheel)",
        _run_kiss_matcher,
        default_on=_SCENES,
        model=None,
        descriptor="kiss-matcher",
    ),
    Method(
        "icp",
        "point-to-point ICP alone, from the identity",
        _run_icp,
        default_on=_OBJECTS,
        model=None,
        open3d_only=True,
        descriptor="none",
    ),
)


def default_methods(dataset: str) -> list[str]:
    """The methods ``o3d-rpointhop benchmark <dataset>`` runs when not given ``--methods``."""
    return [name for name, m in METHODS.items() if dataset in m.default_on]


def check_methods(methods, dataset: str) -> list[str]:
    """``methods`` as a list, refused if one is unknown or does not apply to ``dataset``."""
    methods = list(methods)
    unknown = [m for m in methods if m not in METHODS]
    if unknown:
        raise ValueError(f"unknown methods {unknown}; choose from {sorted(METHODS)}")
    elsewhere = [m for m in methods if dataset not in METHODS[m].datasets]
    if elsewhere:
        where = sorted({d for m in elsewhere for d in METHODS[m].datasets})
        raise ValueError(f"{elsewhere} do not apply to {dataset} (only to {', '.join(where)})")
    if "kiss-matcher" in methods and not kiss_matcher_available():
        print(
            "benchmark: kiss-matcher skipped: not installed "
            "(pip install '.[peers]' in the project folder)",
            file=sys.stderr,
        )
        methods.remove("kiss-matcher")
    return methods


#: The thread budgets a benchmark can give both sides: ``"one"`` thread each (this
#: library's kernels and Open3D's code alike), or ``"all"``: every core each (this
#: library's kernels, and Open3D's normals, features and ICP; Open3D's RANSAC and FGR
#: stay on one thread, the only way a seed repeats them).
THREAD_BUDGETS = ("one", "all")
_BUDGET = ["one"]


@contextmanager
def thread_budget(name: str) -> Iterator[None]:
    """Run the benchmarks inside on the thread budget ``name`` (see
    :data:`THREAD_BUDGETS`)."""
    if name not in THREAD_BUDGETS:
        raise ValueError(f"thread budget must be one of {THREAD_BUDGETS}, got {name!r}")
    previous = _BUDGET[0]
    _BUDGET[0] = name
    try:
        yield
    finally:
        _BUDGET[0] = previous


def current_thread_budget() -> str:
    """The thread budget methods run on now."""
    return _BUDGET[0]


@contextmanager
def _budgeted() -> Iterator[None]:
    """This library's kernels (``joblib.parallel_config``) and Open3D on the budget."""
    one = _BUDGET[0] == "one"
    previous = o3d.utility.get_max_threads()
    if one:
        o3d.utility.set_max_threads(1)
    try:
        with parallel_config(n_jobs=1 if one else -1):
            yield
    finally:
        o3d.utility.set_max_threads(previous)


@dataclass(frozen=True)
class MethodRun:
    """What one method did on one pair.

    Attributes
    ----------
    transformation : ndarray of shape (4, 4)
        Source to target.
    seconds : float
        Wall time, model loading left out.
    claimed : bool or None
        Whether the method's own flags call the result trustworthy (``register()``:
        converged and not ambiguous; KISS-Matcher: valid); None for a method without
        such a flag. Precision is measured over the claimed results.
    """

    transformation: np.ndarray
    seconds: float
    claimed: bool | None


def run_method(
    name: str,
    source: np.ndarray,
    target: np.ndarray,
    *,
    descriptor,
    voxel: float,
    seed: int = 0,
    viewpoints=None,
) -> MethodRun:
    """Run one method on one pair.

    Parameters
    ----------
    descriptor : RPointHopTransformer
        The model the R-PointHop methods use (``rpointhop-loso``: the pair's
        leave-one-scene-out model; ``rpointhop-scene`` always uses the shipped scene
        model).
    voxel : float
        Resolution of the FPFH recipe and of ICP alone (0.05 for unit-sphere objects, as
        in the Open3D tutorial).
    viewpoints : None or (array-like, array-like), default=None
        The sensor positions of the source and the target, each in its own
        coordinates: passed to every descriptor (R-PointHop's frames, FPFH's normals, in
        this library and in Open3D's recipes); KISS-Matcher takes none.

    Returns
    -------
    MethodRun
    """
    if name not in METHODS:
        raise ValueError(f"unknown method {name!r}; choose from {sorted(METHODS)}")
    if name == "kiss-matcher" and not kiss_matcher_available():
        raise ValueError(
            "kiss-matcher is not installed: pip install '.[peers]' in the project folder "
            "(or kiss-matcher)"
        )
    method = METHODS[name]
    # Reading a model file is not part of a method's time: read it now, once per process.
    if method.model == "scene":
        descriptor = shipped_scene_model()
    if method.model == "recipe":
        open3d_recipe_descriptor()
    # Flagged results are scored like any other; the flags' warnings would only repeat.
    # Open3D's recipe warns when its mutual filter leaves few matches; the result says
    # it. Both sides run on the same thread budget (thread_budget).
    with (
        warnings.catch_warnings(),
        o3d.utility.VerbosityContextManager(o3d.utility.VerbosityLevel.Error),
        _budgeted(),
    ):
        warnings.simplefilter("ignore", RegistrationWarning)
        start = time.perf_counter()
        transformation, claimed = method.run(source, target, descriptor, voxel, seed, viewpoints)
        return MethodRun(transformation, time.perf_counter() - start, claimed)
