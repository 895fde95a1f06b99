"""Helpers shared by the tests: random motions, a descriptor comparison, and sklearn's
estimator checks with the list of those that cannot apply to a point-cloud transformer."""

from __future__ import annotations

from contextlib import contextmanager
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from o3d_rpointhop.datasets import make_object
from o3d_rpointhop.io import write_cloud
from o3d_rpointhop.transforms import rotation_error_deg, translation_error


def random_motion(seed: int, translation_scale: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """A random rotation matrix and translation vector."""
    rng = np.random.default_rng(seed)
    rotation = Rotation.random(random_state=seed).as_matrix()
    return rotation, rng.uniform(-1.0, 1.0, 3) * translation_scale


#: The README's contract: descriptors are invariant to rigid motions and equivariant to
#: permutations of the points within this relative difference (float rounding, not
#: the last bit); the same input gives the same bytes on any thread count.
CONTRACT = 1e-5


def relative_difference(a: np.ndarray, b: np.ndarray) -> float:
    """Largest deviation between descriptor arrays, relative to their spread.

    Measured against the largest deviation of ``a`` from its per-component mean (not
    against its magnitude, which the constant Saab bias inflates), so a small value
    really means the descriptors agree.
    """
    a = np.asarray(a, dtype=np.float64)
    b = np.asarray(b, dtype=np.float64)
    return float(np.abs(a - b).max() / np.abs(a - a.mean(axis=0)).max())


# Checks of sklearn's suite that cannot apply to a point-cloud transformer, and why.
NOT_APPLICABLE = {
    name: "feeds data with 2, 4, 5 or 10 columns; the input is xyz points, exactly 3 columns"
    for name in (
        "check_estimators_overwrite_params",
        "check_estimators_fit_returns_self",
        "check_readonly_memmap_input",
        "check_n_features_in_after_fitting",
        "check_positive_only_tag_during_fit",
        "check_estimators_dtypes",
        "check_dtype_object",
        "check_fit_idempotent",
        "check_fit_check_is_fitted",
        "check_n_features_in",
        "check_fit2d_1sample",
    )
}
NOT_APPLICABLE["check_methods_subset_invariance"] = (
    "transforms rows one at a time and expects the same result as for the whole set; a "
    "point's descriptor is computed from its neighbours, so a one-point cloud has none"
)


def assert_passes_check_estimator(estimator, not_applicable: dict) -> None:
    """sklearn's ``check_estimator`` passes, apart from ``not_applicable``, each of which
    really is exercised and really fails (a check that starts passing must leave the list)."""
    from sklearn.utils.estimator_checks import check_estimator

    results = check_estimator(estimator, expected_failed_checks=not_applicable, on_fail=None)
    failed = [
        (r["check_name"], str(r["exception"])[:200]) for r in results if r["status"] == "failed"
    ]
    assert failed == []
    assert {r["check_name"] for r in results if r["status"] == "xfail"} == set(not_applicable)
    assert sum(r["status"] == "passed" for r in results) >= 30


#: The checkout the tests run in.
REPO = Path(__file__).resolve().parents[1]

#: Two samples of one object, and a quarter turn about z: the shared inputs of the tests of
#: inputs, flags and the command line.
OBJECT = make_object(1024, shape_seed=3, sample_seed=1)
OTHER_SAMPLE = make_object(1024, shape_seed=3, sample_seed=2)
TURN = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])  # 90 deg about z
#: Small hops for models fitted in tests.
SMALL = dict(n_neighbors=(16, 16), hop_sizes=(1.0, 0.5), lrf_neighbors=32)


def benchmark_script(name: str):
    """``benchmarks/<name>.py`` loaded as a module (the scripts are not a package)."""
    import importlib.util

    spec = importlib.util.spec_from_file_location(name, REPO / "benchmarks" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def motion_matrix(rot: np.ndarray, shift: np.ndarray) -> np.ndarray:
    t = np.eye(4)
    t[:3, :3] = rot
    t[:3, 3] = shift
    return t


def moved_copy(points, seed, translation_scale=0.5, permute=True):
    """Source = the target's points moved (and shuffled); truth maps source to target."""
    rot, shift = random_motion(seed, translation_scale)
    rng = np.random.default_rng(seed)
    order = rng.permutation(len(points)) if permute else np.arange(len(points))
    source = points[order] @ rot.T + shift
    truth = np.linalg.inv(motion_matrix(rot, shift))
    return source, truth


def assert_close_pose(estimate, truth, rot_deg, trans):
    assert rotation_error_deg(estimate, truth) < rot_deg
    assert translation_error(estimate, truth) < trans


def object_pairs(n: int, seed: int = 0):
    """Pairs of different samples of one object, moved apart over SO(3), with the truth."""
    X, y = [], []
    for k in range(n):
        target = make_object(700, shape_seed=40 + k, sample_seed=1)
        rot, shift = random_motion(seed * 10 + k, 0.3)
        truth = np.eye(4)
        truth[:3, :3], truth[:3, 3] = rot.T, -rot.T @ shift
        X.append((make_object(700, shape_seed=40 + k, sample_seed=2) @ rot.T + shift, target))
        y.append(truth)
    return X, np.array(y)


def write_points(path, points) -> str:
    """Write a cloud file; return its path as a string (as the command line takes it)."""
    write_cloud(path, points)
    return str(path)


def moved_pair_files(tmp_path):
    """A source and a target file of one object, moved apart, and the truth."""
    from scipy.spatial.transform import Rotation

    target = make_object(700, shape_seed=31)
    rot = Rotation.random(random_state=2).as_matrix()
    source = target @ rot.T + [0.2, -0.1, 0.3]
    truth = np.eye(4)
    truth[:3, :3] = rot.T
    truth[:3, 3] = -rot.T @ [0.2, -0.1, 0.3]
    return (
        write_points(tmp_path / "src.ply", source),
        write_points(tmp_path / "tgt.pcd", target),
        truth,
    )


def partial_views(n_scans: int, seed: int = 0, n_points: int = 2400):
    """Overlapping partial views of one object, each moved by its own rigid motion;
    returns the moved scans and each scan's true pose in scan 0's frame."""
    from o3d_rpointhop.evaluation.protocols import crop_nearest
    from o3d_rpointhop.transforms import apply_transform

    rng = np.random.default_rng(seed)
    scans, poses = [], []
    for k in range(n_scans):
        whole = make_object(n_points, shape_seed=21, sample_seed=100 + k)
        view = whole[crop_nearest(whole, 0.7, rng)]
        motion = np.eye(4) if k == 0 else motion_matrix(*random_motion(seed * 100 + k, 0.5))
        scans.append(apply_transform(view, motion))
        poses.append(np.linalg.inv(motion))  # back into the object's (= scan 0's) frame
    return scans, poses


def synthetic_scene(root, name: str, ids=(0, 1, 2), seed: int = 5) -> None:
    """:func:`partial_views` of one object laid out under ``root`` as a 3DMatch scene:
    ``fragments/<name>/cloud_bin_<id>.ply`` and, under ``benchmarks/3DMatch/<name>``, a
    gt.log (fragment j into fragment i) and a gt.info for each pair of consecutive ids."""
    import open3d as o3d

    scans, truth = partial_views(len(ids), seed=seed)
    folder = Path(root) / "fragments" / name
    folder.mkdir(parents=True)
    for k, scan in zip(ids, scans, strict=True):
        cloud = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(scan))
        o3d.io.write_point_cloud(str(folder / f"cloud_bin_{k}.ply"), cloud)
    gt = Path(root) / "benchmarks" / "3DMatch" / name
    gt.mkdir(parents=True)
    log = {
        (ids[n], ids[n + 1]): np.linalg.inv(truth[n]) @ truth[n + 1] for n in range(len(ids) - 1)
    }
    for file, records in (("gt.log", log), ("gt.info", {pair: np.eye(6) for pair in log})):
        lines = []
        for (i, j), matrix in records.items():
            lines.append(f"{i} {j} 3")
            lines += [" ".join(f"{v:.12g}" for v in row) for row in matrix]
        (gt / file).write_text("\n".join(lines) + "\n")


@contextmanager
def dask_cluster():
    """A Dask ``LocalCluster`` of two single-threaded worker processes and its client
    (skipped without ``distributed``), with joblib's dask backend on every core inside.
    The process's environment is restored afterwards: the cluster leaves
    ``OMP_NUM_THREADS=1`` in it (its nannies' pre-spawn-environ), which would put every
    later test on one thread."""
    import os

    import pytest

    distributed = pytest.importorskip("distributed")
    from joblib import parallel_config

    environ = dict(os.environ)
    try:
        with (
            distributed.LocalCluster(
                n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
            ) as cluster,
            distributed.Client(cluster) as client,
            parallel_config(backend="dask", n_jobs=-1),
        ):
            yield client
    finally:
        os.environ.clear()
        os.environ.update(environ)


def free_port() -> int:
    """A TCP port on 127.0.0.1 that nothing listens on now (for the viewer's server)."""
    import socket

    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class CodesBySize:
    """A descriptor of fixed codes for planted matches: ``codes[n]`` are the rows of the
    cloud of ``n`` points (the clouds of a pair are told apart by their sizes; the
    pipeline keeps a small cloud's rows in order)."""

    def __init__(self, codes: dict[int, np.ndarray]):
        self.codes = codes

    def transform(self, X):
        return self.codes[len(np.asarray(X.points if hasattr(X, "points") else X))]


def moved_samples(n_points: int = 2000, shape_seed: int = 12):
    """Two samples of one synthetic object, the first moved by a fixed motion:
    ``(source, target, truth)`` with ``truth`` mapping the source onto the target."""
    target = make_object(n_points, shape_seed=shape_seed, sample_seed=1)
    truth = np.eye(4)
    truth[:3, :3] = Rotation.from_euler("zyx", [120, 40, -70], degrees=True).as_matrix()
    truth[:3, 3] = [0.1, -0.2, 0.3]
    moved = make_object(n_points, shape_seed=shape_seed, sample_seed=2)
    source = (moved - truth[:3, 3]) @ truth[:3, :3]
    return source, target, truth


class TurnedCodesBySize(CodesBySize):
    """Planted codes per turn of each cloud's frames: ``codes[n]`` is ``(4, n, d)``, turn
    0 the plain descriptor; ``asked`` lists the turn counts requested."""

    def __init__(self, codes: dict[int, np.ndarray]):
        super().__init__(codes)
        self.asked: list[int] = []

    def transform(self, X):
        return super().transform(X)[0]

    def transform_turns(self, X, n_turns, viewpoints=None):
        self.asked.append(n_turns)
        return super().transform(X)[[4 * t // n_turns for t in range(n_turns)]]


def global_step_only(step, source, target, descriptor):
    """``step`` alone as a pipeline with ``descriptor``: its result, warnings silenced."""
    import warnings

    from o3d_rpointhop import RegistrationPipeline, RegistrationWarning

    pipeline = RegistrationPipeline([("global", step)], descriptor=descriptor)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RegistrationWarning)
        return pipeline.register(source, target)


def moved_part(rng, shape_seed: int, euler_zyx_deg, shift, n_points: int = 600, n_kept: int = 500):
    """An object of ``n_points`` and ``n_kept`` of them (drawn by ``rng``) moved:
    ``(source, target, truth, keep)``, ``truth`` mapping each source point onto
    ``target[keep]``."""
    from o3d_rpointhop.transforms import apply_transform

    target = make_object(n_points, shape_seed=shape_seed, sample_seed=0)
    keep = rng.permutation(n_points)[:n_kept]
    truth = np.eye(4)
    truth[:3, :3] = Rotation.from_euler("zyx", euler_zyx_deg, degrees=True).as_matrix()
    truth[:3, 3] = shift
    return apply_transform(target[keep], np.linalg.inv(truth)), target, truth, keep


def consensus_matcher(**params):
    """The consensus's default matcher (both ways, at most 4000) with ``params`` changed."""
    from o3d_rpointhop import ConsensusGlobal

    return ConsensusGlobal.default_matcher().set_params(**params)
